#pragma once
// Bonn's full-matrix factorisation as a libbtf codec (`btf-compress --method fmf|dfmf`;
// docs/btf-compress.md, docs/format.md "Codec file"): one truncated SVD of the
// (views x lights x channels) x texels matrix (FMF), or one per decorrelated YUV channel of the
// (views x lights) x texels matrices (DFMF). The SVD is randomised (Halko et al. 2011) and
// streams the input one view slot at a time, so memory is one view slot plus the factors. The
// same factors are what compress/bonn_fmf.h writes as Bonn `.btf` files. Under MPI the view slots
// are split over the ranks (docs/scaling.md).
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "libbtf/compress/value_transform.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/error_stats.h"
#include "libbtf/core/progress.h"
#include "libbtf/io/slot_source.h"

namespace btf {

namespace h5 {
class File;
}

// One factorised matrix X (rows x texels) ~ U SxV^T with SxV = V diag(S). Rows are directions
// (FMF: c + C (l + L v); DFMF: l + L v), columns texels t = x + W y (y = 0 the top row).
struct FmfMatrix {
  int components = 0;                  // k
  std::vector<float> singular_values;  // k, descending
  std::vector<float> u;                // rows x k, row-major, orthonormal columns
  std::vector<float> sxv;              // texels x k, row-major
};

// The codec's model: one matrix (FMF) or three (DFMF: Y, U, V of the forward BT.601 analog YUV
// of docs/format.md "Colour models", undone with its exact inverse).
struct FmfModel {
  bool decorrelated = false;
  int lights = 0, channels = 0;
  std::size_t texels = 0;
  std::vector<FmfMatrix> matrices;

  // Rows of each matrix that belong to one view slot: L C (FMF) or L (DFMF).
  std::size_t rows_per_view() const { return std::size_t(lights) * (decorrelated ? 1 : channels); }
  // Stored float32 values (singular values, U, SxV of every matrix).
  std::uint64_t StoredValues() const;
  // Decoders in the codec's transformed domain (decorrelation undone; a log transform is not).
  void DecodeViewSlot(int view, float* out) const;             // L x T x C
  void DecodeImage(int view, int light, float* out) const;     // T x C
  void Sample(int view, int light, std::size_t texel, float* out) const;  // C
};

// Options of the streaming randomised SVD.
struct FmfSvdOptions {
  bool decorrelate = false;   // false: FMF; true: DFMF (YUV; needs 3 channels)
  int components = 16;        // per matrix (per channel for DFMF); clamped to min(rows, texels)
  int oversampling = 10;      // extra random directions of the range finder
  int power_iterations = 2;   // passes of (X X^T) applied to the range (each reads the input twice)
  std::uint64_t seed = 1;     // of the Gaussian test matrix (deterministic for a seed)
  // If > 0: per matrix, the smallest k <= components with ||X - X_k|| / ||X|| <= target_error.
  double target_error = 0;
  // If > 0: per matrix, the smallest k <= components with sum s_i^2 >= retained_energy ||X||^2.
  double retained_energy = 0;
  void Check() const;
};

// Factorises `input` (read 2 + 2 power_iterations times, one view slot at a time). Components
// carrying at most 1e-12 of a matrix's energy are dropped (counted in *dropped). NaN/Inf in the
// input: btf::Error (bad input) naming the item; DFMF of other than 3 channels: btf::Error (usage).
// Distributed (a collective: every rank calls it; docs/scaling.md): each rank reads only the view
// slots it owns (round robin), and every rank returns the same model, bit-identical to one process's.
// `transform` is applied to every view slot as it is read (after the NaN/Inf check).
FmfModel FactoriseFmf(const FmfSvdOptions& options, const SlotSource& input, const ValueMap& transform = {},
                      const Reporter& reporter = {}, int* dropped = nullptr,
                      const dist::Context& ranks = dist::Context::World());

// The model's items in a codec file (docs/format.md, "Codec file": /codec/fmf/...). The reader
// refuses wrong shapes, non-finite values and component counts above the rank (bad input).
void WriteFmfModel(const h5::File& file, const FmfModel& model, int views, int height, int width);
FmfModel ReadFmfModel(const h5::File& file, bool decorrelated, int views, int lights, int height, int width,
                      int channels);

}  // namespace btf
