#pragma once
// Writes a codec file ("libbtf-codec", docs/format.md) in parts, for a compressor that streams
// per-view PCA slots to the file as it makes them (CompressToFile). WriteCodec is this writer
// given the whole codec at once, so both write the same datasets and attributes.
#include <string>

#include "libbtf/compress/codec.h"
#include "libbtf/io/hdf5.h"

namespace btf {

class CodecFileWriter {
 public:
  // Creates `out`'s temporary and writes the header, the /codec attributes and the sampling
  // tables of `codec` (its shape, method, storage and info; no coefficient arrays yet).
  CodecFileWriter(AtomicOutput& out, const Codec& codec, const std::string& creator);

  // pca-view: one view slot's arrays, then the kernel is asked to start writing them back to the
  // disk (best effort), so that the final fsync does not wait for the whole codec.
  void WritePcaViewSlot(int view, const PcaViewSlot& slot);

  // The rest of `codec`: pca-view's components per slot (slots already written are not written
  // again: `slots_written` of them, from view 0), every other method's model, and the
  // compression provenance; then flushes, closes and commits the output.
  void Finish(const Codec& codec, int slots_written);

 private:
  AtomicOutput& out_;
  h5::File file_;
  h5::Storage storage_;
  hsize_t L_, H_, W_, C_;  // lights, height, width, channels
};

}  // namespace btf
