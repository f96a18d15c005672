// Fuzzes the dataset reader (schema validation on top of HDF5) and btf-info's describer. The
// texel values are read through both paths (raw chunks decoded by libbtf, and H5Dread): each
// may refuse a damaged file, but when both accept it they must agree bit for bit.
#include <cstdlib>
#include <cstring>
#include <optional>

#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/file_kind.h"

namespace {
std::optional<btf::Dataset> Read(const std::filesystem::path& path, bool raw_chunks) {
  btf::DatasetReadOptions o;
  o.raw_chunks = raw_chunks;
  try {
    return btf::ReadDataset(path, o);
  } catch (const btf::Error&) {
    return std::nullopt;
  }
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  btf::fuzz::TempInput in(data, size, ".h5");
  try {
    btf::DescribeDatasetFile(in.path(), true);
  } catch (const btf::Error&) {
  }
  const auto raw = Read(in.path(), true), hdf5 = Read(in.path(), false);
  if (raw && hdf5 &&
      (raw->size() != hdf5->size() || std::memcmp(raw->data().data(), hdf5->data().data(), raw->size() * 4) != 0))
    std::abort();  // the raw chunk path and H5Dread disagree on a file both accept
  return 0;
}
