#include "libbtf/export/sattler.h"

#include <algorithm>
#include <cmath>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/export/export_common.h"
#include "libbtf/export/schneider.h"

namespace btf {

using export_detail::NormalisedStore;
using export_detail::WriteBinary;

void SattlerExportOptions::Check() const {
  BTF_CHECK_OPTION(components >= -1, "components", "must be >= 0, or -1 for all");
  BTF_CHECK_OPTION(storage == "u8" || storage == "f16", "storage", "must be u8 or f16");
  BTF_CHECK_OPTION(atlas_side >= 16 && atlas_side <= 16384, "atlas_side", "must be 16..16384");
}

nlohmann::json SattlerExportSummary::ToJson() const {
  return {{"directory", directory},
          {"layout", kSattlerLayout},
          {"views", views},
          {"lights", lights},
          {"functions_per_view", functions},
          {"storage", storage},
          {"images", {{"width", layer_width}, {"height", layer_height}, {"layers", layers}, {"tiles_x", tiles_x},
                      {"tiles_y", tiles_y}}},
          {"texture_bytes", texture_bytes},
          {"weight_bytes", weight_bytes},
          {"total_bytes", texture_bytes + weight_bytes},
          {"max_quantisation_error_in_scale_units", max_quantization_error},
          {"seconds", times.ToJson()}};
}

std::string SattlerExportSummary::Report() const {
  return fmt::format("{}/ : {} views x {} images (mean + eigen-textures) of {} x {}, {} texture array {} x {} x {} "
                     "layer(s); weights for {} lights; textures {}, weights {}; {}\n",
                     directory, views, functions, width, height, storage, layer_width, layer_height, layers, lights,
                     FormatBytes(texture_bytes), FormatBytes(weight_bytes), times.Report());
}

namespace {

// The texture array: image g = v * F + f is tile (g % tiles_x, (g / tiles_x) % tiles_y) of layer
// g / per_layer; a tile is one W x H image.
struct SattlerAtlas {
  int tiles_x = 0, tiles_y = 0, per_layer = 0, layers = 0;
  int width = 0, height = 0;
};

// The codec's fitness for this export (pca-view, no value transform, >= 3 views and lights, an
// image that fits a tile).
void CheckSattlerCodec(const SattlerExportOptions& o, const Codec& codec) {
  if (codec.method() != CodecMethod::kPcaView)
    ThrowUsage("the sattler export needs a pca-view codec; this one is '{}' (compress with --method pca-view, or "
               "export an lpca codec with --format schneider, a neural codec with --format neural)",
               MethodName(codec.method()));
  if (codec.transform() != ValueTransform::kNone)
    ThrowUsage("the sattler export needs a codec without value transform (the renderer sums weighted images "
               "linearly); compress without --log");
  const int V = codec.num_views(), L = codec.num_lights(), W = codec.width(), H = codec.height();
  if (V < 3 || L < 3)
    ThrowUsage("the sattler export blends the three nearest sampled directions; this codec has {} view(s) and {} "
               "light(s) (need >= 3 each)", V, L);
  if (W > o.atlas_side || H > o.atlas_side)
    ThrowUsage("invalid option 'atlas_side': {} is smaller than the {} x {} texture (one image per tile; WebGL2 "
               "allows up to 2048)", o.atlas_side, W, H);
}

SattlerAtlas PlanAtlas(const SattlerExportOptions& o, int images, int W, int H) {
  SattlerAtlas a;
  a.tiles_x = std::min(images, o.atlas_side / W);
  a.tiles_y = std::min((images + a.tiles_x - 1) / a.tiles_x, o.atlas_side / H);
  a.per_layer = a.tiles_x * a.tiles_y;
  a.layers = (images + a.per_layer - 1) / a.per_layer;
  if (a.layers > 256)
    ThrowUsage("the export needs {} texture-array layers (WebGL2 guarantees 256); raise --atlas-side (now {}, up to "
               "2048) or export fewer components (--components)", a.layers, o.atlas_side);
  a.width = a.tiles_x * W, a.height = a.tiles_y * H;
  return a;
}

// Quantises image g (H x W x C values, or all zero when img is null) into its tile, with the
// scale and bias that make t = (value - bias) / scale span [0, 1] exactly (all 256 codes in use),
// stored in scale_bias. Returns the largest quantisation error of t.
double StoreImage(const float* img, int g, const SattlerAtlas& atlas, int H, int W, int C, NormalisedStore* store,
                  std::vector<float>* scale_bias) {
  const std::size_t D = std::size_t(H) * W * C;
  double lo = 0, hi = 0;
  if (img) {
    lo = hi = img[0];
    for (std::size_t i = 0; i < D; ++i) lo = std::min(lo, double(img[i])), hi = std::max(hi, double(img[i]));
  }
  const float bias = static_cast<float>(lo), scale = static_cast<float>(hi - lo);
  (*scale_bias)[std::size_t(g) * 2] = scale;
  (*scale_bias)[std::size_t(g) * 2 + 1] = bias;
  const int layer = g / atlas.per_layer, tx = g % atlas.tiles_x, ty = (g / atlas.tiles_x) % atlas.tiles_y;
  const int AH = atlas.height, AW = atlas.width;
  double max_q = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int ch = 0; ch < C; ++ch) {
        const double val = img ? img[(std::size_t(y) * W + x) * C + ch] : 0.0;
        const double t = scale > 0 ? std::clamp((val - bias) / double(scale), 0.0, 1.0) : 0.0;
        const std::size_t at =
            ((std::size_t(layer) * AH + std::size_t(ty) * H + y) * AW + std::size_t(tx) * W + x) * C + ch;
        max_q = std::max(max_q, std::abs(store->Put(at, t) - t));
      }
  return max_q;
}

// Terms of (v, l) for every light l of view slot s (c components exported, F = 1 + c images per
// view): offset = bias_0 + sum_k w_k bias_(1+k); weight 0 = scale_0, 1 + k: w_k scale_(1+k).
void FoldViewTerms(const PcaViewSlot& s, int v, int L, int c, const std::vector<float>& scale_bias,
                   std::vector<float>* terms) {
  const int F = 1 + c, NT = 1 + F;
  for (int l = 0; l < L; ++l) {
    float* tm = &(*terms)[(std::size_t(v) * L + l) * NT];
    double offset = scale_bias[std::size_t(v) * F * 2 + 1];
    tm[1] = scale_bias[std::size_t(v) * F * 2];
    for (int k = 0; k < std::min(c, s.components); ++k) {
      const double w = s.weights[std::size_t(l) * s.components + k];
      const std::size_t g = std::size_t(v) * F + 1 + k;
      offset += w * scale_bias[g * 2 + 1];
      tm[2 + k] = static_cast<float>(w * scale_bias[g * 2]);
    }
    tm[0] = static_cast<float>(offset);
  }
}

nlohmann::json DirectionsJson(const Sampling& sm) {
  nlohmann::json a = nlohmann::json::array();
  for (const Vec3& d : sm.directions()) a.push_back({d.x(), d.y(), d.z()});
  return a;
}

nlohmann::json SattlerManifest(const SattlerExportOptions& o, const Codec& codec, const SattlerAtlas& atlas, int F,
                               const std::string& images_file) {
  const bool half = o.storage == "f16";
  const int V = codec.num_views(), L = codec.num_lights(), W = codec.width(), H = codec.height(), C = codec.channels();
  const int NT = 1 + F, AW = atlas.width, AH = atlas.height, layers = atlas.layers;
  nlohmann::json j;
  j["format"] = kSchneiderExportFormat;
  j["format_version"] = kSchneiderExportVersion;
  j["layout"] = kSattlerLayout;
  j["source"] = {{"codec_method", "pca-view"}, {"view_sampling", codec.views().name()},
                 {"light_sampling", codec.lights().name()}, {"compression", codec.provenance().value("options", nlohmann::json())}};
  j["texture"] = export_detail::TextureJson(codec);
  j["values"] = export_detail::ValuesJson(codec);
  j["frame"] = "z = surface normal, x = weft (texture u), y = warp (texture v)";
  j["views"] = {{"count", V}, {"directions", DirectionsJson(codec.views())}};
  j["lights"] = {{"count", L}, {"directions", DirectionsJson(codec.lights())}};
  j["interpolation"] =
      "for wo among the view directions and for wi among the light directions: the three with the largest dot "
      "product (ties keep the lower index first), barycentric weights a solving [d0 d1 d2] a = w (a = (1, 0, 0) if "
      "singular), clamped to >= 0 and divided by their sum (a = (1, 0, 0) if the sum is 0)";
  j["functions"] = {{"count_per_view", F}, {"meaning", "image 0 = the view's mean image, 1..c = its eigen-textures"}};
  j["images"] = {
      {"file", images_file},
      {"type", half ? "float16" : "uint8"},
      {"storage", o.storage},
      {"webgl_format", export_detail::WebGlFormat(half, C)},
      {"target", "TEXTURE_2D_ARRAY, NEAREST (read with texelFetch)"},
      {"shape", {layers, AH, AW, C}},
      {"dimension_names", {"layer", "y", "x", "channel"}},
      {"width", AW}, {"height", AH}, {"layers", layers},
      {"tiles_x", atlas.tiles_x}, {"tiles_y", atlas.tiles_y}, {"tile_width", W}, {"tile_height", H},
      {"max_side", o.atlas_side},
      {"tile_of_image",
       "g = view * F + f; layer = g / (tiles_x * tiles_y), tile column = g % tiles_x, tile row = (g / tiles_x) % tiles_y"},
      {"decode_value", half ? "t = the half float as stored, in [0, 1]" : "t = q / 255 (unsigned normalised), in [0, 1]"}};
  j["terms"] = {
      {"file", "terms.f32"}, {"type", "float32"}, {"shape", {V, L, NT}},
      {"meaning", "value(x, y, wi, wo) = sum_a bv_a sum_b bl_b (terms[v_a][l_b][0] + sum_f terms[v_a][l_b][1 + f] * "
                  "t_f(v_a, x, y)) over the interpolation's views v_a (weights bv_a) and lights l_b (weights bl_b); "
                  "term 0 = bias_0 + sum_k w_k bias_(1 + k), term 1 = scale_0, term 2 + k = w_k scale_(1 + k) with "
                  "the codec's weight w_k of light l_b in view v_a"}};
  j["scale_bias"] = {{"file", "scale_bias.f32"}, {"type", "float32"}, {"shape", {V, F, 2}},
                     {"meaning", "image value = bias + scale * t, t in [0, 1] (min and max over the image); already "
                                 "folded into terms"}};
  j["quantisation_error_bound"] = {
      {"per_t", StorageQuantizationBound(o.storage)},
      {"per_value", fmt::format("sum_a bv_a sum_f |sum_b bl_b terms[v_a][l_b][1 + f]| * {}",
                                StorageQuantizationBound(o.storage))}};
  j["glsl"] = {{"file", "btf_sattler.glsl"}, {"function", "vec3 btf_eval(vec2 uv, vec3 wi, vec3 wo)"}};
  j["byte_order"] = "little-endian";
  return j;
}

}  // namespace

