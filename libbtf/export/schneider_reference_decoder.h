#pragma once
// Header-only reference decoder of the Schneider export (libbtf/export/schneider.h, format 2.x):
// reads the folder through manifest.json and evaluates a value the way a GPU shader would
// (trilinear fetches from the 3D texture atlas in two t_l slabs, lerped; btf_schneider.glsl is the
// same in GLSL). It needs only the manifest, the binary files and the elevated concentric map
// (libbtf/core/directions.h); tests check it against Codec::Value and against the GLSL in a browser.
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

class SchneiderReferenceDecoder {
 public:
  explicit SchneiderReferenceDecoder(const std::filesystem::path& dir) {
    using namespace export_detail;
    const nlohmann::json j = ReadExportManifest(dir, "schneider-2004");
    const auto& fn = j.at("functions");
    const auto& atlas = j.at("atlas");
    clusters_ = j.at("scale_bias").at("shape")[0];
    functions_ = fn.at("count_per_cluster");
    nv_ = fn.at("view_grid");
    nl_ = fn.at("light_grid");
    channels_ = j.at("texture").at("channels");
    cos_theta_i_included_ = JsonFlag(j.at("values").at("cos_theta_i_included"));
    height_ = j.at("texture").at("height");
    width_ = j.at("texture").at("width");
    aw_ = atlas.at("width");
    ah_ = atlas.at("height");
    ad_ = atlas.at("depth");
    pages_ = atlas.at("pages");
    tiles_x_ = atlas.at("tiles_x");
    tiles_y_ = atlas.at("tiles_y");
    if (ad_ != nl_ * nl_ || aw_ != tiles_x_ * nv_ || ah_ != tiles_y_ * nv_ ||
        pages_ * tiles_x_ * tiles_y_ < clusters_ * functions_)
      ThrowBadInput("'{}': atlas shape does not fit the grids and function count", dir.string());
    const std::size_t n = std::size_t(pages_) * ad_ * ah_ * aw_ * channels_;
    const std::string storage = atlas.at("storage");
    quantization_bound_ = j.at("quantisation_error_bound").at("per_t");
    tex_ = LoadNormalised(dir / atlas.at("file").get<std::string>(), storage, n);
    terms_ = LoadExportFile<float>(dir / j.at("terms").at("file").get<std::string>(), std::size_t(height_) * width_ * (1 + functions_));
    index_ = LoadExportFile<std::uint16_t>(dir / j.at("cluster_index").at("file").get<std::string>(), std::size_t(height_) * width_);
    for (auto k : index_)
      if (k >= clusters_) ThrowBadInput("'{}': cluster index {} >= {}", dir.string(), k, clusters_);
  }

  int height() const { return height_; }
  int width() const { return width_; }
  int channels() const { return channels_; }
  int functions() const { return functions_; }
  bool cos_theta_i_included() const { return cos_theta_i_included_; }
  // Terms of texel (x, y): [0] = offset, [1 + f] = weight of function f (scale folded in).
  const float* terms(int y, int x) const { return &terms_[(std::size_t(y) * width_ + x) * (1 + functions_)]; }
  // Largest |stored - exact| of a normalised function value t (manifest quantisation_error_bound.per_t).
  double quantization_bound() const { return quantization_bound_; }
  // Bound on |Value - exact resampled value| at grid nodes: sum_f |terms[1 + f]| * per_t.
  double ErrorBound(int x, int y) const {
    double b = 0;
    for (int f = 0; f < functions_; ++f) b += std::abs(terms(y, x)[1 + f]) * quantization_bound_;
    return b;
  }

  // Value at texel (x, y) (nearest-texel lookup, as the renderer's cluster index must be) for
  // light wi and view wo: out has channels() floats.
  void Value(int x, int y, const Vec3& wi, const Vec3& wo, float* out) const {
    const std::size_t t = std::size_t(y) * width_ + x;
    const int k = index_[t];
    const Vec2 v = SquareFromHemisphere(wo.normalized()), l = SquareFromHemisphere(wi.normalized());
    // Slabs along t_l (manual lerp), s_l clamped half a texel inside each slab.
    const double a = l.y() * nl_ - 0.5;
    int i0, i1;
    double w;
    if (a <= 0) {
      i0 = i1 = 0, w = 0;
    } else if (a >= nl_ - 1) {
      i0 = i1 = nl_ - 1, w = 0;
    } else {
      i0 = static_cast<int>(std::floor(a)), i1 = i0 + 1, w = a - i0;
    }
    const double sl = std::clamp(l.x() * nl_ - 0.5, 0.0, double(nl_ - 1));
    const float* tm = &terms_[t * (1 + functions_)];
    std::vector<double> acc(static_cast<std::size_t>(channels_), double(tm[0]));
    for (int f = 0; f < functions_; ++f) {
      const double wt = tm[1 + f];
      if (wt == 0) continue;
      const int g = k * functions_ + f;
      for (int ch = 0; ch < channels_; ++ch) {
        const double s0 = Fetch(g, i0, v, sl, ch), s1 = i1 == i0 ? s0 : Fetch(g, i1, v, sl, ch);
        acc[static_cast<std::size_t>(ch)] += wt * ((1 - w) * s0 + w * s1);
      }
    }
    for (int ch = 0; ch < channels_; ++ch) out[ch] = static_cast<float>(acc[static_cast<std::size_t>(ch)]);
  }

 private:
  // Normalised value t of texel (sv, tv, z) of function g (its tile in the atlas).
  double Texel(int g, int z, int tv, int sv, int ch) const {
    const int per_page = tiles_x_ * tiles_y_, page = g / per_page, tx = g % tiles_x_, ty = (g / tiles_x_) % tiles_y_;
    const std::size_t i =
        (((std::size_t(page) * ad_ + z) * ah_ + std::size_t(ty) * nv_ + tv) * aw_ + std::size_t(tx) * nv_ + sv) * channels_ + ch;
    return tex_[i];
  }
  // Trilinear fetch in slab `slab`: (s_v, t_v) bilinear with clamp to edge, s_l linear inside the slab.
  double Fetch(int g, int slab, const Vec2& v, double sl, int ch) const {
    const double fx = std::clamp(v.x() * nv_ - 0.5, 0.0, double(nv_ - 1)),
                 fy = std::clamp(v.y() * nv_ - 0.5, 0.0, double(nv_ - 1));
    const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy), z0 = static_cast<int>(sl);
    const int x1 = std::min(x0 + 1, nv_ - 1), y1 = std::min(y0 + 1, nv_ - 1), z1 = std::min(z0 + 1, nl_ - 1);
    const double ax = fx - x0, ay = fy - y0, az = sl - z0;
    double r = 0;
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const double wgt = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay) * (dz ? az : 1 - az);
          if (wgt == 0) continue;
          r += wgt * Texel(g, slab * nl_ + (dz ? z1 : z0), dy ? y1 : y0, dx ? x1 : x0, ch);
        }
    return r;
  }

  int clusters_ = 0, functions_ = 0, nv_ = 0, nl_ = 0, channels_ = 0, height_ = 0, width_ = 0;
  int aw_ = 0, ah_ = 0, ad_ = 0, pages_ = 0, tiles_x_ = 0, tiles_y_ = 0;
  double quantization_bound_ = 0;
  bool cos_theta_i_included_ = false;
  std::vector<float> tex_;  // normalised values t, as a GPU samples them
  std::vector<float> terms_;
  std::vector<std::uint16_t> index_;
};

}  // namespace btf
