#pragma once
// Bonn's full-matrix factorisations written from any view-slot source: FMF (`!FMF12FCER`, one
// truncated SVD of the (channels x lights x views) x texels matrix) and DFMF (`!DFMF08FCR`, one
// per YUV channel). The SVD is randomised and streams the input view slot by view slot
// (docs/format.md, "Writing FMF and DFMF").
#include <cstdint>
#include <filesystem>

#include "libbtf/io/convert.h"
#include "libbtf/io/slot_source.h"

namespace btf {

struct FmfWriteOptions {
  bool decorrelate = false;   // false: FMF; true: DFMF with colour model 1 (YUV; needs 3 channels)
  int components = 16;        // per matrix (per channel for DFMF); clamped to min(rows, texels)
  int oversampling = 10;      // extra random directions of the range finder
  int power_iterations = 2;   // passes of (X X^T) applied to the range (each reads the input twice)
  std::uint64_t seed = 1;     // of the Gaussian test matrix (deterministic for a seed)
  void Check() const;
};

// Writes `input` as FMF or DFMF with float32 factors (scalar_size 4), atomically. Values must be
// finite (btf::Error, bad input, naming the item; nothing written).
ConvertSummary WriteFmf(const FmfWriteOptions& options, const SlotSource& input, const std::filesystem::path& path,
                        const Reporter& reporter = {});

}  // namespace btf
