// Per-view PCA's double kernels (gram_kernel.h): the documented summation order, the same bits
// for every instruction set this CPU has and every tile width, and WidePca's bytes unchanged by
// the instruction set.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "libbtf/compress/gram_kernel.h"
#include "libbtf/compress/pca.h"
#include "libbtf/core/error.h"

namespace btf {
namespace {

using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Every instruction set the kernels can run with on this machine (generic always).
std::vector<KernelIsa> Supported() {
  std::vector<KernelIsa> isas{KernelIsa::kGeneric};
  if (int(BestKernelIsa()) >= int(KernelIsa::kAvx2)) isas.push_back(KernelIsa::kAvx2);
  if (BestKernelIsa() == KernelIsa::kAvx512) isas.push_back(KernelIsa::kAvx512);
  return isas;
}

RowMatrixXd Random(Eigen::Index rows, Eigen::Index cols, std::uint64_t seed, double offset = 0) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  RowMatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = offset + g(rng);
  return m;
}

bool SameBits(const double* a, const double* b, Eigen::Index n) { return std::memcmp(a, b, sizeof(double) * n) == 0; }

// The order gram_kernel.h defines, written out: lane q is the FMA chain over k = q mod 8.
double DocumentedGramEntry(const RowMatrixXd& T, Eigen::Index i, Eigen::Index j) {
  double l[8] = {};
  for (Eigen::Index k = 0; k < T.cols(); ++k) l[k % 8] = std::fma(T(i, k), T(j, k), l[k % 8]);
  return ((l[0] + l[4]) + (l[2] + l[6])) + ((l[1] + l[5]) + (l[3] + l[7]));
}

TEST(LaneGram, EveryInstructionSetAndTileWidthGivesTheDocumentedBits) {
  // Row counts around the kernels' blocks (4 x 6 with AVX-512, 2 x 2 with AVX2, padding to 12),
  // 81 (Bonn lights) and 151 (UBO2014).
  for (const Eigen::Index n : {1, 2, 5, 12, 13, 81, 151}) {
    const RowMatrixXd T = Random(n, 8 * 37, std::uint64_t(n), 3.0);
    Eigen::MatrixXd expected(n, n);
    for (Eigen::Index i = 0; i < n; ++i)
      for (Eigen::Index j = 0; j <= i; ++j) expected(i, j) = expected(j, i) = DocumentedGramEntry(T, i, j);
    for (const KernelIsa isa : Supported())
      for (const Eigen::Index tile : {8, 64, 8 * 37}) {  // added in tiles of this many columns
        LaneGram g(n, isa);
        for (Eigen::Index c0 = 0; c0 < T.cols(); c0 += tile)
          g.Add(T.data() + c0, T.cols(), std::min(tile, T.cols() - c0));
        const Eigen::MatrixXd G = g.Reduce();
        EXPECT_TRUE(SameBits(G.data(), expected.data(), n * n)) << KernelIsaName(isa) << " n " << n << " tile " << tile;
      }
  }
}

TEST(LaneGram, IsTheGramMatrixToDoubleRounding) {
  // Against long-double sums, relative to sum |T_ik T_jk|: 8 lanes of 37 FMAs each, then 3 levels
  // of additions, round at most 40 times, so the error is below 40 * 2^-53 = 4.4e-15 of it; 1e-14
  // leaves room for the long double's own rounding.
  const RowMatrixXd T = Random(13, 8 * 37, 5, 1.0);
  LaneGram g(13);
  g.Add(T.data(), T.cols(), T.cols());
  const Eigen::MatrixXd G = g.Reduce();
  for (Eigen::Index i = 0; i < 13; ++i)
    for (Eigen::Index j = 0; j < 13; ++j) {
      long double s = 0, a = 0;
      for (Eigen::Index k = 0; k < T.cols(); ++k) {
        s += (long double)T(i, k) * T(j, k);
        a += std::abs((long double)T(i, k) * T(j, k));
      }
      EXPECT_LE(std::abs(double(G(i, j) - s)), 1e-14 * double(a)) << i << "," << j;
    }
  // Reset starts a new sum.
  g.Reset();
  g.Add(T.data(), T.cols(), T.cols());
  EXPECT_TRUE(SameBits(g.Reduce().data(), G.data(), 13 * 13));
}

TEST(BasisProduct, EveryInstructionSetGivesTheDocumentedBits) {
  // B(r, k) = the FMA chain over i from 0; rows around the blocks (8 with AVX-512, 4 with AVX2),
  // widths around the 3-vector column chunks, a row stride wider than the width.
  for (const Eigen::Index c : {1, 3, 8, 11, 16})
    for (const Eigen::Index w : {8, 16, 24, 40, 264}) {
      const Eigen::Index n = 81, ld = w + 16;
      const RowMatrixXd S = Random(c, n, std::uint64_t(c)), T = Random(n, ld, std::uint64_t(w), 2.0);
      RowMatrixXd expected(c, w);
      for (Eigen::Index r = 0; r < c; ++r)
        for (Eigen::Index k = 0; k < w; ++k) {
          double acc = 0;
          for (Eigen::Index i = 0; i < n; ++i) acc = std::fma(S(r, i), T(i, k), acc);
          expected(r, k) = acc;
        }
      for (const KernelIsa isa : Supported()) {
        RowMatrixXd B = RowMatrixXd::Constant(c, w + 8, -7.0);  // the columns past w stay untouched
        BasisProduct(S.data(), c, n, T.data(), ld, w, B.data(), w + 8, isa);
        EXPECT_TRUE(SameBits(RowMatrixXd(B.leftCols(w)).data(), expected.data(), c * w))
            << KernelIsaName(isa) << " c " << c << " w " << w;
        EXPECT_TRUE((B.rightCols(8).array() == -7.0).all()) << KernelIsaName(isa);
      }
    }
}

TEST(WidePca, SameBytesWithEveryInstructionSet) {
  // A partial last tile whose width is not a multiple of 8 (zero-padded for the kernels).
  const Eigen::Index n = 29, d = 2 * kWideTile + 13;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<float> X(static_cast<std::size_t>(n * d));
  for (auto& x : X) x = 0.5f + u(rng);
  PcaRequest q;
  q.max_components = 7;
  const WidePcaResult ref = WidePca(X.data(), n, d, q, false, {}, KernelIsa::kGeneric);
  ASSERT_EQ(ref.components, 7);
  for (const KernelIsa isa : Supported()) {
    const WidePcaResult r = WidePca(X.data(), n, d, q, false, {}, isa);
    EXPECT_EQ(r.basis, ref.basis) << KernelIsaName(isa);
    EXPECT_EQ(r.weights, ref.weights) << KernelIsaName(isa);
    EXPECT_EQ(r.eigenvalues, ref.eigenvalues) << KernelIsaName(isa);
  }
}

TEST(KernelIsa, AnInstructionSetThisCpuLacksIsRefused) {
  if (BestKernelIsa() == KernelIsa::kAvx512) GTEST_SKIP() << "this CPU has every instruction set the kernels use";
  EXPECT_THROW(LaneGram(4, KernelIsa::kAvx512), Error);
}

}  // namespace
}  // namespace btf
