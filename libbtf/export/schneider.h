#pragma once
// Renderer export of an LPCA codec after Schneider 2004 section 6 (docs/btf-compress.md
// "Renderer export"): every cluster's mean and Eigen-ABRDFs resampled on a regular grid of the
// elevated concentric map (s_v, t_v, s_l, t_l), t_l slabs stacked along the 3D texture's depth,
// 8 bits per value with one scale per function folded into the per-texel weights.
//
// Files written into the output folder (all little-endian, row 0 = top of the texture):
//   manifest.json        everything a renderer needs (shapes, layouts, formulas, scales)
//   eigen_abrdfs.u8      uint8 [K][F][n_tl * n_sl][n_tv][n_sv][C], F = 1 + c (function 0 = mean)
//   weights.f32          float32 [H][W][F]: per-texel weights with the scales folded in
//   cluster_index.u16    uint16 [H][W]
//   scales.f32           float32 [K][F]: the quantization scales (informative; already folded)
#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"

namespace btf {

inline constexpr const char* kSchneiderExportFormat = "libbtf-schneider-export";
inline constexpr const char* kSchneiderExportVersion = "1.0.0";

struct SchneiderExportOptions {
  int view_grid = 16;   // n_sv = n_tv: samples per side of the view square
  int light_grid = 16;  // n_sl = n_tl: samples per side of the light square
  int components = -1;  // export at most this many Eigen-ABRDFs per cluster (-1 = all the codec has)
  void Check() const;
};

struct SchneiderExportSummary {
  std::string directory;
  int clusters = 0, functions = 0, view_grid = 0, light_grid = 0, height = 0, width = 0, channels = 0;
  std::uint64_t texture_bytes = 0, weight_bytes = 0, index_bytes = 0;
  // Largest |quantized - exact| over all stored function values, in units of that function's scale.
  double max_quantization_error = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// Grid sample i of n along one square axis: the cell center (i + 0.5) / n.
inline double GridCoordinate(int i, int n) { return (i + 0.5) / n; }

// Writes the export into `directory` (created if needed; files replaced atomically, manifest last).
// Throws btf::Error (usage) for pca-view codecs and for log-transformed codecs (the renderer sums
// weighted functions linearly, which a log transform does not allow).
SchneiderExportSummary ExportSchneider(const SchneiderExportOptions& options, const Codec& codec,
                                       const std::filesystem::path& directory, const Reporter& reporter = {});

}  // namespace btf
