#pragma once
// Rectification of the sample region into an N x N normtexture, in one resampling step.
//
// Texel (col, row) covers the plate square x in [-S/2 + col S/N, -S/2 + (col+1) S/N],
// y in [S/2 - (row+1) S/N, S/2 - row S/N] (S = sample side in mm; row 0 = top = +y).
// Anti-aliasing: each texel is the mean of n_u x n_v stratified bilinear samples of the photo
// over its footprint, with n_u, n_v chosen per texel from the projected texel edge lengths
// (samples_per_px samples per photo pixel, at least min, at most max_samples_per_axis): the
// box prefilter over the texel's footprint that plain bilinear warping lacks, with the sample
// count adapted to each axis separately (oblique views shrink one axis only).
#include <functional>

#include "libbtf/core/directions.h"
#include "libbtf/io/image_io.h"

namespace btf {

struct RectifyOptions {
  int resolution = 256;            // N: normtexture side in texels
  double samples_per_px = 4.0;     // sample density along each texel axis, per photo pixel covered
  int max_samples_per_axis = 16;   // cap on n_u and n_v
  int min_samples_per_axis = 1;    // 1 = plain bilinear where a texel covers less than a pixel
  // Where a texel covers >= 1 photo pixel along both axes, sample the pixels as boxes (nearest
  // pixel per sample) instead of bilinearly: the texel then averages the pixels it overlaps,
  // weighted by area (as INTER_AREA), without the extra 2 px tent blur of bilinear sampling.
  bool area_weighting = true;
  void Check() const;
};

struct RectifyStats {
  double invalid_fraction = 0;    // texels with a sample outside the photo (value clamped at the edge)
  double max_footprint_px = 0;    // longest projected texel edge
  double mean_samples = 0;        // mean samples per texel
};

// project(plate (x, y) at the material surface) -> photo pixel; false if not projectable.
using PlateToPixel = std::function<bool(const Vec2& plate_mm, Vec2* px)>;

Image Rectify(const Image& photo, const PlateToPixel& project, double sample_size_mm, const RectifyOptions& options,
              RectifyStats* stats = nullptr);

// Plate position (mm) of the center of texel (col, row) of an N x N normtexture.
Vec2 TexelCenterMm(double col, double row, int n, double sample_size_mm);

// Bilinear sample, OpenCV pixel-center convention, clamped to the edge; returns false if (x, y)
// is more than half a pixel outside the image.
bool SampleBilinear(const Image& image, double x, double y, float* out);

}  // namespace btf
