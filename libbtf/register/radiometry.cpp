#include "libbtf/register/radiometry.h"

#include <cmath>

#include "libbtf/core/error.h"
#include "libbtf/register/rectify.h"

namespace btf {

double IrradianceAt(const PhotoEntry& p, const Vec2& x) {
  if (p.light_distance_mm <= 0) return p.light_intensity * p.light_dir.z();
  const Vec3 d = p.light_distance_mm * p.light_dir - Vec3(x.x(), x.y(), 0.0);
  const double r = d.norm();
  if (!(r > 0)) return 0;
  return p.light_intensity * d.z() / (r * r * r);
}

void ApplyRadiometry(Image& tex, const PhotoEntry& p, double s) {
  if (tex.width != tex.height) ThrowBadInput("radiometry: normtexture is not square ({}x{})", tex.width, tex.height);
  const int n = tex.width;
  for (int row = 0; row < n; ++row)
    for (int col = 0; col < n; ++col) {
      const double e = IrradianceAt(p, TexelCenterMm(col, row, n, s));
      if (!(e > 0) || !std::isfinite(e))
        ThrowBadInput("'{}': the light is at or below the horizon of texel ({}, {}) (irradiance {}): check light_dir "
                      "and light_distance_mm in the manifest",
                      p.file, col, row, e);
      const double scale = 1.0 / (p.exposure * e);
      for (int c = 0; c < tex.channels; ++c) tex.at(col, row, c) = static_cast<float>(tex.at(col, row, c) * scale);
    }
}

}  // namespace btf
