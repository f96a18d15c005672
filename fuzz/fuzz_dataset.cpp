// Fuzzes the dataset reader (schema validation on top of HDF5) and btf-info's describer.
#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/file_kind.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  btf::fuzz::TempInput in(data, size, ".h5");
  try {
    btf::DescribeDatasetFile(in.path(), true);
    btf::Dataset d = btf::ReadDataset(in.path());
  } catch (const btf::Error&) {
  }
  return 0;
}
