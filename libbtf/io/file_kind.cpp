#include "libbtf/io/file_kind.h"

#include "libbtf/io/bonn.h"
#include "libbtf/io/dataset_stats.h"
#include "libbtf/io/hdf5.h"

namespace btf {

std::string FileFormatOf(const std::filesystem::path& path) {
  // Bonn .btf files are recognised by their signature before HDF5 sees them.
  if (IsBonnFile(path)) {
    const std::string sig = BonnSignatureOf(path);  // throws for an unknown '!' signature
    if (sig.starts_with("!BDI")) return kBonnBdiFormat;
    if (sig.starts_with("!DFMF")) return kBonnDfmfFormat;
    if (sig.starts_with("!FMF")) return kBonnFmfFormat;
    return kBonnPvfFormat;
  }
  const h5::File f = h5::File::Open(path);
  if (!f.HasAttr("/", "format"))
    ThrowBadInput("'{}' is not a libbtf file: the root attribute 'format' is missing", path.string());
  return f.GetString("/", "format");
}

nlohmann::json DescribeDatasetFile(const std::filesystem::path& path, bool with_stats, const Reporter& reporter) {
  DatasetReader reader(path);
  nlohmann::json j = DescribeDatasetHeader(reader.header());
  if (with_stats) j["values"] = ComputeValueStats(reader, reporter).ToJson();
  return j;
}

}  // namespace btf
