// module: io
// Bonn .btf reader, DFMF (!DFMF08FCR): raw bytes after the signature (fuzz/fuzz_bonn.h).
#include "fuzz/fuzz_bonn.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return btf::fuzz::RunBonnReader("!DFMF08FCR", data, size);
}
