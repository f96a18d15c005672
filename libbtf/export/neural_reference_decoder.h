#pragma once
// Header-only reference decoder of the neural export (libbtf/export/neural.h, layout neural-mlp of
// format 2.2+): reads the folder through manifest.json alone and evaluates a value as
// docs/format.md ("Neural layout") defines it, in double: the nearest texel's latents
// (dequantised from the codes), the direction encoding, the decoder MLP, exp(y) - epsilon.
// btf_neural.glsl computes the same in float32. It needs no other part of libbtf (not the codec
// code): tests check it against Codec::Value and the GLSL in a browser.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"
#include "libbtf/core/error.h"
#include "libbtf/export/export_reader.h"

namespace btf {

class NeuralReferenceDecoder {
 public:
  explicit NeuralReferenceDecoder(const std::filesystem::path& dir) {
    using namespace export_detail;
    const nlohmann::json j = ReadExportManifest(dir, "neural-mlp");
    channels_ = j.at("texture").at("channels");
    height_ = j.at("texture").at("height");
    width_ = j.at("texture").at("width");
    cos_theta_i_included_ = JsonFlag(j.at("values").at("cos_theta_i_included"));
    const auto& lat = j.at("latents");
    latent_ = lat.at("count");
    const int layers = lat.at("layers");
    const std::size_t T = std::size_t(height_) * width_;
    if (latent_ < 1 || layers != (latent_ + 3) / 4 || height_ < 1 || width_ < 1 || channels_ < 1)
      ThrowBadInput("'{}': latents count {}, layers {}, texture {} x {} x {} do not fit", dir.string(), latent_, layers,
                    width_, height_, channels_);
    const std::string storage = lat.at("storage"), file = lat.at("file");
    latents_.assign(T * latent_, 0.0);
    if (storage == "u8") {
      const auto q = LoadExportFile<std::uint8_t>(dir / file, std::size_t(layers) * T * 4);
      const auto scale = lat.at("scale").get<std::vector<float>>(), bias = lat.at("bias").get<std::vector<float>>();
      if (int(scale.size()) != latent_ || int(bias.size()) != latent_)
        ThrowBadInput("'{}': latents.scale and latents.bias need {} values each", dir.string(), latent_);
      for (std::size_t t = 0; t < T; ++t)
        for (int k = 0; k < latent_; ++k)
          latents_[t * latent_ + k] =
              static_cast<float>(double(bias[k]) + double(scale[k]) * q[(std::size_t(k / 4) * T + t) * 4 + k % 4]);
    } else if (storage == "f16") {
      const auto h = LoadExportFile<std::uint16_t>(dir / file, std::size_t(layers) * T * 4);
      for (std::size_t t = 0; t < T; ++t)
        for (int k = 0; k < latent_; ++k) latents_[t * latent_ + k] = HalfToFloat(h[(std::size_t(k / 4) * T + t) * 4 + k % 4]);
    } else {
      ThrowBadInput("'{}': unknown latent storage '{}' (u8 or f16)", dir.string(), storage);
    }
    const auto& enc = j.at("encoding");
    half_vector_ = JsonFlag(enc.at("half_vector"));
    fourier_ = enc.at("fourier");
    if (fourier_ < 0 || fourier_ > 8 || enc.at("width").get<int>() != 4 + 2 * half_vector_ + 8 * fourier_)
      ThrowBadInput("'{}': encoding width does not match half_vector and fourier", dir.string());
    const auto& dec = j.at("decoder");
    std::size_t params = 0;
    for (const auto& l : dec.at("layers")) {
      Layer layer{l.at("inputs"), l.at("outputs"), l.at("offset"), l.at("activation")};
      const int expected_in = layers_.empty() ? latent_ + enc.at("width").get<int>() : layers_.back().outputs;
      if (layer.inputs != expected_in || layer.outputs < 1 || layer.offset != params)
        ThrowBadInput("'{}': decoder layer {} ({} -> {} at {}) does not chain", dir.string(), layers_.size(), layer.inputs,
                      layer.outputs, layer.offset);
      Activate(layer.activation, 0.0);  // refuses an unknown activation now
      params += std::size_t(layer.outputs) * (layer.inputs + 1);
      layers_.push_back(layer);
    }
    if (layers_.empty() || layers_.back().outputs != channels_ || layers_.back().activation != "linear")
      ThrowBadInput("'{}': the decoder's last layer must be linear with {} outputs", dir.string(), channels_);
    weights_ = LoadExportFile<float>(dir / dec.at("file").get<std::string>(), params);
    const auto& out = j.at("output");
    log_ = out.at("transform") == "log";
    epsilon_ = out.at("epsilon");
  }

