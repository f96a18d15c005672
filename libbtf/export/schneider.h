#pragma once
// Renderer export of an LPCA codec after Schneider 2004 section 6 (docs/btf-compress.md
// "Renderer export"): every cluster's mean and Eigen-ABRDFs resampled on a regular grid of the
// elevated concentric map (s_v, t_v, s_l, t_l), t_l slabs stacked along the 3D texture's depth,
// all functions tiled into one 3D texture atlas within WebGL2 limits, stored as 8-bit unsigned
// normalised or 16-bit half floats with a scale and bias per function folded into the per-texel
// weights and a per-texel offset (docs/format.md, "Renderer export").
//
// Files written into the output folder (all little-endian, row 0 = top of the texture):
//   manifest.json        everything a renderer needs (shapes, atlas layout, formulas)
//   atlas.u8 | atlas.f16 [pages][depth = n_tl * n_sl][atlas_height][atlas_width][C]: normalised
//                        function values t in [0, 1]; function g = k * F + f (F = 1 + c, f = 0 the
//                        cluster mean) is tile (g % tiles_x, (g / tiles_x) % tiles_y) of page
//                        g / (tiles_x * tiles_y), each tile n_sv x n_tv texels
//   terms.f32            float32 [H][W][1 + F]: term 0 = offset, term 1 + f = weight of function f
//                        (value = offset + sum_f weight_f * t_f)
//   cluster_index.u16    uint16 [H][W]
//   scale_bias.f32       float32 [K][F][2]: (scale, bias) per function, informative (already folded)
//   btf_schneider.glsl   GLSL ES 3.00 function btf_eval(uv, wi, wo) with this export's constants
#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"

namespace btf {

inline constexpr const char* kSchneiderExportFormat = "libbtf-schneider-export";
// 2.1.0 added "layout": kSchneiderLayout (LPCA, this file) or kSattlerLayout (pca-view,
// libbtf/export/sattler.h); a 2.0.0 manifest without it is the Schneider layout. 2.2.0 added
// "checksums" (CRC-32 of every file, checked by the readers).
inline constexpr const char* kSchneiderExportVersion = "2.2.0";
inline constexpr const char* kSchneiderLayout = "schneider-2004";
inline constexpr const char* kSattlerLayout = "sattler-2003";

struct SchneiderExportOptions {
  int view_grid = 16;   // n_sv = n_tv: samples per side of the view square
  int light_grid = 16;  // n_sl = n_tl: samples per side of the light square
  int components = -1;  // export at most this many Eigen-ABRDFs per cluster (-1 = all the codec has)
  std::string storage = "u8";  // "u8" (unsigned normalised 8 bits) or "f16" (half floats, HDR data)
  int atlas_side = 256;  // largest atlas side (3D texture width, height, depth); WebGL2 guarantees 256
  void Check() const;
};

struct SchneiderExportSummary {
  std::string directory;
  int clusters = 0, functions = 0, view_grid = 0, light_grid = 0, height = 0, width = 0, channels = 0;
  std::string storage;
  int atlas_width = 0, atlas_height = 0, atlas_depth = 0, atlas_pages = 0, tiles_x = 0, tiles_y = 0;
  std::uint64_t texture_bytes = 0, weight_bytes = 0, index_bytes = 0;
  // Largest |stored - exact| over all normalised function values t in [0, 1] (u8: <= 1/510,
  // f16: <= 2^-12 + 2^-24): in units of each function's scale.
  double max_quantization_error = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// Grid sample i of n along one square axis: the cell center (i + 0.5) / n.
inline double GridCoordinate(int i, int n) { return (i + 0.5) / n; }

// Largest |stored - exact| of a normalised value t in [0, 1]: half a step of 1/255, or half an
// ulp of a half float below 1 (2^-12) plus the float32 rounding before it (2^-24).
inline double StorageQuantizationBound(const std::string& storage) {
  return storage == "f16" ? 1.0 / 4096 + 1.0 / 16777216 : 0.5 / 255;
}

// The GLSL ES 3.00 source of btf_eval(uv, wi, wo) for an export with this manifest (written into
// the export as btf_schneider.glsl; docs/viewer.md).
std::string SchneiderGlsl(const nlohmann::json& manifest);

// Writes the export into `directory` (created if needed; files replaced atomically, manifest last).
// Throws btf::Error (usage) for pca-view codecs and for log-transformed codecs (the renderer sums
// weighted functions linearly, which a log transform does not allow).
SchneiderExportSummary ExportSchneider(const SchneiderExportOptions& options, const Codec& codec,
                                       const std::filesystem::path& directory, const Reporter& reporter = {});

}  // namespace btf
