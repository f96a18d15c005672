#pragma once
// Shared body of the Bonn .btf reader targets (fuzz_bonn_bdi, _dfmf, _fmf, _pvf): the input is the
// file after its signature, so every execution reaches the format's own parser. Whatever the
// reader accepts must describe itself and decode every view slot without touching memory it does
// not own (ASan) or undefined behavior (UBSan).
#include <cstdint>
#include <cstring>
#include <vector>

#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"

namespace btf::fuzz {

inline int RunBonnReader(const char* signature, const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> file(signature, signature + std::strlen(signature));
  file.insert(file.end(), data, data + size);
  const TempInput in(file.data(), file.size(), ".btf");
  try {
    (void)DescribeBonnFile(in.path(), /*with_stats=*/false);
    const auto source = OpenBonnSource(in.path());
    std::vector<float> slot(source->slot_size());
    for (int v = 0; v < source->views().size(); ++v) source->ReadViewSlot(v, slot.data());
  } catch (const Error& e) {
    if (e.code() == ExitCode::kInternal) __builtin_trap();  // a broken invariant is a bug
  }
  return 0;
}

}  // namespace btf::fuzz
