// core/memory.h: PageBuffer (scratch outside the allocator's heap) and ReleaseFreeHeap.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numeric>
#include <vector>

#include <gtest/gtest.h>

#include "libbtf/core/memory.h"

namespace btf {
namespace {

// Resident bytes of this process (Linux: /proc/self/statm), or 0.
std::size_t ResidentBytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  unsigned long size = 0, resident = 0;
  const int got = std::fscanf(f, "%lu %lu", &size, &resident);
  std::fclose(f);
  return got == 2 ? std::size_t(resident) * 4096 : 0;
}

TEST(PageBuffer, GrowsKeepsItsSizeAndMoves) {
  PageBuffer b;
  float* p = b.Get<float>(1000);
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % 4096, 0u);  // a mapping of its own: page-aligned
  std::iota(p, p + 1000, 0.0f);
  EXPECT_EQ(b.Get<float>(10), p);  // no smaller request moves it
  EXPECT_EQ(b.Get<float>(1000)[999], 999.0f);
  const std::size_t big = std::size_t(8) << 20;  // 32 MiB of floats: every page writable
  float* q = b.Get<float>(big);
  for (std::size_t i = 0; i < big; i += 1024) q[i] = float(i);
  EXPECT_EQ(q[big - 1024], float(big - 1024));
  PageBuffer moved(std::move(b));
  EXPECT_EQ(moved.Get<float>(big), q);
  EXPECT_EQ(moved.Get<float>(big)[1024], 1024.0f);
  PageBuffer other;
  other = std::move(moved);
  EXPECT_EQ(other.Get<float>(16), q);
}

TEST(ReleaseFreeHeap, ReturnsHolesBetweenLiveBlocks) {
#if defined(__SANITIZE_ADDRESS__) || !defined(__GLIBC__)
  GTEST_SKIP() << "glibc's allocator only (the sanitizer build has its own)";
#else
  if (ResidentBytes() == 0) GTEST_SKIP() << "no /proc/self/statm";
  // 48 MiB in 64 KiB blocks (below glibc's mmap threshold: from the heap), each followed by a
  // small block that stays: freeing the large ones leaves holes that glibc's free() keeps
  // resident, which ReleaseFreeHeap must return (at least half of them: page rounding and the
  // allocator's bookkeeping keep some).
  constexpr std::size_t kBlocks = 768, kBlock = 64 << 10;
  std::vector<std::unique_ptr<char[]> > large, small;
  for (std::size_t i = 0; i < kBlocks; ++i) {
    large.emplace_back(new char[kBlock]);
    std::fill_n(large.back().get(), kBlock, char(i));
    small.emplace_back(new char[64]);
    small.back()[0] = char(i);
  }
  large.clear();
  const std::size_t before = ResidentBytes();
  ReleaseFreeHeap();
  const std::size_t after = ResidentBytes();
  EXPECT_GE(double(before) - double(after), 0.5 * kBlocks * kBlock) << before << " -> " << after << " bytes";
  EXPECT_EQ(small[5][0], char(5));
#endif
}

}  // namespace
}  // namespace btf
