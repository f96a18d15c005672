#include "libbtf/export/schneider.h"

#include <algorithm>
#include <cmath>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"

namespace btf {

namespace {

template <typename T>
std::uint64_t WriteBinary(const std::filesystem::path& path, const std::vector<T>& data) {
  WriteFileAtomic(path, data.data(), data.size() * sizeof(T));
  return data.size() * sizeof(T);
}

}  // namespace

void SchneiderExportOptions::Check() const {
  BTF_CHECK_OPTION(view_grid >= 2 && view_grid <= 256, "view_grid", "must be 2..256");
  BTF_CHECK_OPTION(light_grid >= 2 && light_grid <= 256, "light_grid", "must be 2..256");
  BTF_CHECK_OPTION(components >= -1, "components", "must be >= 0, or -1 for all");
}

nlohmann::json SchneiderExportSummary::ToJson() const {
  return {{"directory", directory},
          {"clusters", clusters},
          {"functions_per_cluster", functions},
          {"view_grid", view_grid},
          {"light_grid", light_grid},
          {"texture_bytes", texture_bytes},
          {"weight_bytes", weight_bytes},
          {"index_bytes", index_bytes},
          {"total_bytes", texture_bytes + weight_bytes + index_bytes},
          {"max_quantisation_error_in_scale_units", max_quantization_error},
          {"seconds", times.ToJson()}};
}

std::string SchneiderExportSummary::Report() const {
  return fmt::format("{}/ : {} clusters x {} functions on a {}^2 x {}^2 grid; textures {}, weights {}, index {}; {}\n",
                     directory, clusters, functions, view_grid, light_grid, FormatBytes(texture_bytes),
                     FormatBytes(weight_bytes), FormatBytes(index_bytes), times.Report());
}

SchneiderExportSummary ExportSchneider(const SchneiderExportOptions& o, const Codec& codec,
                                       const std::filesystem::path& out_dir, const Reporter& rep) {
  o.Check();
  if (codec.method() != CodecMethod::kLpca)
    ThrowUsage("the schneider export needs an LPCA codec; this one is '{}' (compress with --method lpca)",
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
  const std::size_t grid = std::size_t(nv) * nv * nl * nl;  // per function, per channel
  AtomicDirectory output(out_dir, "manifest.json");
  const std::filesystem::path& dir = output.temp_path();

  // Interpolants of every grid direction over the codec's samplings.
  std::vector<Interpolant> view_ip(std::size_t(nv) * nv), light_ip(std::size_t(nl) * nl);
  for (int t = 0; t < nv; ++t)
    for (int sv = 0; sv < nv; ++sv)
      view_ip[std::size_t(t) * nv + sv] =
          codec.views().Barycentric(HemisphereFromSquare(Vec2(GridCoordinate(sv, nv), GridCoordinate(t, nv))));
  for (int t = 0; t < nl; ++t)
    for (int sl = 0; sl < nl; ++sl)
      light_ip[std::size_t(t) * nl + sl] =
          codec.lights().Barycentric(HemisphereFromSquare(Vec2(GridCoordinate(sl, nl), GridCoordinate(t, nl))));

  std::vector<std::uint8_t> tex(std::size_t(K) * F * grid * C);
  std::vector<float> scales(std::size_t(K) * F, 0.0f);
  double max_q = 0;
  for (int k = 0; k < K; ++k) {
    rep.Progress(std::size_t(k), std::size_t(K), "resample");
    for (int f = 0; f < F; ++f) {
      const float* fn = f == 0 ? &m.means[std::size_t(k) * d] : &m.basis[(std::size_t(k) * m.components + f - 1) * d];
      // Resample: value[z = tl * nl + sl][tv][sv][ch], z = slab index * nl + s_l index.
      std::vector<double> vals(grid * C);
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
      double scale = 0;
      for (double v : vals) scale = std::max(scale, std::abs(v));
      scales[std::size_t(k) * F + f] = static_cast<float>(scale);
      const float sc = scales[std::size_t(k) * F + f];
      std::uint8_t* out = &tex[(std::size_t(k) * F + f) * grid * C];
      for (std::size_t i = 0; i < vals.size(); ++i) {
        // Signed normalized 8 bits: q in 0..255 stands for q / 127.5 - 1 in [-1, 1].
        const double u = sc > 0 ? vals[i] / sc : 0.0;
        const long q = std::lround((u + 1.0) * 127.5);
        out[i] = static_cast<std::uint8_t>(std::clamp(q, 0L, 255L));
        max_q = std::max(max_q, std::abs((out[i] / 127.5 - 1.0) - u));
      }
    }
  }
  s.times.Add("resample", timer.Seconds());
  timer.Restart();
  std::vector<float> weights(T * F);
  std::vector<std::uint16_t> index(T);
  for (std::size_t t = 0; t < T; ++t) {
    const int k = m.cluster_of[t];
    index[t] = static_cast<std::uint16_t>(k);
    weights[t * F] = scales[std::size_t(k) * F];
    for (int j = 0; j < c; ++j)
      weights[t * F + 1 + j] = (j < m.cluster_components[static_cast<std::size_t>(k)] ? m.weights[t * m.components + j] : 0.0f) *
                               scales[std::size_t(k) * F + 1 + j];
  }
  s.texture_bytes = WriteBinary(dir / "eigen_abrdfs.u8", tex);
  s.weight_bytes = WriteBinary(dir / "weights.f32", weights);
  s.index_bytes = WriteBinary(dir / "cluster_index.u16", index);
  WriteBinary(dir / "scales.f32", scales);

  nlohmann::json j;
  j["format"] = kSchneiderExportFormat;
  j["format_version"] = kSchneiderExportVersion;
  j["source"] = {{"codec_method", "lpca"}, {"view_sampling", codec.views().name()},
                 {"light_sampling", codec.lights().name()}, {"compression", codec.provenance().value("options", nlohmann::json())}};
  j["texture"] = {{"height", codec.height()}, {"width", codec.width()}, {"channels", C},
                  {"channel_names", codec.info().channel_names}, {"row_0", "top (v = 1)"},
                  {"texel_of_uv", "x = floor(u * width), y = floor((1 - v) * height), wrapping"}};
  j["values"] = {{"units", codec.info().units}, {"color_space", codec.info().color_space},
                 {"cos_theta_i_included", codec.info().cos_theta_i_included}};
  j["parameterisation"] = {
      {"map", "elevated concentric (Schneider 2004 section 6.1): square -> Shirley-Chiu disk -> hemisphere with "
              "z = 1 - rho^2, (x, y) scaled by sqrt(2 - rho^2)"},
      {"frame", "z = surface normal, x = weft (texture u), y = warp (texture v)"},
      {"view", "(s_v, t_v) = square coordinates of the view direction wo"},
      {"light", "(s_l, t_l) = square coordinates of the light direction wi"},
      {"grid", "sample i of n on an axis sits at the cell centre (i + 0.5) / n"}};
  j["eigen_abrdfs"] = {
      {"file", "eigen_abrdfs.u8"},
      {"type", "uint8"},
      {"shape", {K, F, nl * nl, nv, nv, C}},
      {"dimension_names", {"cluster", "function", "z", "t_v", "s_v", "channel"}},
      {"functions", "function 0 = cluster mean, 1..c = Eigen-ABRDFs"},
      {"view_grid", nv},
      {"light_grid", nl},
      {"z_layout", "z = i * n_sl + j for slab i (t_l sample i) and s_l sample j: 3D texture of depth n_tl * n_sl"},
      {"decode_value", "q / 127.5 - 1 (signed normalised); the scale is folded into the weights"},
      {"lookup",
       "slab coordinate a = t_l * n_tl - 0.5: a <= 0 -> slab 0 only, a >= n_tl - 1 -> the last slab only, else "
       "i0 = floor(a), i1 = i0 + 1, w = a - i0; in each slab s_l is clamped half a texel inside "
       "[0.5 / n_sl, 1 - 0.5 / n_sl] so filtering never mixes neighbouring slabs; normalised 3D coordinates "
       "(s_v, t_v, (i + s_l_clamped) / n_tl) with trilinear filtering, clamp to edge; value = (1 - w) S_i0 + w S_i1"}};
  j["weights"] = {{"file", "weights.f32"}, {"type", "float32"}, {"shape", {codec.height(), codec.width(), F}},
                  {"meaning", "value = sum_f weights[y][x][f] * decode(eigen_abrdfs[cluster_index[y][x]][f] at (wo, wi))"}};
  j["cluster_index"] = {{"file", "cluster_index.u16"}, {"type", "uint16"}, {"shape", {codec.height(), codec.width()}}};
  j["scales"] = {{"file", "scales.f32"}, {"type", "float32"}, {"shape", {K, F}},
                 {"meaning", "max |function| over the grid; already multiplied into weights"}};
  j["quantisation_error_bound"] =
      "per value: sum_f |weights[f]| / 255 (half a step of 2/255 in each function's [-1, 1] range)";
  j["byte_order"] = "little-endian";
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
  s.max_quantization_error = max_q;
  rep.Progress(std::size_t(K), std::size_t(K), "resample");
  return s;
}

}  // namespace btf
