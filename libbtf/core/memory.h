#pragma once
// Memory for large arrays: huge-page advice, and scratch buffers outside the allocator's heap.
#include <cstddef>

namespace btf {

// Asks the kernel to back the whole 2 MiB pages inside [data, data + bytes) with transparent huge
// pages, before the array is first written: one page fault per 2 MiB instead of one per 4 KiB.
// Call it on arrays of many MiB that are filled at once (LPCA's texel matrix: docs/performance.md,
// "LPCA"). Advice only: nothing changes where the kernel or the system's setting
// (/sys/kernel/mm/transparent_hugepage/enabled: never) declines.
void AdviseHugePages(void* data, std::size_t bytes);

// Returns the allocator's free memory to the system (glibc: malloc_trim, which also releases the
// whole free pages inside each arena, not only at its top; elsewhere nothing). For the end of a
// phase that freed many MiB of working arrays interleaved with what it keeps: without it, those
// holes stay resident into the next phase (LPCA's rounds: docs/performance.md, "LPCA"). Changes
// no allocator setting.
void ReleaseFreeHeap();

// A grow-only scratch buffer in its own anonymous mapping, with huge-page advice: for working
// arrays of MiBs that are filled, used and dropped over and over (a block of gathered rows, a
// slot read). Kept out of malloc on purpose: glibc serves a large block with mmap and, when it is
// freed, raises its mmap threshold to that size and its trim threshold to twice it, so that each
// thread's arena then keeps up to twice the largest such block of free memory resident (LPCA's
// peak: docs/performance.md, "LPCA"). Move-only; the pages go back to the system on destruction.
class PageBuffer {
 public:
  PageBuffer() = default;
  PageBuffer(PageBuffer&& o) noexcept : data_(o.data_), bytes_(o.bytes_) { o.data_ = nullptr, o.bytes_ = 0; }
  PageBuffer& operator=(PageBuffer&& o) noexcept;
  PageBuffer(const PageBuffer&) = delete;
  PageBuffer& operator=(const PageBuffer&) = delete;
  ~PageBuffer();
  // At least n values of T (contents unspecified once it grows; throws std::bad_alloc).
  template <typename T>
  T* Get(std::size_t n) {
    Reserve(n * sizeof(T));
    return static_cast<T*>(data_);
  }

 private:
  void Reserve(std::size_t bytes);
  void Release() noexcept;
  void* data_ = nullptr;
  std::size_t bytes_ = 0;
};

}  // namespace btf
