#pragma once
// Memory advice for large arrays.
#include <cstddef>

namespace btf {

// Asks the kernel to back the whole 2 MiB pages inside [data, data + bytes) with transparent huge
// pages, before the array is first written: one page fault per 2 MiB instead of one per 4 KiB.
// Call it on arrays of many MiB that are filled at once (LPCA's texel matrix: docs/performance.md,
// "LPCA"). Advice only: nothing changes where the kernel or the system's setting
// (/sys/kernel/mm/transparent_hugepage/enabled: never) declines.
void AdviseHugePages(void* data, std::size_t bytes);

}  // namespace btf
