// Fuzzes image reading as we interpret it (headers, sRGB decision, size limits) for PNG and EXR.
#include <OpenImageIO/imageio.h>

#include <cstdlib>

#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/image_io.h"

// Headers claiming huge sizes must be refused by the allocation limit, not decoded for seconds.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  setenv("BTF_MAX_BYTES", "67108864", 1);
  // Only the reader the extension names: trying every OIIO plugin per input costs ~1 s.
  OIIO::attribute("try_all_readers", 0);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  // First byte picks the container so one corpus covers both.
  btf::fuzz::TempInput in(data + 1, size - 1, data[0] & 1 ? ".exr" : ".png");
  try {
    btf::ReadImage(in.path());
  } catch (const btf::Error&) {
  }
  return 0;
}
