#pragma once
// Unit-tile reconstruction from all photo pixels (multi-frame super-resolution on a periodic
// weave; docs/btf-register.md "Unit-tile reconstruction").
//
// The unit tile of the lattice (lattice.h) is a periodic T x T grid of unknowns in lattice
// coordinates with a bilinear basis. Every photo pixel whose footprint lies on the sample and is
// not masked gives one equation: its value (times a per-pixel factor to the output units) equals
// the mean of the tile function over the pixel's box, integrated with pixel_samples x
// pixel_samples sub-samples mapped photo -> plate (the exact inverse of the rectifier's
// plate -> photo map, distortion included) and reduced modulo the lattice. Each repeat of the
// weave is seen at a different sub-pixel phase, so all pixels together sample the tile far more
// densely than one repeat does. The regularised normal equations (a periodic Laplacian Tikhonov
// term) are solved by a dense Cholesky factorisation in double; accumulation is serial in pixel
// order, so the result does not depend on the thread count.
#include <cstdint>
#include <functional>
#include <vector>

#include "libbtf/core/directions.h"
#include "libbtf/io/image_io.h"
#include "libbtf/register/lattice.h"
#include "libbtf/register/rectify.h"

namespace btf {

struct TileReconstructOptions {
  // Tile grid: T = ceil(samples_per_texel x max(|a1|, |a2|)) samples per lattice axis. 4 per
  // texel: at 75 deg a pixel covers 0.68 texel along the foreshortened axis, so the grid
  // (0.25 texel) resolves detail finer than a pixel there, while T^2 stays below about 1000 for
  // lattices of up to 8 texels.
  double samples_per_texel = 4;
  int pixel_samples = 4;     // sub-samples per pixel axis integrating the pixel's box (4 x 4)
  // Weight of the periodic Laplacian (smoothness) term, relative: the term is scaled by
  // trace(A^T A) / trace(L^T L), so the weight does not depend on the pixel count or T.
  double smoothness = 1e-3;
  void Check() const;
};

// One photo's pixels and how they map onto the sample's N x N normtexture.
struct TilePhoto {
  const Image* photo = nullptr;  // linear values, C channels
  PlateToPixel project;          // plate (mm, material surface) -> photo pixel (OpenCV centres)
  double sample_size_mm = 0;     // S
  int resolution = 0;            // N: the lattice is in texel units of the N x N normtexture
  // Factor taking a pixel's value to the output units at a plate point (radiometry); empty = 1.
  std::function<double(const Vec2& plate_mm)> scale;
  // Whether a plate point is hidden (behind a raised marker); empty = nothing hidden.
  std::function<bool(const Vec2& plate_mm)> hidden;
  // Photo-sized, 1 = pixel without a value (clipped); null = none.
  const std::vector<std::uint8_t>* pixel_mask = nullptr;
};

struct ReconstructedTile {
  // T x T x C; sample (i, j) = the texel-box average of the reconstructed tile function around
  // lattice coordinates ((i + 0.5) / T, (j + 0.5) / T), clamped to >= 0 (as AverageTiles' tile,
  // so TileImage re-tiles it).
  AveragedTile tile;
  int pixels_used = 0;    // equations
  int pixels_masked = 0;  // pixels on the sample left out: hidden behind a marker or clipped
  double residual_rms = 0;  // RMS of the pixel equations after the solve (output units, all channels)
};

// Throws btf::Error (bad input) when fewer usable pixels than tile unknowns lie on the sample, the
// tile grid is too large (T^2 > 4096), or the normal equations are singular.
ReconstructedTile ReconstructTile(const TilePhoto& photo, const Lattice& lattice,
                                  const TileReconstructOptions& options = {});

}  // namespace btf
