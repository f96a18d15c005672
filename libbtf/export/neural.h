#pragma once
// Renderer export of a neural codec (docs/format.md, "Neural layout"; layout neural-mlp of format
// libbtf-schneider-export 2.2.0): the codec's per-texel latents as they are stored (8-bit codes
// with a float32 scale and bias per latent channel, or half floats), 4 latent channels per layer
// of a 2D texture array, and its decoder MLP's float32 weights, with a GLSL function that
// evaluates the decoder per pixel. Nothing is resampled or requantised: the export decodes to the
// codec's own values (Codec::Value with nearest texel) up to float arithmetic.
//
// Files written into the output folder (all little-endian, row 0 = top of the texture):
//   manifest.json        everything a renderer needs (shapes, the latent dequantisation, the
//                        direction encoding, the decoder's layers, the output transform)
//   latents.u8 | latents.f16  [layers][H][W][4]: latent j of texel (x, y) is channel j % 4 of
//                        layer j / 4 (channels past the latent count are 0); u8: the codec's codes
//   decoder.f32          float32: per layer n, [out_n][in_n + 1] row-major, row o = (W_n[o][0..in_n - 1],
//                        b_n[o]); layers concatenated in order
//   btf_neural.glsl      GLSL ES 3.00 function btf_eval(uv, wi, wo) with this export's constants
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"

namespace btf {

// The layout of libbtf/export/neural.h (from format 2.2.0, kSchneiderExportVersion).
inline constexpr const char* kNeuralLayout = "neural-mlp";

// Limits of the GLSL function: a layer's activations are held in registers (at most
// kNeuralExportMaxWidth values), and every neuron is a row of the decoder texture (at most
// kNeuralExportMaxRows rows: WebGL2 guarantees MAX_TEXTURE_SIZE >= 2048).
inline constexpr int kNeuralExportMaxWidth = 256;
inline constexpr int kNeuralExportMaxRows = 2048;

struct NeuralExportSummary {
  std::string directory;
  int latent = 0, latent_layers = 0, height = 0, width = 0, channels = 0;
  std::string storage;        // u8 or f16 (the codec's latent storage)
  int inputs = 0;             // decoder inputs: latent + direction encoding width
  std::vector<int> hidden;    // decoder hidden widths
  std::string activation;
  std::int64_t parameters = 0;
  int decoder_texture_width = 0, decoder_texture_height = 0;  // RGBA32F texels of the viewer's decoder texture
  std::uint64_t texture_bytes = 0, weight_bytes = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// The GLSL ES 3.00 source of btf_eval(uv, wi, wo) for a neural-mlp export with this manifest
// (written into the export as btf_neural.glsl; docs/viewer.md).
std::string NeuralGlsl(const nlohmann::json& manifest);

// Writes the export into `directory` (created if needed; files replaced atomically, manifest
// last). Throws btf::Error (usage) for codecs other than neural, a codec without latents, and a
// decoder beyond the GLSL function's limits (a layer wider than kNeuralExportMaxWidth, more than
// kNeuralExportMaxRows neurons).
NeuralExportSummary ExportNeural(const Codec& codec, const std::filesystem::path& directory,
                                 const Reporter& reporter = {});

}  // namespace btf
