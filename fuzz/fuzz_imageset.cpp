// Fuzzes the image-set importer on zip archives (libzip's parser, our entry reading, CRC and size
// checks, name matching, then the images) into a dataset.
#include <OpenImageIO/imageio.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/convert.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  setenv("BTF_MAX_BYTES", "67108864", 1);
  OIIO::attribute("try_all_readers", 0);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  btf::fuzz::TempInput in(data, size, ".zip");
  const std::filesystem::path out = in.path() + ".h5";
  btf::ConvertOptions o;
  o.layout = "pattern";
  o.pattern = "{tv}_{pv}_{tl}_{pl}.png";
  o.allow_missing = true;
  try {
    btf::ImportImageSet(o, in.path(), out);
  } catch (const btf::Error&) {
  }
  std::error_code ec;
  std::filesystem::remove(out, ec);
  return 0;
}
