#pragma once
// Header-only reference decoder of the Sattler export (libbtf/export/sattler.h, layout
// sattler-2003 of format 2.1+): reads the folder through manifest.json and evaluates a value the
// way btf_sattler.glsl does: the three nearest views and lights with barycentric weights
// (Sampling::Barycentric, as Codec::Value), and per view the terms of its lights applied to the
// view's images at the nearest texel. Tests check it against Codec::Value and the GLSL in a browser.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"
#include "libbtf/core/error.h"
#include "libbtf/export/export_reader.h"

namespace btf {

class SattlerReferenceDecoder {
 public:
  explicit SattlerReferenceDecoder(const std::filesystem::path& dir) {
    using namespace export_detail;
    const nlohmann::json j = ReadExportManifest(dir, "sattler-2003");
    auto sampling = [&](const char* key) {
      std::vector<Vec3> d;
      for (const auto& v : j.at(key).at("directions")) d.emplace_back(v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>());
      if (d.size() < 3 || int(d.size()) != j.at(key).at("count").get<int>())
        ThrowBadInput("'{}': '{}' must list 'count' (>= 3) directions", dir.string(), key);
      return Sampling(std::string("export ") + key, std::move(d));
    };
    views_ = sampling("views");
    lights_ = sampling("lights");
    functions_ = j.at("functions").at("count_per_view");
    channels_ = j.at("texture").at("channels");
    height_ = j.at("texture").at("height");
    width_ = j.at("texture").at("width");
    cos_theta_i_included_ = JsonFlag(j.at("values").at("cos_theta_i_included"));
    const auto& im = j.at("images");
    aw_ = im.at("width");
    ah_ = im.at("height");
    layers_ = im.at("layers");
    tiles_x_ = im.at("tiles_x");
    tiles_y_ = im.at("tiles_y");
    if (functions_ < 1 || aw_ != tiles_x_ * width_ || ah_ != tiles_y_ * height_ ||
        layers_ * tiles_x_ * tiles_y_ < views_.size() * functions_)
      ThrowBadInput("'{}': image layout does not fit the texture size, view count and image count", dir.string());
    quantization_bound_ = j.at("quantisation_error_bound").at("per_t");
    tex_ = LoadNormalised(dir / im.at("file").get<std::string>(), im.at("storage").get<std::string>(),
                          std::size_t(layers_) * ah_ * aw_ * channels_);
    terms_ = LoadExportFile<float>(dir / j.at("terms").at("file").get<std::string>(),
                                   std::size_t(views_.size()) * lights_.size() * (1 + functions_));
  }

  int height() const { return height_; }
  int width() const { return width_; }
  int channels() const { return channels_; }
  int functions() const { return functions_; }
  bool cos_theta_i_included() const { return cos_theta_i_included_; }
  double quantization_bound() const { return quantization_bound_; }
  // Terms of (view, light): [0] = offset, [1 + f] = weight of image f (scale folded in).
  const float* terms(int view, int light) const {
    return &terms_[(std::size_t(view) * lights_.size() + light) * (1 + functions_)];
  }
  // Bound on |Value - Codec::Value (nearest texel)| from the storage:
  // sum_a bv_a sum_f |sum_b bl_b terms[v_a][l_b][1 + f]| * per_t.
  double ErrorBound(const Vec3& wi, const Vec3& wo) const {
    const Interpolant iv = views_.Barycentric(wo), il = lights_.Barycentric(wi);
    double b = 0;
    for (int a = 0; a < iv.count; ++a)
      for (int f = 0; f < functions_; ++f) {
        double w = 0;
        for (int k = 0; k < il.count; ++k) w += il.weight[k] * terms(iv.index[a], il.index[k])[1 + f];
        b += iv.weight[a] * std::abs(w) * quantization_bound_;
      }
    return b;
  }

  // Value at texel (x, y) for light wi and view wo: out has channels() floats.
  void Value(int x, int y, const Vec3& wi, const Vec3& wo, float* out) const {
    const Interpolant iv = views_.Barycentric(wo), il = lights_.Barycentric(wi);
    std::vector<double> acc(static_cast<std::size_t>(channels_), 0.0);
    for (int a = 0; a < iv.count; ++a) {
      if (iv.weight[a] <= 0) continue;
      const int v = iv.index[a];
      for (int f = 0; f <= functions_; ++f) {  // term 0 = offset, 1 + f' = image f'
        double w = 0;
        for (int k = 0; k < il.count; ++k) w += il.weight[k] * terms(v, il.index[k])[f];
        w *= iv.weight[a];
        for (int ch = 0; ch < channels_; ++ch)
          acc[static_cast<std::size_t>(ch)] += f == 0 ? w : w * Texel(v * functions_ + f - 1, x, y, ch);
      }
    }
    for (int ch = 0; ch < channels_; ++ch) out[ch] = static_cast<float>(acc[static_cast<std::size_t>(ch)]);
  }

 private:
  double Texel(int g, int x, int y, int ch) const {
    const int per_layer = tiles_x_ * tiles_y_, layer = g / per_layer, tx = g % tiles_x_, ty = (g / tiles_x_) % tiles_y_;
    return tex_[((std::size_t(layer) * ah_ + std::size_t(ty) * height_ + y) * aw_ + std::size_t(tx) * width_ + x) * channels_ + ch];
  }

  Sampling views_, lights_;
  int functions_ = 0, channels_ = 0, height_ = 0, width_ = 0, aw_ = 0, ah_ = 0, layers_ = 0, tiles_x_ = 0, tiles_y_ = 0;
  double quantization_bound_ = 0;
  bool cos_theta_i_included_ = false;
  std::vector<float> tex_;  // normalised values t, as a GPU reads them
  std::vector<float> terms_;
};

}  // namespace btf
