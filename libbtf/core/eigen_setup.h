#pragma once
// Eigen sizes the blocks of its matrix products from the CPU's cache sizes, and the depth of a
// block (from the L1 size) decides where a long sum is split, so the last bits of a product
// depend on the machine: a 6 x 256 rank update differs by 4e-14 between a 32 KB and a 48 KB L1
// (docs/architecture.md, "Reproducibility"). Every libbtf program (the tools, the tests, the
// benchmarks, the Python module) calls this before its first product, so that results are the
// same on every CPU with the same instruction set; C++ users of the library should too.
#include <cstddef>

#include <Eigen/Core>

namespace btf {

// The L1 data cache size Eigen's blocking assumes (the most common x86-64 L1d).
inline constexpr std::ptrdiff_t kEigenL1Bytes = 32 * 1024;

// Sets Eigen's L1 size to kEigenL1Bytes, keeping the L2 and L3 sizes it detected (they decide
// only how the result is partitioned, not the order of any sum).
inline void FixEigenBlocking() {
  std::ptrdiff_t l1 = 0, l2 = 0, l3 = 0;
  Eigen::internal::manage_caching_sizes(Eigen::GetAction, &l1, &l2, &l3);
  Eigen::setCpuCacheSizes(kEigenL1Bytes, l2, l3);
}

}  // namespace btf
