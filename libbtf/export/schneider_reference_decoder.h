#pragma once
// Header-only reference decoder of the Schneider export (libbtf/export/schneider.h): reads the
// folder through manifest.json and evaluates a value the way a GPU shader would (trilinear 3D
// texture fetches in two t_l slabs, lerped). It needs only the manifest, the binary files and the
// elevated concentric map (libbtf/core/directions.h); tests check it against Codec::Value.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"
#include "libbtf/core/error.h"

namespace btf {

class SchneiderReferenceDecoder {
 public:
  explicit SchneiderReferenceDecoder(const std::filesystem::path& dir) {
    std::ifstream in(dir / "manifest.json");
    if (!in) ThrowIo("cannot open '{}'", (dir / "manifest.json").string());
    const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    if (j.is_discarded() || j.value("format", "") != "libbtf-schneider-export")
      ThrowBadInput("'{}' is not a libbtf Schneider export manifest", (dir / "manifest.json").string());
    if (j.value("format_version", "").rfind("1.", 0) != 0)
      ThrowBadInput("'{}': unsupported export version '{}'", (dir / "manifest.json").string(),
                    j.value("format_version", ""));
    const auto shape = j.at("eigen_abrdfs").at("shape");
    clusters_ = shape[0];
    functions_ = shape[1];
    nv_ = j.at("eigen_abrdfs").at("view_grid");
    nl_ = j.at("eigen_abrdfs").at("light_grid");
    channels_ = shape[5];
    height_ = j.at("texture").at("height");
    width_ = j.at("texture").at("width");
    tex_ = Load<std::uint8_t>(dir / j.at("eigen_abrdfs").at("file").get<std::string>(),
                              std::size_t(clusters_) * functions_ * nl_ * nl_ * nv_ * nv_ * channels_);
    weights_ = Load<float>(dir / j.at("weights").at("file").get<std::string>(),
                           std::size_t(height_) * width_ * functions_);
    index_ = Load<std::uint16_t>(dir / j.at("cluster_index").at("file").get<std::string>(), std::size_t(height_) * width_);
    for (auto k : index_)
      if (k >= clusters_) ThrowBadInput("'{}': cluster index {} >= {}", dir.string(), k, clusters_);
  }

  int height() const { return height_; }
  int width() const { return width_; }
  int channels() const { return channels_; }
  int functions() const { return functions_; }
  const float* weights(int y, int x) const { return &weights_[(std::size_t(y) * width_ + x) * functions_]; }

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
    std::vector<double> acc(static_cast<std::size_t>(channels_), 0.0);
    for (int f = 0; f < functions_; ++f) {
      const double wt = weights_[t * functions_ + f];
      if (wt == 0) continue;
      for (int ch = 0; ch < channels_; ++ch) {
        const double s0 = Fetch(k, f, i0, v, sl, ch), s1 = i1 == i0 ? s0 : Fetch(k, f, i1, v, sl, ch);
        acc[static_cast<std::size_t>(ch)] += wt * ((1 - w) * s0 + w * s1);
      }
    }
    for (int ch = 0; ch < channels_; ++ch) out[ch] = static_cast<float>(acc[static_cast<std::size_t>(ch)]);
  }

 private:
  template <typename T>
  static std::vector<T> Load(const std::filesystem::path& path, std::size_t count) {
    std::ifstream in(path, std::ios::binary);
    if (!in) ThrowIo("cannot open '{}'", path.string());
    std::vector<T> v(count);
    in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(count * sizeof(T)));
    if (in.gcount() != static_cast<std::streamsize>(count * sizeof(T)) || in.peek() != EOF)
      ThrowBadInput("'{}' does not hold exactly {} values of {} bytes", path.string(), count, sizeof(T));
    return v;
  }
  // Decoded (signed normalized) texel of function f of cluster k.
  double Texel(int k, int f, int z, int tv, int sv, int ch) const {
    const std::size_t i =
        ((((std::size_t(k) * functions_ + f) * nl_ * nl_ + z) * nv_ + tv) * nv_ + sv) * channels_ + ch;
    return tex_[i] / 127.5 - 1.0;
  }
  // Trilinear fetch in slab `slab`: (s_v, t_v) bilinear with clamp to edge, s_l linear inside the slab.
  double Fetch(int k, int f, int slab, const Vec2& v, double sl, int ch) const {
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
          r += wgt * Texel(k, f, slab * nl_ + (dz ? z1 : z0), dy ? y1 : y0, dx ? x1 : x0, ch);
        }
    return r;
  }

  int clusters_ = 0, functions_ = 0, nv_ = 0, nl_ = 0, channels_ = 0, height_ = 0, width_ = 0;
  std::vector<std::uint8_t> tex_;
  std::vector<float> weights_;
  std::vector<std::uint16_t> index_;
};

}  // namespace btf
