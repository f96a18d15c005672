#pragma once
// Renderer export of a per-view PCA codec as Sattler 2003 renders it (docs/format.md, "Renderer
// export", layout sattler-2003): for every sampled view direction its mean image and
// eigen-textures (the "view-dependent texture maps"), tiled into the layers of a 2D texture array
// and stored as 8-bit unsigned normalised or 16-bit half floats with a scale and bias per image,
// and for every (view, light) pair the weights of those images with the scales folded in. A
// renderer blends the three nearest views and lights barycentrically, exactly as the codec's
// decoder (Codec::Value, nearest texel) does.
//
// Files written into the output folder (all little-endian, row 0 = top of the texture):
//   manifest.json        everything a renderer needs (directions, shapes, layout, formulas)
//   images.u8 | images.f16  [layers][height][width][C]: normalised image values t in [0, 1]; image
//                        g = v * F + f (F = 1 + c, f = 0 the view's mean) is tile
//                        (g % tiles_x, (g / tiles_x) % tiles_y) of layer g / (tiles_x * tiles_y)
//   terms.f32            float32 [V][L][1 + F]: term 0 = offset, term 1 + f = weight of image f
//   scale_bias.f32       float32 [V][F][2]: (scale, bias) per image, informative (already folded)
//   btf_sattler.glsl     GLSL ES 3.00 function btf_eval(uv, wi, wo) with this export's constants
#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"

namespace btf {

struct SattlerExportOptions {
  int components = -1;         // export at most this many eigen-textures per view (-1 = all the codec has)
  std::string storage = "u8";  // "u8" (unsigned normalised 8 bits) or "f16" (half floats, HDR data)
  int atlas_side = 256;        // largest side of a texture-array layer in texels (WebGL2 guarantees 2048)
  void Check() const;
};

struct SattlerExportSummary {
  std::string directory;
  int views = 0, lights = 0, functions = 0, height = 0, width = 0, channels = 0;
  std::string storage;
  int layer_width = 0, layer_height = 0, layers = 0, tiles_x = 0, tiles_y = 0;
  std::uint64_t texture_bytes = 0, weight_bytes = 0;
  // Largest |stored - exact| over all normalised image values t in [0, 1], in units of each
  // image's scale (<= StorageQuantizationBound).
  double max_quantization_error = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// The GLSL ES 3.00 source of btf_eval(uv, wi, wo) for a sattler-2003 export with this manifest
// (written into the export as btf_sattler.glsl; docs/viewer.md).
std::string SattlerGlsl(const nlohmann::json& manifest);

// Writes the export into `directory` (created if needed; files replaced atomically, manifest
// last). Throws btf::Error (usage) for codecs other than pca-view, log-transformed codecs, fewer
// than 3 sampled view or light directions, and layouts beyond WebGL2's limits (256 layers, 2048
// texels per side of the terms texture).
SattlerExportSummary ExportSattler(const SattlerExportOptions& options, const Codec& codec,
                                   const std::filesystem::path& directory, const Reporter& reporter = {});

}  // namespace btf
