#pragma once
// Compression: the controller of compress/ (compress.cpp opens nothing itself: it takes a
// view-slot source, applies a scene and a byte budget, picks the method from the table in
// method.h, writes the codec and fills the summary). Library entry points of btf-compress.
#include <string>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress_options.h"
#include "libbtf/compress/compress_summary.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/progress.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// Compresses `input` (an in-memory dataset through MemorySource, a file through
// OpenDatasetSource, ...) into *codec. pca-view reads it view slot by view slot (memory: about
// three view slots); lpca reads it slot by slot into a texel-major matrix (memory: the BTF once).
// NaN/Inf anywhere gives btf::Error (bad input) naming the item.
CompressSummary Compress(const CompressOptions& options, const SlotSource& input, Codec* codec,
                         const Reporter& reporter = {}, const dist::Context& ranks = dist::Context::World());

// Compress, then the codec file written into `out` and committed (nullptr: nothing written, e.g.
// on the MPI ranks other than 0): the same file as Compress + WriteCodec. pca-view in one process
// writes each view slot as soon as it and the slots before it are done, so the write overlaps the
// decomposition and the codec is never all in memory (at Bonn size 1 GiB of float coefficients).
// On failure nothing is committed.
CompressSummary CompressToFile(const CompressOptions& options, const SlotSource& input, AtomicOutput* out,
                               const std::string& creator, const Reporter& reporter = {}, const dist::Context& ranks = dist::Context::World());

}  // namespace btf
