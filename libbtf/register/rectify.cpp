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
  BTF_CHECK_OPTION(filter == "area" || filter == "bilinear" || filter == "spline", "filter", "area, bilinear or spline");
}

namespace {

// In place: the coefficients c of sum_j c_j B3(k - j) = s_k (B3 the cubic B-spline: weights 1/6,
// 4/6, 1/6 at -1, 0, 1) along n values `stride` apart, mirror boundaries. One causal and one
// anti-causal pass of the pole z = sqrt(3) - 2 (Unser, "Splines: a perfect fit", IEEE SPM 1999;
// the initial values as in Thevenaz, Blu and Unser, "Interpolation revisited", 2000).
void CubicSplinePrefilter(double* c, int n, std::ptrdiff_t stride) {
  if (n < 2) return;
  const double z = std::sqrt(3.0) - 2.0;
  auto at = [&](int k) -> double& { return c[static_cast<std::ptrdiff_t>(k) * stride]; };
  for (int k = 0; k < n; ++k) at(k) *= 6.0;  // (1 - z)(1 - 1/z)
  // Causal initial value for the mirror-extended signal.
  const int horizon = static_cast<int>(std::ceil(std::log(1e-15) / std::log(std::abs(z))));
  double sum = 0;
  if (horizon < n) {
    double zn = 1;
    for (int k = 0; k < horizon; ++k, zn *= z) sum += zn * at(k);
  } else {
    double zn = z, z2n = std::pow(z, n - 1);
    const double iz = 1.0 / z;
    sum = at(0) + z2n * at(n - 1);
    z2n *= z2n * iz;
    for (int k = 1; k <= n - 2; ++k, zn *= z, z2n *= iz) sum += (zn + z2n) * at(k);
    sum /= 1.0 - zn * zn;
  }
  at(0) = sum;
  for (int k = 1; k < n; ++k) at(k) += z * at(k - 1);
  at(n - 1) = (z / (z * z - 1.0)) * (z * at(n - 2) + at(n - 1));
  for (int k = n - 2; k >= 0; --k) at(k) = z * (at(k + 1) - at(k));
}

int Mirror(int i, int n) { return i < 0 ? std::min(-i, n - 1) : (i >= n ? std::max(2 * (n - 1) - i, 0) : i); }

}  // namespace

SplineImage HistopolatingSpline(const Image& im) {
  SplineImage sp;
  sp.width = im.width, sp.height = im.height, sp.channels = im.channels;
  sp.coeff.assign(im.pixels.begin(), im.pixels.end());
  const int W = im.width, H = im.height, C = im.channels;
  // A quadratic B-spline averaged over a unit box is a cubic B-spline: its pixel averages are the
  // pixels when its coefficients are those of cubic B-spline interpolation of the pixels.
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int c = 0; c < C; ++c) CubicSplinePrefilter(&sp.coeff[static_cast<std::size_t>(y) * W * C + c], W, C);
#pragma omp parallel for schedule(static)
  for (int x = 0; x < W; ++x)
    for (int c = 0; c < C; ++c)
      CubicSplinePrefilter(&sp.coeff[static_cast<std::size_t>(x) * C + c], H, static_cast<std::ptrdiff_t>(W) * C);
  return sp;
}

bool SampleSpline(const SplineImage& sp, double x, double y, float* out) {
  const bool inside = x >= -0.5 && y >= -0.5 && x <= sp.width - 0.5 && y <= sp.height - 0.5;
  // The spline covers every pixel's whole box (mirrored beyond the first and last centres).
  x = std::clamp(x, -0.5, sp.width - 0.5);
  y = std::clamp(y, -0.5, sp.height - 0.5);
  const int ix = static_cast<int>(std::lround(x)), iy = static_cast<int>(std::lround(y));
  const double tx = x - ix, ty = y - iy;
  // Quadratic B-spline weights of the nearest coefficient and its two neighbours (|t| <= 1/2).
  const double wx[3] = {0.5 * (tx - 0.5) * (tx - 0.5), 0.75 - tx * tx, 0.5 * (tx + 0.5) * (tx + 0.5)};
  const double wy[3] = {0.5 * (ty - 0.5) * (ty - 0.5), 0.75 - ty * ty, 0.5 * (ty + 0.5) * (ty + 0.5)};
  const int C = sp.channels;
  std::size_t at[9];
  double w[9];
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) {
      at[j * 3 + i] = (static_cast<std::size_t>(Mirror(iy + j - 1, sp.height)) * sp.width +
                       static_cast<std::size_t>(Mirror(ix + i - 1, sp.width))) * C;
      w[j * 3 + i] = wy[j] * wx[i];
    }
  for (int c = 0; c < C; ++c) {
    double a = 0;
    for (int k = 0; k < 9; ++k) a += w[k] * sp.coeff[at[k] + c];
    out[c] = static_cast<float>(a);
  }
  return inside;
}

Vec2 TexelCenterMm(double col, double row, int n, double s) {
  return Vec2(-s / 2 + (col + 0.5) * s / n, s / 2 - (row + 0.5) * s / n);
}

namespace {

// Bilinear sample, OpenCV pixel-center convention, clamped to the edge; returns false if (x, y)
// is more than half a pixel outside the image.
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

}  // namespace

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
  const bool spline = options.filter == "spline";
  const SplineImage coeff = spline ? HistopolatingSpline(photo) : SplineImage();
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
      const bool box = options.filter == "area" && lu >= 1 && lv >= 1;
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
          } else if (spline) {
            inside &= SampleSpline(coeff, px.x(), px.y(), v.data());
          } else {
            inside &= SampleBilinear(photo, px.x(), px.y(), v.data());
          }
          for (int k = 0; k < ch; ++k) acc[k] += v[k];
        }
      const double w = 1.0 / (nu * nv);
      for (int k = 0; k < ch; ++k) out.at(col, row, k) = static_cast<float>(spline ? std::max(0.0, acc[k] * w) : acc[k] * w);
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
