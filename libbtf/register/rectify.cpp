#include "libbtf/register/rectify.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "libbtf/core/error.h"

namespace btf {

void RectifyOptions::Check() const {
  BTF_CHECK_OPTION(resolution >= 2 && resolution <= 8192, "resolution", "2..8192");
  BTF_CHECK_OPTION(std::isfinite(samples_per_px) && samples_per_px > 0 && samples_per_px <= 16, "samples_per_px",
                   "0 < value <= 16");
  BTF_CHECK_OPTION(min_samples_per_axis >= 1, "min_samples_per_axis", ">= 1");
  BTF_CHECK_OPTION(max_samples_per_axis >= min_samples_per_axis && max_samples_per_axis <= 64, "max_samples_per_axis",
                   "min_samples_per_axis..64");
}

Vec2 TexelCenterMm(double col, double row, int n, double s) {
  return Vec2(-s / 2 + (col + 0.5) * s / n, s / 2 - (row + 0.5) * s / n);
}

bool SampleBilinear(const Image& im, double x, double y, float* out) {
  const bool inside = x >= -0.5 && y >= -0.5 && x <= im.width - 0.5 && y <= im.height - 0.5;
  x = std::clamp(x, 0.0, static_cast<double>(im.width - 1));
  y = std::clamp(y, 0.0, static_cast<double>(im.height - 1));
  const int x0 = std::min(static_cast<int>(x), im.width - 1), y0 = std::min(static_cast<int>(y), im.height - 1);
  const int x1 = std::min(x0 + 1, im.width - 1), y1 = std::min(y0 + 1, im.height - 1);
  const double fx = x - x0, fy = y - y0;
  for (int c = 0; c < im.channels; ++c) {
    const double top = (1 - fx) * im.at(x0, y0, c) + fx * im.at(x1, y0, c);
    const double bot = (1 - fx) * im.at(x0, y1, c) + fx * im.at(x1, y1, c);
    out[c] = static_cast<float>((1 - fy) * top + fy * bot);
  }
  return inside;
}

Image Rectify(const Image& photo, const PlateToPixel& project, double s, const RectifyOptions& options,
              RectifyStats* stats) {
  options.Check();
  if (photo.width < 2 || photo.height < 2 || photo.channels < 1) ThrowBadInput("rectify: photo is empty");
  if (!(std::isfinite(s) && s > 0)) ThrowBadInput("rectify: sample size {} mm is not positive", s);
  const int n = options.resolution, ch = photo.channels;
  const double texel = s / n;
  Image out(n, n, ch);
  long long invalid = 0;
  double max_fp = 0, total_samples = 0;
#pragma omp parallel for schedule(dynamic, 4) reduction(+ : invalid, total_samples) reduction(max : max_fp)
  for (int row = 0; row < n; ++row) {
    std::vector<double> acc(static_cast<std::size_t>(ch));
    std::vector<float> v(static_cast<std::size_t>(ch));
    for (int col = 0; col < n; ++col) {
      const Vec2 c = TexelCenterMm(col, row, n, s);
      Vec2 p0, pu, pv;
      bool ok = project(c, &p0) && project(c + Vec2(texel, 0), &pu) && project(c - Vec2(0, texel), &pv);
      if (!ok) {
        ++invalid;
        continue;  // stays 0; counted as invalid
      }
      const double lu = (pu - p0).norm(), lv = (pv - p0).norm();  // px per texel along u (col) and v (row)
      max_fp = std::max({max_fp, lu, lv});
      const int nu = std::clamp(static_cast<int>(std::ceil(lu * options.samples_per_px)), options.min_samples_per_axis,
                                options.max_samples_per_axis);
      const int nv = std::clamp(static_cast<int>(std::ceil(lv * options.samples_per_px)), options.min_samples_per_axis,
                                options.max_samples_per_axis);
      std::fill(acc.begin(), acc.end(), 0.0);
      bool inside = true;
      const bool box = options.area_weighting && lu >= 1 && lv >= 1;
      for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
          const Vec2 q(-s / 2 + (col + (i + 0.5) / nu) * texel, s / 2 - (row + (j + 0.5) / nv) * texel);
          Vec2 px;
          if (!project(q, &px)) {
            inside = false;
            continue;
          }
          if (box) {
            const int ix = static_cast<int>(std::lround(px.x())), iy = static_cast<int>(std::lround(px.y()));
            inside &= ix >= 0 && iy >= 0 && ix < photo.width && iy < photo.height;
            const int cx = std::clamp(ix, 0, photo.width - 1), cy = std::clamp(iy, 0, photo.height - 1);
            for (int k = 0; k < ch; ++k) v[k] = photo.at(cx, cy, k);
          } else {
            inside &= SampleBilinear(photo, px.x(), px.y(), v.data());
          }
          for (int k = 0; k < ch; ++k) acc[k] += v[k];
        }
      const double w = 1.0 / (nu * nv);
      for (int k = 0; k < ch; ++k) out.at(col, row, k) = static_cast<float>(acc[k] * w);
      total_samples += nu * nv;
      if (!inside) ++invalid;
    }
  }
  if (stats) {
    stats->invalid_fraction = static_cast<double>(invalid) / (static_cast<double>(n) * n);
    stats->max_footprint_px = max_fp;
    stats->mean_samples = total_samples / (static_cast<double>(n) * n);
  }
  return out;
}

}  // namespace btf