  int height() const { return height_; }
  int width() const { return width_; }
  int channels() const { return channels_; }
  int latent() const { return latent_; }
  bool cos_theta_i_included() const { return cos_theta_i_included_; }
  bool log_transform() const { return log_; }
  double log_epsilon() const { return epsilon_; }
  // The stored latents of texel (x, y), dequantised.
  const float* latents(int x, int y) const { return &latents_[(std::size_t(y) * width_ + x) * latent_]; }

  // The decoder's outputs y (before the output transform) at texel (x, y) for light wi and view
  // wo: channels() values.
  std::vector<double> Outputs(int x, int y, const Vec3& wi_in, const Vec3& wo_in) const {
    const Vec3 wi = wi_in.normalized(), wo = wo_in.normalized();
    std::vector<double> a(latents(x, y), latents(x, y) + latent_);
    const double base[4] = {wi.x(), wi.y(), wo.x(), wo.y()};
    a.insert(a.end(), base, base + 4);
    if (half_vector_) {
      const Vec3 h = wi + wo;
      const double n2 = h.squaredNorm(), s = n2 > 1e-24 ? 1 / std::sqrt(n2) : 0.0;
      a.push_back(h.x() * s);
      a.push_back(h.y() * s);
    }
    for (int f = 0; f < fourier_; ++f)
      for (double b : base) {
        a.push_back(std::sin(std::ldexp(std::numbers::pi, f) * b));
        a.push_back(std::cos(std::ldexp(std::numbers::pi, f) * b));
      }
    for (const Layer& l : layers_) {
      std::vector<double> z(std::size_t(l.outputs));
      for (int o = 0; o < l.outputs; ++o) {
        const float* row = &weights_[l.offset + std::size_t(o) * (l.inputs + 1)];
        double s = row[l.inputs];
        for (int i = 0; i < l.inputs; ++i) s += double(row[i]) * a[std::size_t(i)];
        z[std::size_t(o)] = Activate(l.activation, s);
      }
      a.swap(z);
    }
    return a;
  }

  // Value at texel (x, y) (nearest-texel lookup, as the other exports) for light wi and view wo:
  // out has channels() floats.
  void Value(int x, int y, const Vec3& wi, const Vec3& wo, float* out) const {
    const std::vector<double> y_out = Outputs(x, y, wi, wo);
    for (int ch = 0; ch < channels_; ++ch)
      out[ch] = static_cast<float>(log_ ? std::exp(y_out[std::size_t(ch)]) - epsilon_ : y_out[std::size_t(ch)]);
  }

 private:
  struct Layer {
    int inputs = 0, outputs = 0;
    std::size_t offset = 0;
    std::string activation;
  };

  static double Activate(const std::string& act, double z) {
    if (act == "linear") return z;
    if (act == "silu") return z / (1 + std::exp(-z));
    if (act == "relu") return std::max(z, 0.0);
    if (act == "leaky_relu") return z > 0 ? z : 0.01 * z;
    if (act == "softplus") return std::max(z, 0.0) + std::log1p(std::exp(-std::abs(z)));
    ThrowBadInput("neural export: unknown activation '{}'", act);
  }

  int channels_ = 0, height_ = 0, width_ = 0, latent_ = 0, fourier_ = 0;
  bool cos_theta_i_included_ = false, half_vector_ = false, log_ = false;
  double epsilon_ = 0;
  std::vector<float> latents_;  // [H][W][latent], as stored (dequantised to float as the codec does)
  std::vector<Layer> layers_;
  std::vector<float> weights_;
};

}  // namespace btf
