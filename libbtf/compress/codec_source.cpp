#include "libbtf/compress/codec_source.h"

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/file_kind.h"

namespace btf {

nlohmann::json CodecSource::Describe() const {
  nlohmann::json j = codec_.Describe();  // method, shape, samplings, components, sizes, transform
  j["path"] = name_;
  return j;
}

std::unique_ptr<CodecSource> OpenCodecSource(const std::filesystem::path& path) {
  return std::make_unique<CodecSource>(ReadCodec(path), path.string());
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

nlohmann::json DescribeFile(const std::filesystem::path& path, bool stats, const Reporter& reporter) {
  const std::string format = FileFormatOf(path);
  if (format == kDatasetFormat) return DescribeDatasetFile(path, stats, reporter);
  if (format == kCodecFormat) return OpenCodecSource(path)->Describe();
  if (IsBonnFormat(format)) return DescribeBonnFile(path, stats, reporter);
  ThrowBadInput("'{}' holds format '{}', which this build of libbtf does not know", path.string(), format);
}

}  // namespace btf
