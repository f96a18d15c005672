#include "libbtf/export/schneider.h"

#include <algorithm>
#include <cmath>

#include "libbtf/compress/lpca_tensor.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/export/export_common.h"

namespace btf {

using export_detail::NormalisedStore;
using export_detail::WriteBinary;

void SchneiderExportOptions::Check() const {
  BTF_CHECK_OPTION(view_grid >= 2 && view_grid <= 256, "view_grid", "must be 2..256");
  BTF_CHECK_OPTION(light_grid >= 2 && light_grid <= 256, "light_grid", "must be 2..256");
  BTF_CHECK_OPTION(components >= -1, "components", "must be >= 0, or -1 for all");
  BTF_CHECK_OPTION(storage == "u8" || storage == "f16", "storage", "must be u8 or f16");
  BTF_CHECK_OPTION(atlas_side >= 16 && atlas_side <= 16384, "atlas_side", "must be 16..16384");
  BTF_CHECK_OPTION(view_grid <= atlas_side, "view_grid", "must be <= atlas_side (one tile per function)");
  BTF_CHECK_OPTION(light_grid * light_grid <= atlas_side, "light_grid",
                   "light_grid^2 (the atlas depth) must be <= atlas_side (16 for 256)");
}

nlohmann::json SchneiderExportSummary::ToJson() const {
  return {{"directory", directory},
          {"clusters", clusters},
          {"functions_per_cluster", functions},
          {"view_grid", view_grid},
          {"light_grid", light_grid},
          {"storage", storage},
          {"atlas", {{"width", atlas_width}, {"height", atlas_height}, {"depth", atlas_depth}, {"pages", atlas_pages},
                     {"tiles_x", tiles_x}, {"tiles_y", tiles_y}}},
          {"texture_bytes", texture_bytes},
          {"weight_bytes", weight_bytes},
          {"index_bytes", index_bytes},
          {"total_bytes", texture_bytes + weight_bytes + index_bytes},
          {"max_quantisation_error_in_scale_units", max_quantization_error},
          {"seconds", times.ToJson()}};
}

std::string SchneiderExportSummary::Report() const {
  return fmt::format("{}/ : {} clusters x {} functions on a {}^2 x {}^2 grid, {} atlas {} x {} x {} x {} page(s); "
                     "textures {}, weights {}, index {}; {}\n",
                     directory, clusters, functions, view_grid, light_grid, storage, atlas_width, atlas_height,
                     atlas_depth, atlas_pages, FormatBytes(texture_bytes),
                     FormatBytes(weight_bytes), FormatBytes(index_bytes), times.Report());
}

namespace {

// Atlas of the resampled functions: function g = k * F + f is tile (g % tiles_x, (g / tiles_x) %
// tiles_y) of page g / per_page; a tile is nv x nv texels, the page depth nl * nl.
struct SchneiderAtlas {
  int tiles_x = 0, tiles_y = 0, per_page = 0, pages = 0;
  int width = 0, height = 0, depth = 0;
};

SchneiderAtlas PlanAtlas(int functions, int nv, int nl, int atlas_side) {
  SchneiderAtlas a;
  a.tiles_x = std::min(functions, atlas_side / nv);
  a.tiles_y = std::min((functions + a.tiles_x - 1) / a.tiles_x, atlas_side / nv);
  a.per_page = a.tiles_x * a.tiles_y;
  a.pages = (functions + a.per_page - 1) / a.per_page;
  a.width = a.tiles_x * nv, a.height = a.tiles_y * nv, a.depth = nl * nl;
  return a;
}

// Interpolants over `sampling` of every direction of an n x n grid on the square, row t, column s
// at [t * n + s].
std::vector<Interpolant> GridInterpolants(const Sampling& sampling, int n) {
  std::vector<Interpolant> ip(std::size_t(n) * n);
  for (int t = 0; t < n; ++t)
    for (int s = 0; s < n; ++s)
      ip[std::size_t(t) * n + s] =
          sampling.Barycentric(HemisphereFromSquare(Vec2(GridCoordinate(s, n), GridCoordinate(t, n))));
  return ip;
}

// One function (an ABRDF of the codec's views x lights x channels) resampled on the grid:
// value[z = tl * nl + sl][tv][sv][ch], z = slab index * nl + s_l index.
std::vector<double> ResampleFunction(const float* fn, const std::vector<Interpolant>& view_ip,
                                     const std::vector<Interpolant>& light_ip, int nv, int nl, int C, int L) {
  std::vector<double> vals(std::size_t(nv) * nv * nl * nl * C);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t z = 0; z < std::ptrdiff_t(nl) * nl; ++z) {
    const Interpolant& il = light_ip[static_cast<std::size_t>(z)];  // z = tl * nl + sl: same order
    for (int tv = 0; tv < nv; ++tv)
      for (int sv = 0; sv < nv; ++sv) {
        const Interpolant& iv = view_ip[std::size_t(tv) * nv + sv];
        for (int ch = 0; ch < C; ++ch) {
          double acc = 0;
          for (int a = 0; a < iv.count; ++a)
            for (int b = 0; b < il.count; ++b)
              acc += iv.weight[a] * il.weight[b] * fn[(std::size_t(iv.index[a]) * L + il.index[b]) * C + ch];
          vals[((std::size_t(z) * nv + tv) * nv + sv) * C + ch] = acc;
        }
      }
  }
  return vals;
}

// Quantises resampled function g into its atlas tile, with the scale and bias that make
// t = (value - bias) / scale span [0, 1] exactly (all 256 codes in use), stored in scale_bias.
// Returns the largest quantisation error of t.
double StoreFunction(const std::vector<double>& vals, int g, const SchneiderAtlas& atlas, int nv, int C,
                     NormalisedStore* store, std::vector<float>* scale_bias) {
  double lo = vals.empty() ? 0 : vals[0], hi = lo;
  for (double v : vals) lo = std::min(lo, v), hi = std::max(hi, v);
  const float bias = static_cast<float>(lo), scale = static_cast<float>(hi - lo);
  (*scale_bias)[std::size_t(g) * 2] = scale;
  (*scale_bias)[std::size_t(g) * 2 + 1] = bias;
  const int page = g / atlas.per_page, tx = g % atlas.tiles_x, ty = (g / atlas.tiles_x) % atlas.tiles_y;
  const int AD = atlas.depth, AH = atlas.height, AW = atlas.width;
  double max_q = 0;
  for (int z = 0; z < AD; ++z)
    for (int tv = 0; tv < nv; ++tv)
      for (int sv = 0; sv < nv; ++sv)
        for (int ch = 0; ch < C; ++ch) {
          const double v = vals[((std::size_t(z) * nv + tv) * nv + sv) * C + ch];
          const double t = scale > 0 ? std::clamp((v - bias) / double(scale), 0.0, 1.0) : 0.0;
          const std::size_t at =
              (((std::size_t(page) * AD + z) * AH + std::size_t(ty) * nv + tv) * AW + std::size_t(tx) * nv + sv) * C + ch;
          max_q = std::max(max_q, std::abs(store->Put(at, t) - t));
        }
  return max_q;
}

// Terms per texel (1 + F each): offset = sum_f w_f bias_f, then w_f scale_f (w_0 = 1 for the
// mean); and each texel's cluster index.
void FoldTerms(const LpcaModel& m, int F, std::size_t T, const std::vector<float>& scale_bias,
               std::vector<float>* terms, std::vector<std::uint16_t>* index) {
  const int NT = 1 + F;
  terms->assign(T * NT, 0.0f);
  index->assign(T, 0);
  for (std::size_t t = 0; t < T; ++t) {
    const int k = m.cluster_of[t];
    (*index)[t] = static_cast<std::uint16_t>(k);
    double offset = 0;
    for (int f = 0; f < F; ++f) {
      const double w = f == 0 ? 1.0
                              : (f - 1 < m.cluster_components[static_cast<std::size_t>(k)] ? m.weights[t * m.components + f - 1] : 0.0f);
      const std::size_t g = std::size_t(k) * F + f;
      offset += w * scale_bias[g * 2 + 1];
      (*terms)[t * NT + 1 + f] = static_cast<float>(w * scale_bias[g * 2]);
    }
    (*terms)[t * NT] = static_cast<float>(offset);
  }
}

nlohmann::json SchneiderManifest(const SchneiderExportOptions& o, const Codec& codec, const SchneiderAtlas& atlas,
                                 int K, int F, const std::string& atlas_file) {
  const bool half = o.storage == "f16";
  const int nv = o.view_grid, nl = o.light_grid, C = codec.channels(), NT = 1 + F;
  const int AW = atlas.width, AH = atlas.height, AD = atlas.depth, pages = atlas.pages;
  nlohmann::json j;
  j["format"] = kSchneiderExportFormat;
  j["format_version"] = kSchneiderExportVersion;
  j["layout"] = kSchneiderLayout;
  j["source"] = {{"codec_method", "lpca"}, {"view_sampling", codec.views().name()},
                 {"light_sampling", codec.lights().name()}, {"compression", codec.provenance().value("options", nlohmann::json())}};
  j["texture"] = export_detail::TextureJson(codec);
  j["values"] = export_detail::ValuesJson(codec);
  j["parameterisation"] = {
      {"map", "elevated concentric (Schneider 2004 section 6.1): square -> Shirley-Chiu disk -> hemisphere with "
              "z = 1 - rho^2, (x, y) scaled by sqrt(2 - rho^2)"},
      {"frame", "z = surface normal, x = weft (texture u), y = warp (texture v)"},
      {"view", "(s_v, t_v) = square coordinates of the view direction wo"},
      {"light", "(s_l, t_l) = square coordinates of the light direction wi"},
      {"grid", "sample i of n on an axis sits at the cell centre (i + 0.5) / n"}};
  j["functions"] = {{"count_per_cluster", F}, {"meaning", "function 0 = cluster mean, 1..c = Eigen-ABRDFs"},
                    {"view_grid", nv}, {"light_grid", nl},
                    {"slab_layout", "depth z = i * n_sl + j for slab i (t_l sample i) and s_l sample j"}};
  j["atlas"] = {
      {"file", atlas_file},
      {"type", half ? "float16" : "uint8"},
      {"storage", o.storage},
      {"webgl_format", export_detail::WebGlFormat(half, C)},
      {"shape", {pages, AD, AH, AW, C}},
      {"dimension_names", {"page", "z", "y", "x", "channel"}},
      {"width", AW}, {"height", AH}, {"depth", AD}, {"pages", pages},
      {"tiles_x", atlas.tiles_x}, {"tiles_y", atlas.tiles_y}, {"tile_width", nv}, {"tile_height", nv},
      {"max_side", o.atlas_side},
      {"tile_of_function",
       "g = cluster * F + f; page = g / (tiles_x * tiles_y), tile column = g % tiles_x, tile row = (g / tiles_x) % tiles_y"},
      {"decode_value", half ? "t = the half float as stored, in [0, 1]" : "t = q / 255 (unsigned normalised), in [0, 1]"},
      {"lookup",
       "slab coordinate a = t_l * n_tl - 0.5: a <= 0 -> slab 0 only, a >= n_tl - 1 -> the last slab only, else "
       "i0 = floor(a), i1 = i0 + 1, w = a - i0; in each slab, with texel coordinates (centre of texel n at n + 0.5): "
       "x = tile column * n_sv + clamp(s_v * n_sv - 0.5, 0, n_sv - 1) + 0.5, y = tile row * n_tv + clamp(t_v * n_tv - 0.5, "
       "0, n_tv - 1) + 0.5, z = i * n_sl + clamp(s_l * n_sl - 0.5, 0, n_sl - 1) + 0.5 (the clamps keep filtering inside "
       "one tile and one slab), trilinear filtering of the page at (x / width, y / height, z / depth); "
       "t_f = (1 - w) S_i0 + w S_i1"}};
  j["terms"] = {{"file", "terms.f32"}, {"type", "float32"}, {"shape", {codec.height(), codec.width(), NT}},
                {"meaning", "value = terms[y][x][0] + sum_f terms[y][x][1 + f] * t_f(cluster_index[y][x], wo, wi); "
                            "term 0 = sum_f w_f bias_f, term 1 + f = w_f scale_f (w_0 = 1)"}};
  j["cluster_index"] = {{"file", "cluster_index.u16"}, {"type", "uint16"}, {"shape", {codec.height(), codec.width()}}};
  j["scale_bias"] = {{"file", "scale_bias.f32"}, {"type", "float32"}, {"shape", {K, F, 2}},
                     {"meaning", "function value = bias + scale * t, t in [0, 1] (min and max over the grid); "
                                 "already folded into terms"}};
  j["quantisation_error_bound"] = {
      {"per_t", StorageQuantizationBound(o.storage)},
      {"per_value", fmt::format("sum_f |terms[1 + f]| * {} ({})", StorageQuantizationBound(o.storage),
                                half ? "half an ulp of a half float below 1, 2^-12, plus 2^-24 for the float32 rounding before it" : "half a step of 1/255")}};
  j["glsl"] = {{"file", "btf_schneider.glsl"}, {"function", "vec3 btf_eval(vec2 uv, vec3 wi, vec3 wo)"}};
  j["byte_order"] = "little-endian";
  return j;
}

}  // namespace

