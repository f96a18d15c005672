#pragma once
// The double kernels of per-view PCA (WidePca): the Gram matrix of a few long rows, and the basis
// rows S T of a centred tile. Each result has one fixed order of floating-point operations, chosen
// by the data's column index alone, so the bits do not depend on the tile width, the thread or the
// instruction set the kernel runs with (AVX-512, AVX2 or plain C++, chosen at run time; all use
// fused multiply-adds, so all give the same bits):
//   Gram:  G(i, j) = sum over lanes q = 0..7 (in the order ((0+4)+(2+6))+((1+5)+(3+7))) of
//          g_q(i, j), where g_q(i, j) is the FMA chain over the columns k = q, q + 8, q + 16, ...
//          in increasing k, over every tile added since Reset;
//   basis: B(r, k) = the FMA chain over i = 0..n-1 of S(r, i) T(i, k), from 0.
// docs/performance.md, "Per-view PCA kernels".
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace btf {

enum class KernelIsa { kAuto, kGeneric, kAvx2, kAvx512 };

// The instruction set kAuto resolves to on this machine.
KernelIsa BestKernelIsa();
const char* KernelIsaName(KernelIsa isa);

// Accumulates T T^T over row-major tiles T (n rows, w columns, row stride ld) in 8 lanes per entry.
class LaneGram {
 public:
  explicit LaneGram(Eigen::Index n, KernelIsa isa = KernelIsa::kAuto);
  void Reset();
  // Adds the tile's columns [0, w); w must be a multiple of 8 (callers pad with zero columns,
  // which leave every lane unchanged).
  void Add(const double* T, Eigen::Index ld, Eigen::Index w);
  // G (n x n, both triangles) from the lanes.
  Eigen::MatrixXd Reduce() const;
  KernelIsa isa() const { return isa_; }

 private:
  Eigen::Index n_, np_;  // rows, and rows padded to the kernel's blocks
  KernelIsa isa_;
  std::vector<double> lanes_;  // np_ x np_ x 8, entry (i, j) at (i * np_ + j) * 8
  std::vector<double> zero_;   // a zero row for the padding
};

// B (c x w, row-major, row stride ldb) = S (c x n, row-major) T (n x w, row-major, row stride ld);
// w must be a multiple of 8.
void BasisProduct(const double* S, Eigen::Index c, Eigen::Index n, const double* T, Eigen::Index ld, Eigen::Index w,
                  double* B, Eigen::Index ldb, KernelIsa isa = KernelIsa::kAuto);

}  // namespace btf
