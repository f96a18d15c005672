#include "libbtf/export/neural.h"

#include <algorithm>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/export/export_common.h"
#include "libbtf/export/schneider.h"
#include "libbtf/io/half.h"

namespace btf {

using export_detail::WriteBinary;

nlohmann::json NeuralExportSummary::ToJson() const {
  return {{"directory", directory},
          {"layout", kNeuralLayout},
          {"latent", latent},
          {"latent_layers", latent_layers},
          {"storage", storage},
          {"inputs", inputs},
          {"hidden", hidden},
          {"activation", activation},
          {"decoder_parameters", parameters},
          {"decoder_texture", {{"width", decoder_texture_width}, {"height", decoder_texture_height}}},
          {"texture_bytes", texture_bytes},
          {"weight_bytes", weight_bytes},
          {"total_bytes", texture_bytes + weight_bytes},
          {"seconds", times.ToJson()}};
}

std::string NeuralExportSummary::Report() const {
  std::string widths;
  for (int h : hidden) widths += fmt::format("{}{}", widths.empty() ? "" : ",", h);
  return fmt::format("{}/ : {} latents per texel ({}, {} texture-array layer(s) of {} x {}), decoder {} -> {} -> {} "
                     "({}, {} parameters); latents {}, decoder {}; {}\n",
                     directory, latent, storage, latent_layers, width, height, inputs,
                     widths.empty() ? "-" : widths, channels, activation, parameters, FormatBytes(texture_bytes),
                     FormatBytes(weight_bytes), times.Report());
}

namespace {

// The codec's fitness for this export: neural, with latents, a decoder the GLSL can hold.
void CheckNeuralCodec(const Codec& codec) {
  if (codec.method() != CodecMethod::kNeural)
    ThrowUsage("the neural export needs a neural codec; this one is '{}' (export lpca codecs with --format "
               "schneider, pca-view codecs with --format sattler)",
               MethodName(codec.method()));
  const NeuralCodecModel& m = codec.neural();
  if (m.latent < 1) ThrowUsage("the neural export needs per-texel latents; this codec has none (--neural-latent 0)");
  int rows = 0;
  for (int l = 0; l < m.net.layers(); ++l) {
    const auto w = m.net.weight(l);
    if (w.rows() > kNeuralExportMaxWidth || w.cols() > kNeuralExportMaxWidth)
      ThrowUsage("the neural export's GLSL holds at most {} values per layer; this decoder's layer {} maps {} to {}",
                 kNeuralExportMaxWidth, l, w.cols(), w.rows());
    rows += int(w.rows());
  }
  if (rows > kNeuralExportMaxRows)
    ThrowUsage("the neural export's decoder texture needs {} rows (one per neuron; WebGL2 guarantees {})", rows,
               kNeuralExportMaxRows);
}

// latents.u8 (the codes) or latents.f16 (the halves), [layers][H][W][4], channels past c zero.
void StoreLatents(const NeuralCodecModel& m, std::size_t T, std::vector<std::uint8_t>* u8,
                  std::vector<std::uint16_t>* f16) {
  const int c = m.latent, layers = (c + 3) / 4;
  const bool half = m.storage == LatentStorage::kHalf;
  if (half)
    f16->assign(std::size_t(layers) * T * 4, 0);
  else
    u8->assign(std::size_t(layers) * T * 4, 0);
  for (std::size_t t = 0; t < T; ++t)
    for (int j = 0; j < c; ++j) {
      const std::size_t at = (std::size_t(j / 4) * T + t) * 4 + std::size_t(j % 4);
      if (half)
        (*f16)[at] = FloatToHalf(m.latents(j, Eigen::Index(t)));  // exactly a half already
      else
        (*u8)[at] = static_cast<std::uint8_t>(m.codes[t * std::size_t(c) + std::size_t(j)]);
    }
}

// decoder.f32: per layer [out][in + 1] row-major (weights, then the bias); the layer table of the
// manifest, with each layer's first row in the viewer's decoder texture.
std::vector<float> DecoderFloats(const NeuralNet& net, nlohmann::json* layers, int* texture_width, int* rows) {
  std::vector<float> v;
  *layers = nlohmann::json::array();
  *texture_width = 0, *rows = 0;
  for (int l = 0; l < net.layers(); ++l) {
    const auto W = net.weight(l);
    const auto b = net.bias(l);
    const int in = int(W.cols()), out = int(W.rows());
    const bool hidden = l + 1 < net.layers();
    layers->push_back({{"inputs", in}, {"outputs", out}, {"offset", v.size()}, {"first_row", *rows},
                       {"activation", hidden ? std::string(ActivationName(net.shape().activation)) : "linear"}});
    for (int o = 0; o < out; ++o) {
      for (int i = 0; i < in; ++i) v.push_back(W(o, i));
      v.push_back(b(o));
    }
    *texture_width = std::max(*texture_width, (in + 1 + 3) / 4);
    *rows += out;
  }
  return v;
}

nlohmann::json LatentsJson(const Codec& codec, const std::string& file) {
  const NeuralCodecModel& m = codec.neural();
  const bool half = m.storage == LatentStorage::kHalf;
  const int c = m.latent, layers = (c + 3) / 4;
  nlohmann::json j = {
      {"file", file},
      {"count", c},
      {"storage", half ? "f16" : "u8"},
      {"type", half ? "float16" : "uint8"},
      {"webgl_format", half ? "RGBA16F / RGBA / HALF_FLOAT" : "RGBA8 / RGBA / UNSIGNED_BYTE"},
      {"target", "TEXTURE_2D_ARRAY, NEAREST (read with texelFetch)"},
      {"shape", {layers, codec.height(), codec.width(), 4}},
      {"dimension_names", {"layer", "y", "x", "channel"}},
      {"layers", layers},
      {"latent_of_channel", "latent j = layer * 4 + channel; channels past count are 0"},
      {"decode_value", half ? "z_j = the half float as stored"
                            : "z_j = float(double(bias[j]) + double(scale[j]) * q), q the stored code 0..255 (a GPU "
                              "sampling the unsigned normalised texture reads q / 255: q = round(255 * texel))"}};
  if (!half) {
    j["scale"] = m.scale;
    j["bias"] = m.bias;
  }
  return j;
}

nlohmann::json NeuralManifest(const Codec& codec, const std::string& latents_file, const nlohmann::json& layers,
                              int texture_width, int rows) {
  const NeuralCodecModel& m = codec.neural();
  const int E = m.encoding.Width();
  nlohmann::json j;
  j["format"] = kSchneiderExportFormat;
  j["format_version"] = kSchneiderExportVersion;
  j["layout"] = kNeuralLayout;
  j["source"] = {{"codec_method", "neural"}, {"view_sampling", codec.views().name()},
                 {"light_sampling", codec.lights().name()}, {"compression", codec.provenance().value("options", nlohmann::json())}};
  j["texture"] = export_detail::TextureJson(codec);
  j["values"] = export_detail::ValuesJson(codec);
  j["frame"] = "z = surface normal, x = weft (texture u), y = warp (texture v)";
  j["latents"] = LatentsJson(codec, latents_file);
  j["encoding"] = {
      {"half_vector", m.encoding.half_vector},
      {"fourier", m.encoding.fourier},
      {"width", E},
      {"formula", "wi, wo unit vectors (normalised); e = (wi.x, wi.y, wo.x, wo.y); with half_vector: h = wi + wo, "
                  "(h.x, h.y) / |h| ((0, 0) where |h|^2 <= 1e-24); then for k = 0..fourier-1 and each of the 4 first "
                  "values b: sin(2^k pi b), cos(2^k pi b)"}};
  j["decoder"] = {
      {"file", "decoder.f32"},
      {"type", "float32"},
      {"parameters", m.net.parameter_count()},
      {"inputs", m.latent + E},
      {"input", "x = (z_0 .. z_(c-1), e_0 .. e_(E-1)): the texel's latents, then the direction encoding"},
      {"layers", layers},
      {"layout", "layer n at offset_n: float32 [outputs][inputs + 1] row-major, row o = (W_n[o][0 .. inputs - 1], "
                 "b_n[o])"},
      {"forward", "a_0 = x; a_(n+1) = act(W_n a_n + b_n) for hidden layers; y = W_last a_last + b_last"},
      {"activations", "silu: z / (1 + exp(-z)); relu: max(z, 0); leaky_relu: z > 0 ? z : 0.01 z; softplus: "
                      "max(z, 0) + log(1 + exp(-|z|)); linear: z"},
      {"texture", {{"width", texture_width}, {"height", rows}, {"format", "RGBA32F"},
                   {"meaning", "row first_row_n + o = layer n's row o, texel j = its values 4j .. 4j + 3, zero-padded"}}}};
  const bool log = codec.transform() == ValueTransform::kLog;
  j["output"] = {{"transform", log ? "log" : "none"},
                 {"epsilon", log ? codec.log_epsilon() : 0.0},
                 {"value", log ? "exp(y) - epsilon" : "y"},
                 {"channels", "y has C values; the GLSL returns the first three (1 channel: replicated)"}};
  j["glsl"] = {{"file", "btf_neural.glsl"}, {"function", "vec3 btf_eval(vec2 uv, vec3 wi, vec3 wo)"}};
  j["byte_order"] = "little-endian";
  return j;
}

}  // namespace

NeuralExportSummary ExportNeural(const Codec& codec, const std::filesystem::path& out_dir, const Reporter& rep) {
  CheckNeuralCodec(codec);
  Timer timer;
  const NeuralCodecModel& m = codec.neural();
  const std::size_t T = std::size_t(codec.height()) * codec.width();
  AtomicDirectory output(out_dir, "manifest.json");
  const std::filesystem::path& dir = output.temp_path();
  rep.Progress(0, 2, "export");
  std::vector<std::uint8_t> u8;
  std::vector<std::uint16_t> f16;
  StoreLatents(m, T, &u8, &f16);
  const bool half = m.storage == LatentStorage::kHalf;
  const std::string latents_file = half ? "latents.f16" : "latents.u8";
  NeuralExportSummary s;
  s.texture_bytes = half ? WriteBinary(dir / latents_file, f16) : WriteBinary(dir / latents_file, u8);
  nlohmann::json layers;
  const std::vector<float> decoder = DecoderFloats(m.net, &layers, &s.decoder_texture_width, &s.decoder_texture_height);
  s.weight_bytes = WriteBinary(dir / "decoder.f32", decoder);
  rep.Progress(1, 2, "export");
  nlohmann::json j = NeuralManifest(codec, latents_file, layers, s.decoder_texture_width, s.decoder_texture_height);
  WriteTextFileAtomic(dir / "btf_neural.glsl", NeuralGlsl(j));
  j["checksums"] = export_detail::ExportChecksums(dir);
  WriteTextFileAtomic(dir / "manifest.json", j.dump(2) + "\n");
  output.Commit();
  s.times.Add("write", timer.Seconds());
  s.directory = out_dir.string();
  s.latent = m.latent;
  s.latent_layers = (m.latent + 3) / 4;
  s.height = codec.height(), s.width = codec.width(), s.channels = codec.channels();
  s.storage = half ? "f16" : "u8";
  s.inputs = m.net.shape().inputs;
  s.hidden = m.net.shape().hidden;
  s.activation = std::string(ActivationName(m.net.shape().activation));
  s.parameters = m.net.parameter_count();
  rep.Progress(2, 2, "export");
  return s;
}

}  // namespace btf
