#pragma once
// Ground-truth BTF datasets from an SvbrdfModel: each texel is the average of the model over its
// footprint (stratified jittered S x S samples, fixed seed), for every view x light pair.
#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/core/dataset.h"
#include "libbtf/core/hash.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/synth/model.h"

namespace btf {

// Optional irregularity: a smooth random displacement of the thread pattern (not periodic in
// the tile), so that unit-tile averaging has something to remove. `amplitude` is the RMS
// displacement in tile units (0 = perfectly regular). Deterministic for a seed.
class PatternWarp {
 public:
  PatternWarp() = default;
  PatternWarp(double amplitude, std::uint64_t seed);
  // Tile coordinates (u, v) -> displaced coordinates; identity when amplitude is 0.
  Vec2 Apply(const Vec2& uv) const;
  double amplitude() const { return amplitude_; }
  nlohmann::json Describe() const;

 private:
  double amplitude_ = 0;
  struct Wave {
    Vec2 freq;  // cycles per tile
    double phase = 0;
    Vec2 dir;  // displacement direction x amplitude weight
  };
  std::vector<Wave> waves_;
};


struct BtfOptions {
  Sampling views = Sampling::Bonn81();   // view directions (default bonn81)
  Sampling lights = Sampling::Bonn81();  // light directions (default bonn81)
  int resolution = 64;       // texels per side (square image)
  double tiles = 1;          // tiles per image side (texel pitch = tiles * tile_mm / resolution)
  int samples = 4;           // S: S x S stratified samples per texel footprint
  std::uint64_t seed = 1;    // jitter seed
  double irregularity = 0;   // PatternWarp amplitude, tile units
  std::uint64_t irregularity_seed = 7;
  void Check() const;
};

struct BtfSummary {
  int views = 0, lights = 0, resolution = 0, samples = 0;
  std::uint64_t texel_values = 0;       // V * L * N^2 texel values written
  std::uint64_t model_evaluations = 0;  // texel_values * S^2
  PhaseTimes times;                     // sample_positions, evaluate, write
  nlohmann::json ToJson() const;
  std::string Report() const;  // one line: shape, rate, time
};

// Texture coordinates of sample (i, j) of texel (x, y) (row 0 = top): the exact positions used.
Vec2 TexelSampleUv(const BtfOptions& o, int x, int y, int i, int j);

// Fills one view slot (lights x N x N x channels) of the BTF. Uses all cores (OpenMP).
void GenerateViewSlot(const SvbrdfModel& model, const BtfOptions& options, int view, float* out);

// The whole BTF in memory (tests, small jobs). Progress is reported per view.
BtfSummary GenerateBtf(const BtfOptions& options, const SvbrdfModel& model, Dataset* out,
                       const Reporter& reporter = {});

// Streams the BTF to a dataset file view by view (Bonn-size jobs do not fit in memory), atomically.
// In a distributed run (core/distributed.h) every rank calls it: ranks render the view slots they
// own, rank 0 writes the file; the file is the same for any number of ranks.
BtfSummary WriteGeneratedBtf(const BtfOptions& options, const SvbrdfModel& model, const std::filesystem::path& path,
                             const Reporter& reporter = {}, const nlohmann::json& extra_provenance = {});

// The far-field BRDF (SvbrdfModel::EvalBrdf) on views x lights, as a 1 x 1 texel dataset.
Dataset GenerateBrdf(const SvbrdfModel& model, const Sampling& views, const Sampling& lights);

}  // namespace btf
