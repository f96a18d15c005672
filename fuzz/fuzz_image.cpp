// Fuzzes image reading as we interpret it (headers, sRGB decision, size limits) for PNG and EXR.
// The first byte picks the container (bit 0) and the pixel limit (bit 1: the default, or 4096
// pixels, so that both sides of the max_pixels check are reached by small inputs).
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
  btf::ImageReadOptions options;
  if (data[0] & 2) options.max_pixels = 4096;
  try {
    btf::ReadImage(in.path(), options);
  } catch (const btf::Error&) {
  }
  return 0;
}
