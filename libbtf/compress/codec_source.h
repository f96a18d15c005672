#pragma once
// Codecs seen as view-slot sources (libbtf/io/slot_source.h), and the entry points that know every
// libbtf BTF file: open any of them as a source, choose the compression input, describe a file.
#include <filesystem>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/core/progress.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// A codec as a view-slot source, decoded one view slot at a time (Codec::DecodeViewSlot); the
// codec itself stays reachable for the decoders a slot source lacks (Value, DecodeAbrdf).
class CodecSource final : public SlotSource {
 public:
  CodecSource(Codec codec, std::string name) : codec_(std::move(codec)), name_(std::move(name)) {}
  const Codec& codec() const { return codec_; }
  // btf-info's summary of the codec file: Codec::Describe() and "path" (the name).
  nlohmann::json Describe() const;

  const std::string& name() const override { return name_; }
  std::string kind() const override { return kCodecFormat; }
  const Sampling& views() const override { return codec_.views(); }
  const Sampling& lights() const override { return codec_.lights(); }
  int height() const override { return codec_.height(); }
  int width() const override { return codec_.width(); }
  int channels() const override { return codec_.channels(); }
  DatasetInfo info() const override { return codec_.info(); }
  void ReadViewSlot(int view, float* out) const override { codec_.DecodeViewSlot(view, out); }
  void ReadImage(int view, int light, float* out) const override { codec_.DecodeImage(view, light, out); }

 private:
  Codec codec_;
  std::string name_;
};

// A codec file (ReadCodec), named by its path.
std::unique_ptr<CodecSource> OpenCodecSource(const std::filesystem::path& path);

// Opens a dataset or codec file, chosen by its "format" attribute (FileFormatOf), or a Bonn .btf
// file (libbtf/io/bonn.h, recognised by its signature). Other libbtf formats and foreign files
// throw btf::Error (bad input) naming the file. `read` applies to datasets. The source's kind()
// is the file's format name; a codec file gives a CodecSource.
std::unique_ptr<SlotSource> OpenSource(const std::filesystem::path& path, const DatasetReadOptions& read = {});

// What btf-compress (and libbtf.compress) compresses: a Bonn .btf file (recognised by its
// signature, decoded one view slot at a time) or else a dataset file (a codec is refused: it
// would be compressed twice).
std::unique_ptr<SlotSource> OpenCompressInput(const std::filesystem::path& path, const DatasetReadOptions& read = {});

// btf-info's summary of a dataset, codec or Bonn .btf file (chosen as OpenSource does; another
// format throws btf::Error, bad input, naming it): shape, samplings, conventions, sizes; `stats`
// adds the value scan of datasets and Bonn files (min, max, mean, NaN/Inf counts; it reads every
// value and reports progress to `reporter`). Codecs have no value scan.
nlohmann::json DescribeFile(const std::filesystem::path& path, bool stats, const Reporter& reporter = {});

}  // namespace btf
