#pragma once
// Weave-lattice estimation and unit-tile averaging (registration notes section 6).
//
// Coordinates: texel units of the normtexture, x = column (right), y = row (down), texel centers
// at integers. A lattice is origin + i a1 + j a2 (i, j integer); the unit tile is the
// parallelogram spanned by a1, a2.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"
#include "libbtf/io/image_io.h"

namespace btf {

struct LatticeOptions {
  double min_frequency_bins = 3;  // spectrum peaks closer than this to DC are ignored (shading, gradients)
  double peak_fraction = 0.03;    // significant peak: magnitude >= this x the strongest peak ...
  double noise_factor = 8;        // ... and >= this x the median magnitude of the spectrum
  int max_yarns_per_repeat = 8;   // largest sub-harmonic denominator searched (satins repeat over up to 8 yarns)
  double match_tolerance_bins = 0.35;  // a peak belongs to a lattice if within this many bins of a node
  double subharmonic_fraction = 0.05;       // a sub-harmonic (longer repeat) needs this x the strongest peak ...
  double subharmonic_tolerance_bins = 0.1;  // ... and must sit this close to its n/d position
  void Check() const;
};

struct Lattice {
  Vec2 a1 = Vec2::Zero(), a2 = Vec2::Zero();  // direct basis (texels); a1 the more horizontal one, a1.x > 0, a2.y > 0
  Vec2 origin = Vec2(-0.5, -0.5);            // a lattice node (texels)
  Vec2 k1 = Vec2::Zero(), k2 = Vec2::Zero();  // reciprocal basis (cycles per texel), k_i . a_j = delta_ij
  // Unit cells of the strongest-peak lattice per repeat (1 = the strongest period is the repeat;
  // 3 for a 3-yarn twill whose strongest peak is the yarn spacing).
  int yarn_cells_per_repeat = 1;
  int peaks_found = 0, peaks_used = 0;
  int aliases_skipped = 0;  // peaks explained as harmonics folded back by texel sampling
  double fit_rms_bins = 0;  // RMS distance of the used peaks from the fitted reciprocal lattice
  std::vector<std::pair<Vec2, double>> peaks;  // significant peaks (cycles/texel, magnitude), strongest first
  nlohmann::json ToJson() const;
};

// Estimates the lattice of a periodic gray image (row-major width x height): Hann-windowed DFT,
// peaks refined to the maximum of the windowed DTFT (no bin-grid bias), the coarsest reciprocal lattice generating every
// significant peak (the smallest repeat consistent with all peaks, so twill/satin sub-harmonics
// are honoured; peaks that are aliases of the strong lattice's harmonics are skipped), then a
// magnitude-weighted least-squares fit of the basis to all harmonics.
// Throws btf::Error (bad input) if no two non-collinear periods are found.
Lattice EstimateLattice(const std::vector<float>& gray, int width, int height, const LatticeOptions& options = {});

struct TileAverageOptions {
  int tile_resolution = 0;     // samples per tile axis; 0 = ceil(2 max(|a1|, |a2|)): twice the texel density,
                               // so averaging and re-tiling (two bilinear resamplings) keep fine detail
  double trim_fraction = 0.2;  // trimmed mean: drop this fraction of tiles at each end per sample (0 = mean)
  void Check() const;
};

struct AveragedTile {
  Image tile;    // T x T x C; sample (i, j) at lattice coordinates ((i+0.5)/T, (j+0.5)/T)
  Image stddev;  // per-sample standard deviation across tiles (before trimming)
  int tiles_used = 0;
  int samples_without_valid_tile = 0;  // with a mask: tile samples masked in every tile (averaged over all)
};

// Averages every complete unit tile of `image` (resampled bicubically on the lattice). With a
// `mask` (width x height, 1 = masked texel), a tile's sample whose bicubic footprint (4 x 4
// texels) touches a masked texel is left out of that sample's average. Throws btf::Error (bad
// input) if fewer than 2 complete tiles fit.
AveragedTile AverageTiles(const Image& image, const Lattice& lattice, const TileAverageOptions& options = {},
                          const std::vector<std::uint8_t>* mask = nullptr);

// The regular tiling of `tile` over a width x height image (periodic bicubic lookup).
Image TileImage(const AveragedTile& tile, const Lattice& lattice, int width, int height);

}  // namespace btf
