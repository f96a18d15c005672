// module: io
// Fuzzes the rig readers (board.json, manifest.json, truth.json): the first byte picks the reader.
#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/rig.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  btf::fuzz::TempInput in(data + 1, size - 1, ".json");
  try {
    switch (data[0] % 3) {
      case 0: btf::ReadBoard(in.path()); break;
      case 1: btf::ReadManifest(in.path()); break;
      default: btf::ReadTruth(in.path()); break;
    }
  } catch (const btf::Error&) {
  }
  return 0;
}
