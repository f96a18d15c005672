#include "libbtf/compress/gram_kernel.h"

#include <algorithm>
#include <cmath>

#include "libbtf/core/error.h"

#if defined(__x86_64__) || defined(_M_X64)
#define BTF_KERNEL_X86 1
#include <immintrin.h>
#endif

namespace btf {

namespace {

using Index = Eigen::Index;
constexpr int kLanes = 8;
// Rows are padded to a multiple of this (the AVX-512 Gram block is 4 x 6 rows, AVX2's 2 x 2).
constexpr Index kRowPad = 12;

// ----- plain C++: the definition of the order, and the fallback -------------------------------

void GramGeneric(const double* const* row, Index n, Index np, double* lanes, Index w) {
  for (Index i = 0; i < n; ++i)
    for (Index j = 0; j <= i; ++j) {
      double* acc = lanes + (i * np + j) * kLanes;
      for (Index k = 0; k < w; k += kLanes)
        for (int q = 0; q < kLanes; ++q) acc[q] = std::fma(row[i][k + q], row[j][k + q], acc[q]);
    }
}

void BasisGeneric(const double* S, Index c, Index n, const double* T, Index ld, Index w, double* B, Index ldb) {
  for (Index r = 0; r < c; ++r)
    for (Index k = 0; k < w; ++k) {
      double acc = 0;
      for (Index i = 0; i < n; ++i) acc = std::fma(S[r * n + i], T[i * ld + k], acc);
      B[r * ldb + k] = acc;
    }
}

#ifdef BTF_KERNEL_X86

// ----- AVX-512: Gram blocks of 4 x 6 entries (24 accumulators), basis blocks of 8 rows x 24 columns

__attribute__((target("avx512f"))) void GramAvx512(const double* const* row, Index n, Index np, double* lanes,
                                                    Index w) {
  constexpr int MI = 4, NJ = 6;
  for (Index j0 = 0; j0 < n; j0 += NJ)
    for (Index i0 = j0 / MI * MI; i0 < n; i0 += MI) {
      __m512d acc[MI][NJ];
      for (int x = 0; x < MI; ++x)
        for (int y = 0; y < NJ; ++y) acc[x][y] = _mm512_loadu_pd(lanes + ((i0 + x) * np + j0 + y) * kLanes);
      const double* a[MI] = {row[i0], row[i0 + 1], row[i0 + 2], row[i0 + 3]};
      const double* b[NJ] = {row[j0], row[j0 + 1], row[j0 + 2], row[j0 + 3], row[j0 + 4], row[j0 + 5]};
      for (Index k = 0; k < w; k += kLanes) {
        __m512d av[MI];
#pragma GCC unroll 4
        for (int x = 0; x < MI; ++x) av[x] = _mm512_loadu_pd(a[x] + k);
#pragma GCC unroll 6
        for (int y = 0; y < NJ; ++y) {
          const __m512d bv = _mm512_loadu_pd(b[y] + k);
#pragma GCC unroll 4
          for (int x = 0; x < MI; ++x) acc[x][y] = _mm512_fmadd_pd(av[x], bv, acc[x][y]);
        }
      }
      for (int x = 0; x < MI; ++x)
        for (int y = 0; y < NJ; ++y) _mm512_storeu_pd(lanes + ((i0 + x) * np + j0 + y) * kLanes, acc[x][y]);
    }
}

template <int RB>
__attribute__((target("avx512f"))) void BasisBlockAvx512(const double* S, Index n, const double* T, Index ld,
                                                          Index k0, int vecs, double* B, Index ldb) {
  __m512d acc[RB][3];
  for (int r = 0; r < RB; ++r)
    for (int v = 0; v < 3; ++v) acc[r][v] = _mm512_setzero_pd();
  for (Index i = 0; i < n; ++i) {
    const double* t = T + i * ld + k0;
    __m512d tv[3];
#pragma GCC unroll 3
    for (int v = 0; v < 3; ++v) tv[v] = v < vecs ? _mm512_loadu_pd(t + 8 * v) : _mm512_setzero_pd();
#pragma GCC unroll 8
    for (int r = 0; r < RB; ++r) {
      const __m512d s = _mm512_set1_pd(S[r * n + i]);
#pragma GCC unroll 3
      for (int v = 0; v < 3; ++v) acc[r][v] = _mm512_fmadd_pd(s, tv[v], acc[r][v]);
    }
  }
  for (int r = 0; r < RB; ++r)
    for (int v = 0; v < vecs; ++v) _mm512_storeu_pd(B + r * ldb + k0 + 8 * v, acc[r][v]);
}

// ----- AVX2: the same 8 lanes as two 4-wide halves; Gram blocks of 2 x 2, basis 4 rows x 12 columns

__attribute__((target("avx2,fma"))) void GramAvx2(const double* const* row, Index n, Index np, double* lanes,
                                                   Index w) {
  constexpr int MI = 2, NJ = 2;
  for (Index j0 = 0; j0 < n; j0 += NJ)
    for (Index i0 = j0 / MI * MI; i0 < n; i0 += MI) {
      __m256d acc[MI][NJ][2];
      for (int x = 0; x < MI; ++x)
        for (int y = 0; y < NJ; ++y)
          for (int h = 0; h < 2; ++h) acc[x][y][h] = _mm256_loadu_pd(lanes + ((i0 + x) * np + j0 + y) * kLanes + 4 * h);
      for (Index k = 0; k < w; k += kLanes)
#pragma GCC unroll 2
        for (int h = 0; h < 2; ++h) {
          const __m256d a0 = _mm256_loadu_pd(row[i0] + k + 4 * h), a1 = _mm256_loadu_pd(row[i0 + 1] + k + 4 * h);
          const __m256d b0 = _mm256_loadu_pd(row[j0] + k + 4 * h), b1 = _mm256_loadu_pd(row[j0 + 1] + k + 4 * h);
          acc[0][0][h] = _mm256_fmadd_pd(a0, b0, acc[0][0][h]);
          acc[1][0][h] = _mm256_fmadd_pd(a1, b0, acc[1][0][h]);
          acc[0][1][h] = _mm256_fmadd_pd(a0, b1, acc[0][1][h]);
          acc[1][1][h] = _mm256_fmadd_pd(a1, b1, acc[1][1][h]);
        }
      for (int x = 0; x < MI; ++x)
        for (int y = 0; y < NJ; ++y)
          for (int h = 0; h < 2; ++h) _mm256_storeu_pd(lanes + ((i0 + x) * np + j0 + y) * kLanes + 4 * h, acc[x][y][h]);
    }
}

template <int RB>
__attribute__((target("avx2,fma"))) void BasisBlockAvx2(const double* S, Index n, const double* T, Index ld, Index k0,
                                                         int vecs, double* B, Index ldb) {
  __m256d acc[RB][3];
  for (int r = 0; r < RB; ++r)
    for (int v = 0; v < 3; ++v) acc[r][v] = _mm256_setzero_pd();
  for (Index i = 0; i < n; ++i) {
    const double* t = T + i * ld + k0;
    __m256d tv[3];
#pragma GCC unroll 3
    for (int v = 0; v < 3; ++v) tv[v] = v < vecs ? _mm256_loadu_pd(t + 4 * v) : _mm256_setzero_pd();
#pragma GCC unroll 4
    for (int r = 0; r < RB; ++r) {
      const __m256d s = _mm256_set1_pd(S[r * n + i]);
#pragma GCC unroll 3
      for (int v = 0; v < 3; ++v) acc[r][v] = _mm256_fmadd_pd(s, tv[v], acc[r][v]);
    }
  }
  for (int r = 0; r < RB; ++r)
    for (int v = 0; v < vecs; ++v) _mm256_storeu_pd(B + r * ldb + k0 + 4 * v, acc[r][v]);
}

// One block of rb basis rows (1 <= rb <= the kernel's block height) over `vecs` vectors of columns.
using BasisBlock = void (*)(const double* S, Index n, const double* T, Index ld, Index k0, int vecs, double* B,
                            Index ldb);
constexpr BasisBlock kAvx512Blocks[] = {BasisBlockAvx512<1>, BasisBlockAvx512<2>, BasisBlockAvx512<3>,
                                        BasisBlockAvx512<4>, BasisBlockAvx512<5>, BasisBlockAvx512<6>,
                                        BasisBlockAvx512<7>, BasisBlockAvx512<8>};
constexpr BasisBlock kAvx2Blocks[] = {BasisBlockAvx2<1>, BasisBlockAvx2<2>, BasisBlockAvx2<3>, BasisBlockAvx2<4>};

// Runs blocks[rb - 1] over rows [r0, r0 + rb), rb <= height, and column chunks of 3 vectors of
// `vec` values (the last chunk shorter).
void BasisRows(const BasisBlock* blocks, int height, int vec, const double* S, Index c, Index n, const double* T,
               Index ld, Index w, double* B, Index ldb) {
  for (Index r0 = 0; r0 < c; r0 += height) {
    const int rb = static_cast<int>(std::min<Index>(height, c - r0));
    for (Index k0 = 0; k0 < w; k0 += 3 * vec)
      blocks[rb - 1](S + r0 * n, n, T, ld, k0, static_cast<int>(std::min<Index>(3, (w - k0) / vec)), B + r0 * ldb, ldb);
  }
}

#endif  // BTF_KERNEL_X86

KernelIsa Resolve(KernelIsa isa) {
  if (isa == KernelIsa::kAuto) return BestKernelIsa();
  if (isa != KernelIsa::kGeneric && int(isa) > int(BestKernelIsa()))
    ThrowUsage("kernel instruction set {} is not supported by this CPU (it has {})", KernelIsaName(isa),
               KernelIsaName(BestKernelIsa()));
  return isa;
}

}  // namespace

KernelIsa BestKernelIsa() {
#ifdef BTF_KERNEL_X86
  static const KernelIsa best = [] {
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f")) return KernelIsa::kAvx512;
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return KernelIsa::kAvx2;
    return KernelIsa::kGeneric;
  }();
  return best;
#else
  return KernelIsa::kGeneric;
#endif
}

const char* KernelIsaName(KernelIsa isa) {
  switch (isa) {
    case KernelIsa::kAuto: return "auto";
    case KernelIsa::kGeneric: return "generic";
    case KernelIsa::kAvx2: return "avx2";
    case KernelIsa::kAvx512: return "avx512";
  }
  return "?";
}

LaneGram::LaneGram(Index n, KernelIsa isa)
    : n_(n), np_((n + kRowPad - 1) / kRowPad * kRowPad), isa_(Resolve(isa)),
      lanes_(static_cast<std::size_t>(np_ * np_ * kLanes), 0.0) {}

void LaneGram::Reset() { std::fill(lanes_.begin(), lanes_.end(), 0.0); }

void LaneGram::Add(const double* T, Index ld, Index w) {
  BTF_CHECK(w % kLanes == 0);
  if (static_cast<Index>(zero_.size()) < w) zero_.assign(static_cast<std::size_t>(w), 0.0);
  // Chunks of kChunk columns: the rows one block of the kernel reads (10 with AVX-512) stay in L1.
  constexpr Index kChunk = 256;
  std::vector<const double*> row(static_cast<std::size_t>(np_), zero_.data());
  for (Index k0 = 0; k0 < w; k0 += kChunk) {
    const Index wc = std::min(kChunk, w - k0);
    for (Index i = 0; i < n_; ++i) row[static_cast<std::size_t>(i)] = T + i * ld + k0;
    switch (isa_) {
#ifdef BTF_KERNEL_X86
      case KernelIsa::kAvx512: GramAvx512(row.data(), n_, np_, lanes_.data(), wc); break;
      case KernelIsa::kAvx2: GramAvx2(row.data(), n_, np_, lanes_.data(), wc); break;
#endif
      default: GramGeneric(row.data(), n_, np_, lanes_.data(), wc);
    }
  }
}

Eigen::MatrixXd LaneGram::Reduce() const {
  Eigen::MatrixXd G(n_, n_);
  for (Index i = 0; i < n_; ++i)
    for (Index j = 0; j <= i; ++j) {
      const double* l = lanes_.data() + (i * np_ + j) * kLanes;
      G(i, j) = G(j, i) = ((l[0] + l[4]) + (l[2] + l[6])) + ((l[1] + l[5]) + (l[3] + l[7]));
    }
  return G;
}

void BasisProduct(const double* S, Index c, Index n, const double* T, Index ld, Index w, double* B, Index ldb,
                  KernelIsa isa) {
  BTF_CHECK(w % kLanes == 0);
  switch (Resolve(isa)) {
#ifdef BTF_KERNEL_X86
    case KernelIsa::kAvx512: return BasisRows(kAvx512Blocks, 8, 8, S, c, n, T, ld, w, B, ldb);
    case KernelIsa::kAvx2: return BasisRows(kAvx2Blocks, 4, 4, S, c, n, T, ld, w, B, ldb);
#endif
    default: return BasisGeneric(S, c, n, T, ld, w, B, ldb);
  }
}

}  // namespace btf