SchneiderExportSummary ExportSchneider(const SchneiderExportOptions& o, const Codec& codec,
                                       const std::filesystem::path& out_dir, const Reporter& rep) {
  o.Check();
  // lpca-tensor: its factorised functions expanded, exported as the LPCA codec they make.
  if (codec.method() == CodecMethod::kLpcaTensor) return ExportSchneider(o, ExpandToLpcaCodec(codec), out_dir, rep);
  if (codec.method() != CodecMethod::kLpca)
    ThrowUsage("the schneider export needs an LPCA (or lpca-tensor) codec; this one is '{}' (compress with --method "
               "lpca; a pca-view codec exports with --format sattler, a neural codec with --format neural)",
               MethodName(codec.method()));
  if (codec.transform() != ValueTransform::kNone)
    ThrowUsage("the schneider export needs a codec without value transform (the renderer sums weighted "
               "functions linearly); compress without --log");
  if (codec.lpca().clusters > 65535) ThrowUsage("the schneider export stores cluster indices in 16 bits (<= 65535 clusters)");
  Timer timer;
  SchneiderExportSummary s;
  const LpcaModel& m = codec.lpca();
  const int K = m.clusters, c = o.components < 0 ? m.components : std::min(o.components, m.components);
  const int F = 1 + c, nv = o.view_grid, nl = o.light_grid, C = codec.channels(), L = codec.num_lights();
  const std::size_t d = codec.abrdf_size(), T = std::size_t(codec.height()) * codec.width();
  AtomicDirectory output(out_dir, "manifest.json");
  const std::filesystem::path& dir = output.temp_path();

  const std::vector<Interpolant> view_ip = GridInterpolants(codec.views(), nv);
  const std::vector<Interpolant> light_ip = GridInterpolants(codec.lights(), nl);
  const int G = K * F;
  const SchneiderAtlas atlas = PlanAtlas(G, nv, nl, o.atlas_side);
  const std::size_t atlas_values = std::size_t(atlas.pages) * atlas.depth * atlas.height * atlas.width * C;
  const bool half = o.storage == "f16";
  NormalisedStore store(half, atlas_values);
  std::vector<float> scale_bias(std::size_t(G) * 2, 0.0f);
  double max_q = 0;
  for (int k = 0; k < K; ++k) {
    rep.Progress(std::size_t(k), std::size_t(K), "resample");
    for (int f = 0; f < F; ++f) {
      const float* fn = f == 0 ? &m.means[std::size_t(k) * d] : &m.basis[(std::size_t(k) * m.components + f - 1) * d];
      const std::vector<double> vals = ResampleFunction(fn, view_ip, light_ip, nv, nl, C, L);
      max_q = std::max(max_q, StoreFunction(vals, k * F + f, atlas, nv, C, &store, &scale_bias));
    }
  }
  s.times.Add("resample", timer.Seconds());
  timer.Restart();
  std::vector<float> terms;
  std::vector<std::uint16_t> index;
  FoldTerms(m, F, T, scale_bias, &terms, &index);
  const std::string atlas_file = half ? "atlas.f16" : "atlas.u8";
  s.texture_bytes = store.Write(dir / atlas_file);
  s.weight_bytes = WriteBinary(dir / "terms.f32", terms);
  s.index_bytes = WriteBinary(dir / "cluster_index.u16", index);
  WriteBinary(dir / "scale_bias.f32", scale_bias);

  nlohmann::json j = SchneiderManifest(o, codec, atlas, K, F, atlas_file);
  WriteTextFileAtomic(dir / "btf_schneider.glsl", SchneiderGlsl(j));
  j["checksums"] = export_detail::ExportChecksums(dir);
  WriteTextFileAtomic(dir / "manifest.json", j.dump(2) + "\n");
  output.Commit();
  s.times.Add("write", timer.Seconds());
  s.directory = out_dir.string();
  s.clusters = K;
  s.functions = F;
  s.view_grid = nv;
  s.light_grid = nl;
  s.height = codec.height();
  s.width = codec.width();
  s.channels = C;
  s.storage = o.storage;
  s.atlas_width = atlas.width, s.atlas_height = atlas.height, s.atlas_depth = atlas.depth, s.atlas_pages = atlas.pages;
  s.tiles_x = atlas.tiles_x, s.tiles_y = atlas.tiles_y;
  s.max_quantization_error = max_q;
  rep.Progress(std::size_t(K), std::size_t(K), "resample");
  return s;
}

}  // namespace btf
