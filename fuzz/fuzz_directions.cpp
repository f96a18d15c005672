// Fuzzes the direction-list parser.
#include "fuzz/fuzz_util.h"
#include "libbtf/core/directions.h"
#include "libbtf/core/error.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  btf::fuzz::TempInput in(data, size, ".txt");
  try {
    const btf::Sampling s = btf::Sampling::FromFile(in.path());
    if (s.size() > 0) s.Barycentric(s[0] + btf::Vec3(0.01, 0.02, 0));
  } catch (const btf::Error&) {
  }
  return 0;
}
