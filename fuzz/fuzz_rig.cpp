// module: io
// Fuzzes the rig readers (board.json, a Kalibr board .yaml through OpenCV's parser, manifest.json,
// truth.json): the first byte picks the reader (0 board, 1 manifest, 2 truth, 3 Kalibr YAML).
#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/rig.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const int reader = data[0] % 4;
  btf::fuzz::TempInput in(data + 1, size - 1, reader == 3 ? ".yaml" : ".json");
  try {
    switch (reader) {
      case 0:
      case 3: btf::ReadBoard(in.path()); break;
      case 1: btf::ReadManifest(in.path()); break;
      default: btf::ReadTruth(in.path()); break;
    }
  } catch (const btf::Error&) {
  }
  return 0;
}
