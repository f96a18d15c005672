// module: io
// Bonn .btf reader, BDI (!BDIF06R2!): raw bytes after the signature (fuzz/fuzz_bonn.h).
#include "fuzz/fuzz_bonn.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return btf::fuzz::RunBonnReader("!BDIF06R2!", data, size);
}
