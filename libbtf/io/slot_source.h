#pragma once
// A BTF read view slot by view slot, whatever stores it: a dataset file (streamed through
// DatasetReader), an in-memory Dataset, or a codec (libbtf/compress/codec_source.h). Compression
// and metrics need only this interface, so neither holds more than a few view slots of an input
// in memory.
#include <filesystem>
#include <memory>
#include <string>

#include "libbtf/core/dataset.h"
#include "libbtf/io/dataset_io.h"

namespace btf {

class SlotSource {
 public:
  virtual ~SlotSource() = default;
  // What error messages call this input (a path, or "in-memory dataset").
  virtual const std::string& name() const = 0;
  // "libbtf-dataset", "libbtf-codec" or "memory".
  virtual std::string kind() const = 0;
  virtual const Sampling& views() const = 0;
  virtual const Sampling& lights() const = 0;
  virtual int height() const = 0;
  virtual int width() const = 0;
  virtual int channels() const = 0;
  virtual DatasetInfo info() const = 0;
  // lights x height x width x channels floats.
  virtual void ReadViewSlot(int view, float* out) const = 0;
  // The view slot as ReadViewSlot writes it, where the source holds it in memory (read it there,
  // without a copy; valid while the source lives), or nullptr (the default): then ReadViewSlot.
  virtual const float* ViewSlotData(int view) const { return nullptr; }
  // height x width x channels floats (default: reads the view slot and copies one image).
  virtual void ReadImage(int view, int light, float* out) const;
  // (view, light) images the source marks missing (a dataset file's /btf/missing): their values
  // are 0, not measurements. Default: none.
  virtual std::vector<std::pair<int, int>> missing() const { return {}; }

  std::size_t image_size() const { return std::size_t(height()) * width() * channels(); }
  std::size_t slot_size() const { return image_size() * std::size_t(lights().size()); }
};

// The in-memory dataset must outlive the source.
std::unique_ptr<SlotSource> MemorySource(const Dataset& dataset, std::string name = "in-memory dataset");
// A dataset file ("libbtf-dataset"), read one slot at a time; bad files throw btf::Error naming it.
std::unique_ptr<SlotSource> OpenDatasetSource(const std::filesystem::path& path, const DatasetReadOptions& options = {});

// Throws btf::Error (bad input) unless both have the same shape and samplings (directions equal to
// 1e-6, about 0.2 arc seconds); the message names both inputs and the first difference.
void CheckCompatible(const SlotSource& reference, const SlotSource& test);

// Throws btf::Error (bad input) at the first NaN or Inf in one view slot (lights x height x
// width x channels of `source`), naming the input, view, light, texel and channel.
void CheckFiniteSlot(const SlotSource& source, int view, const float* slot);

}  // namespace btf
