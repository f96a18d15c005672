#pragma once
// The compression methods' one interface (below the controller compress.cpp, above codec.h):
// what a method gets, the table of methods, and what the methods share (error sums, the PCA
// request of the options). Each method lives in its own file: pca_view.cpp, lpca*.cpp,
// lpca_tensor_method.cpp, fmf_codec.cpp, neural_method.cpp.
#include <cstdint>
#include <string>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/codec_writer.h"
#include "libbtf/compress/compress_options.h"
#include "libbtf/compress/compress_summary.h"
#include "libbtf/compress/pca.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/error_stats.h"
#include "libbtf/core/progress.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// What a method compresses from and reports to. `options` are those the controller applied
// (a scene's error bound and --bytes already turned into target_error and components).
struct MethodContext {
  const SlotSource& input;
  const CompressOptions& options;
  const ValueMap& transform;
  const dist::Context& ranks;
  const Reporter& reporter;
  // pca-view in one process: the codec file, written slot by slot while the method runs (null:
  // the controller writes the codec afterwards).
  CodecFileWriter* writer = nullptr;
  // A warning: recorded in the summary and logged once (by rank 0; every rank records it).
  void Warn(CompressSummary& summary, const std::string& warning) const;
};

// One method: fills the codec's model and the summary's method-specific fields and errors
// (in the original domain, of the codec as stored). Returns the bytes of coefficient arrays
// already written through context.writer (the codec then keeps only their shapes), else 0.
using CompressMethodFn = std::uint64_t (*)(const MethodContext& context, Codec& codec, CompressSummary& summary);

struct MethodEntry {
  CodecMethod method;
  CompressMethodFn compress;
  // --bytes by components: the stored bytes at c components per slot / cluster / matrix (an
  // upper bound: clamping only shrinks a codec); null where the method meets --bytes itself.
  double (*bytes_at)(const CompressOptions& options, const SlotSource& input, double c);
  bool streams_slots;  // writes its arrays through MethodContext::writer as it goes
};

// The method table's entry for `method`.
const MethodEntry& FindMethod(CodecMethod method);

// The methods (one file each).
std::uint64_t CompressPcaView(const MethodContext& context, Codec& codec, CompressSummary& summary);
std::uint64_t CompressLpca(const MethodContext& context, Codec& codec, CompressSummary& summary);
std::uint64_t CompressLpcaTensor(const MethodContext& context, Codec& codec, CompressSummary& summary);
std::uint64_t CompressFmf(const MethodContext& context, Codec& codec, CompressSummary& summary);
std::uint64_t CompressNeural(const MethodContext& context, Codec& codec, CompressSummary& summary);

// The summary's error fields from error sums in the original domain (ErrorStats' definitions).
void FillErrors(const ErrorStats& errors, CompressSummary& summary);

// Errors of a codec against its input in the original domain: decoded slot by slot, one image
// per task, merged in (view, light) order. Distributed, each rank decodes and reads the view
// slots it owns (round robin) and every rank merges every image's sums in the same order.
ErrorStats MeasureErrors(const SlotSource& input, const Codec& codec, const dist::Context& ranks);

// The per-slot / per-cluster PCA request of the options (seed mixed with seed_offset).
PcaRequest MakeRequest(const CompressOptions& options, std::uint64_t seed_offset);

}  // namespace btf