SattlerExportSummary ExportSattler(const SattlerExportOptions& o, const Codec& codec, const std::filesystem::path& out_dir,
                                   const Reporter& rep) {
  o.Check();
  CheckSattlerCodec(o, codec);
  const int V = codec.num_views(), L = codec.num_lights(), W = codec.width(), H = codec.height(), C = codec.channels();
  int cmax = 0;
  for (const PcaViewSlot& s : codec.pca_view()) cmax = std::max(cmax, s.components);
  const int c = o.components < 0 ? cmax : std::min(o.components, cmax), F = 1 + c, NT = 1 + F, NT4 = (NT + 3) / 4;
  if (L * NT4 > 2048 || V > 2048)
    ThrowUsage("the terms texture ({} x {} texels) exceeds WebGL2's guaranteed 2048; export fewer components "
               "(--components)", L * NT4, V);
  const int G = V * F;
  const SattlerAtlas atlas = PlanAtlas(o, G, W, H);
  Timer timer;
  AtomicDirectory output(out_dir, "manifest.json");
  const std::filesystem::path& dir = output.temp_path();
  const bool half = o.storage == "f16";
  const std::size_t D = codec.image_size();
  NormalisedStore store(half, std::size_t(atlas.layers) * atlas.height * atlas.width * C);
  std::vector<float> scale_bias(std::size_t(G) * 2, 0.0f), terms(std::size_t(V) * L * NT, 0.0f);
  double max_q = 0;
  for (int v = 0; v < V; ++v) {
    rep.Progress(std::size_t(v), std::size_t(V), "quantise");
    const PcaViewSlot& s = codec.pca_view()[static_cast<std::size_t>(v)];
    for (int f = 0; f < F; ++f) {
      const bool present = f == 0 || f - 1 < s.components;  // absent components stay t = 0, scale 0
      const float* img = !present ? nullptr : f == 0 ? s.mean.data() : &s.basis[std::size_t(f - 1) * D];
      max_q = std::max(max_q, StoreImage(img, v * F + f, atlas, H, W, C, &store, &scale_bias));
    }
    FoldViewTerms(s, v, L, c, scale_bias, &terms);
  }
  SattlerExportSummary s;
  s.times.Add("quantise", timer.Seconds());
  timer.Restart();
  const std::string images_file = half ? "images.f16" : "images.u8";
  s.texture_bytes = store.Write(dir / images_file);
  s.weight_bytes = WriteBinary(dir / "terms.f32", terms);
  WriteBinary(dir / "scale_bias.f32", scale_bias);

  nlohmann::json j = SattlerManifest(o, codec, atlas, F, images_file);
  WriteTextFileAtomic(dir / "btf_sattler.glsl", SattlerGlsl(j));
  j["checksums"] = export_detail::ExportChecksums(dir);
  WriteTextFileAtomic(dir / "manifest.json", j.dump(2) + "\n");
  output.Commit();
  s.times.Add("write", timer.Seconds());
  s.directory = out_dir.string();
  s.views = V, s.lights = L, s.functions = F, s.height = H, s.width = W, s.channels = C;
  s.storage = o.storage;
  s.layer_width = atlas.width, s.layer_height = atlas.height, s.layers = atlas.layers;
  s.tiles_x = atlas.tiles_x, s.tiles_y = atlas.tiles_y;
  s.max_quantization_error = max_q;
  rep.Progress(std::size_t(V), std::size_t(V), "quantise");
  return s;
}

}  // namespace btf
