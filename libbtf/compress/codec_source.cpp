#include "libbtf/compress/codec_source.h"

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/file_kind.h"

namespace btf {

namespace {

class CodecSlotSource final : public SlotSource {
 public:
  CodecSlotSource(Codec codec, std::string name) : codec_(std::move(codec)), name_(std::move(name)) {}
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

}  // namespace

std::unique_ptr<SlotSource> OpenCodecSource(const std::filesystem::path& path) {
  return std::make_unique<CodecSlotSource>(ReadCodec(path), path.string());
}

std::unique_ptr<SlotSource> OpenSource(const std::filesystem::path& path, const DatasetReadOptions& read) {
  const std::string format = FileFormatOf(path);
  if (format == kDatasetFormat) return OpenDatasetSource(path, read);
  if (format == kCodecFormat) return OpenCodecSource(path);
  if (IsBonnFormat(format)) return OpenBonnSource(path);
  ThrowBadInput("'{}' holds format '{}'; expected a libbtf dataset or codec, or a Bonn .btf file", path.string(), format);
}

std::unique_ptr<SlotSource> OpenCompressInput(const std::filesystem::path& path, const DatasetReadOptions& read) {
  return IsBonnFile(path) ? OpenBonnSource(path) : OpenDatasetSource(path, read);
}

}  // namespace btf
