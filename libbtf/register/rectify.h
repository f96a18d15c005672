#pragma once
// Rectification of the sample region into an N x N normtexture, in one resampling step.
//
// Texel (col, row) covers the plate square x in [-S/2 + col S/N, -S/2 + (col+1) S/N],
// y in [S/2 - (row+1) S/N, S/2 - row S/N] (S = sample side in mm; row 0 = top = +y).
// Anti-aliasing: each texel is the mean of n_u x n_v stratified samples of the photo (read as
// RectifyOptions::filter says) over its footprint, with n_u, n_v chosen per texel from the
// projected texel edge lengths
// (samples_per_px samples per photo pixel, at least min, at most max_samples_per_axis): the
// box prefilter over the texel's footprint that plain bilinear warping lacks, with the sample
// count adapted to each axis separately (oblique views shrink one axis only).
#include <functional>
#include <string>
#include <vector>

#include "libbtf/core/directions.h"
#include "libbtf/io/image_io.h"

namespace btf {

struct RectifyOptions {
  int resolution = 256;            // N: normtexture side in texels
  double samples_per_px = 4.0;     // sample density along each texel axis, per photo pixel covered
  int max_samples_per_axis = 16;   // cap on n_u and n_v
  int min_samples_per_axis = 1;    // 1 = plain bilinear where a texel covers less than a pixel
  // How the photo is read between pixel centres at each sample:
  //  "area": where a texel covers >= 1 photo pixel along both axes, the nearest pixel (the texel
  //          then averages the pixels it overlaps, weighted by area, as INTER_AREA, without the
  //          extra 2 px tent of bilinear sampling); bilinear elsewhere.
  //  "bilinear": bilinear everywhere.
  //  "spline": the quadratic B-spline whose box average over every pixel equals that pixel's
  //          value (histopolation; the photo's own box integration over each pixel undone), read
  //          at every sample. Its coefficients come from the cubic B-spline interpolation prefilter
  //          (box * quadratic B-spline = cubic B-spline), separable, mirror boundaries. It keeps
  //          detail near the photo's Nyquist frequency that "area" attenuates by sinc^2 (box pixel
  //          times box reconstruction): 0.67 of the amplitude at 0.34 cycles/px, 0.93 with it.
  //          Values below 0 (ringing at dark edges) are clamped to 0.
  std::string filter = "area";
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

// The coefficients of the quadratic B-spline whose average over every pixel (a unit box around
// its centre, OpenCV convention) equals the pixel (RectifyOptions::filter "spline"); double
// precision, mirror boundaries, every channel.
struct SplineImage {
  int width = 0, height = 0, channels = 0;
  std::vector<double> coeff;
};
SplineImage HistopolatingSpline(const Image& image);

// The spline's value at (x, y) (clamped to the image's pixel boxes); false if more than half a
// pixel outside.
bool SampleSpline(const SplineImage& spline, double x, double y, float* out);

}  // namespace btf
