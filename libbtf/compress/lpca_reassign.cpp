#include "libbtf/compress/lpca_reassign.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/QR>

#include "libbtf/core/error.h"
#include "libbtf/io/half.h"

#if defined(__AVX2__) && defined(__FMA__) && defined(__F16C__)
#include <immintrin.h>
#define BTF_REASSIGN_AVX2 1
#endif

namespace btf {
namespace {

// Eight float lanes; fused multiply-add per lane. The AVX2 build and the portable one compute the
// same values (IEEE fma, exact half conversion).
#ifdef BTF_REASSIGN_AVX2
struct Lanes {
  __m256 v;
  static Lanes Zero() { return {_mm256_setzero_ps()}; }
  static Lanes Load(const float* p) { return {_mm256_loadu_ps(p)}; }
  static Lanes Load(const std::uint16_t* p) {
    return {_mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)))};
  }
  void Store(float* p) const { _mm256_storeu_ps(p, v); }
  friend Lanes operator-(Lanes a, Lanes b) { return {_mm256_sub_ps(a.v, b.v)}; }
  static Lanes Fma(Lanes a, Lanes b, Lanes c) { return {_mm256_fmadd_ps(a.v, b.v, c.v)}; }
  double Sum() const {
    alignas(32) float f[8];
    _mm256_store_ps(f, v);
    double s = 0;
    for (float x : f) s += double(x);
    return s;
  }
};
#else
struct Lanes {
  float v[8];
  static Lanes Zero() { return {}; }
  static Lanes Load(const float* p) {
    Lanes r;
    for (int l = 0; l < 8; ++l) r.v[l] = p[l];
    return r;
  }
  static Lanes Load(const std::uint16_t* p) {
    Lanes r;
    for (int l = 0; l < 8; ++l) r.v[l] = HalfToFloat(p[l]);
    return r;
  }
  void Store(float* p) const { std::copy_n(v, 8, p); }
  friend Lanes operator-(Lanes a, Lanes b) {
    for (int l = 0; l < 8; ++l) a.v[l] -= b.v[l];
    return a;
  }
  static Lanes Fma(Lanes a, Lanes b, Lanes c) {
    for (int l = 0; l < 8; ++l) c.v[l] = std::fma(a.v[l], b.v[l], c.v[l]);
    return c;
  }
  double Sum() const {
    double s = 0;
    for (float x : v) s += double(x);
    return s;
  }
};
#endif

// Values per chunk: a sweep's 8 basis rows and the mean over a chunk (18 KB) stay in L1 while
// every row of a batch passes over them.
constexpr std::size_t kChunk = 512;
constexpr std::size_t kState = 9 * 8;  // floats of a sweep's lanes: W <= 8 dot products, then the squares

// Steps [i0, i1) of one sweep for one row x: state holds the sweep's lanes between calls (dot
// product j at 8 j, the squares, if Sq, at 8 W). Each lane takes the indices = l mod 8 in index
// order, so chunking changes no sum.
template <int W, bool Sq, typename T>
void Steps(const T* x, const float* mean, const float* b, std::size_t stride, std::size_t i0, std::size_t i1, float* state) {
  Lanes acc[W + 1];
  for (int j = 0; j <= W; ++j) acc[j] = Lanes::Load(state + 8 * j);
  for (std::size_t i = i0; i < i1; i += 8) {
    const Lanes diff = Lanes::Load(x + i) - Lanes::Load(mean + i);
    if constexpr (Sq) acc[W] = Lanes::Fma(diff, diff, acc[W]);
    for (int j = 0; j < W; ++j) acc[j] = Lanes::Fma(diff, Lanes::Load(b + std::size_t(j) * stride + i), acc[j]);
  }
  for (int j = 0; j <= W; ++j) acc[j].Store(state + 8 * j);
}

template <bool Sq, typename T>
void StepsN(int w, const T* x, const float* mean, const float* b, std::size_t stride, std::size_t i0, std::size_t i1,
            float* state) {
  switch (w) {
    case 0: return Steps<0, Sq>(x, mean, b, stride, i0, i1, state);
    case 1: return Steps<1, Sq>(x, mean, b, stride, i0, i1, state);
    case 2: return Steps<2, Sq>(x, mean, b, stride, i0, i1, state);
    case 3: return Steps<3, Sq>(x, mean, b, stride, i0, i1, state);
    case 4: return Steps<4, Sq>(x, mean, b, stride, i0, i1, state);
    case 5: return Steps<5, Sq>(x, mean, b, stride, i0, i1, state);
    case 6: return Steps<6, Sq>(x, mean, b, stride, i0, i1, state);
    case 7: return Steps<7, Sq>(x, mean, b, stride, i0, i1, state);
    default: return Steps<8, Sq>(x, mean, b, stride, i0, i1, state);
  }
}

// The basis rows in sweeps of at most 8 (the first also sums the squares), over chunks of the
// values, each chunk for every row of the batch; the last d mod 8 values as one zero-padded step.
template <typename T>
void Residuals(const T* const* rows, std::size_t n, const float* mean, const float* basis, int c, std::size_t d,
               double* out) {
  BTF_CHECK(c >= 0);
  const int sweeps = std::max(1, (c + 7) / 8);
  auto width = [&](int s) { return std::min(8, c - 8 * s); };
  std::vector<float> state(n * std::size_t(sweeps) * kState, 0.0f);
  auto at = [&](std::size_t r, int s) { return state.data() + (r * std::size_t(sweeps) + std::size_t(s)) * kState; };
  const std::size_t full = d / 8 * 8;
  for (std::size_t i0 = 0; i0 < full; i0 += kChunk) {
    const std::size_t i1 = std::min(full, i0 + kChunk);
    for (int s = 0; s < sweeps; ++s)
      for (std::size_t r = 0; r < n; ++r) {
        const float* b = basis + std::size_t(8 * s) * d;
        if (s == 0) StepsN<true>(width(s), rows[r], mean, b, d, i0, i1, at(r, s));
        else StepsN<false>(width(s), rows[r], mean, b, d, i0, i1, at(r, s));
      }
  }
  if (full < d) {
    const std::size_t rest = d - full;
    float mt[8] = {}, bt[64] = {};
    std::copy_n(mean + full, rest, mt);
    for (int s = 0; s < sweeps; ++s) {
      std::fill(std::begin(bt), std::end(bt), 0.0f);
      for (int j = 0; j < width(s); ++j) std::copy_n(basis + std::size_t(8 * s + j) * d + full, rest, bt + 8 * j);
      for (std::size_t r = 0; r < n; ++r) {
        T xt[8] = {};
        std::copy_n(rows[r] + full, rest, xt);
        if (s == 0) StepsN<true>(width(s), xt, mt, bt, 8, 0, 8, at(r, s));
        else StepsN<false>(width(s), xt, mt, bt, 8, 0, 8, at(r, s));
      }
    }
  }
  for (std::size_t r = 0; r < n; ++r) {
    double projected = 0;
    for (int s = 0; s < sweeps; ++s)
      for (int j = 0; j < width(s); ++j) {
        const double dot = Lanes::Load(at(r, s) + 8 * j).Sum();
        projected += dot * dot;
      }
    out[r] = Lanes::Load(at(r, 0) + 8 * width(0)).Sum() - projected;
  }
}

}  // namespace

void SubspaceResiduals(const float* const* rows, std::size_t n, const float* mean, const float* basis, int c,
                       std::size_t d, double* out) {
  Residuals(rows, n, mean, basis, c, d, out);
}
void SubspaceResiduals(const std::uint16_t* const* rows, std::size_t n, const float* mean, const float* basis, int c,
                       std::size_t d, double* out) {
  Residuals(rows, n, mean, basis, c, d, out);
}
double SubspaceResidual(const float* x, const float* mean, const float* basis, int c, std::size_t d) {
  double r;
  Residuals(&x, 1, mean, basis, c, d, &r);
  return r;
}
double SubspaceResidual(const std::uint16_t* x, const float* mean, const float* basis, int c, std::size_t d) {
  double r;
  Residuals(&x, 1, mean, basis, c, d, &r);
  return r;
}

ReassignSketch::ReassignSketch(const std::vector<PcaResult>& clusters, std::size_t d, int per_cluster) {
  std::vector<const float*> cols;
  for (const PcaResult& p : clusters) {
    if (p.mean.size() == 0) continue;
    cols.push_back(p.mean.data());
    for (int j = 0; j < std::min(per_cluster, p.components()); ++j) cols.push_back(p.basis.row(j).data());
  }
  const Eigen::Index n = static_cast<Eigen::Index>(d), m = std::min<Eigen::Index>(Eigen::Index(cols.size()), n);
  if (m == 0) return;
  Eigen::MatrixXd M(n, Eigen::Index(cols.size()));
  for (std::size_t j = 0; j < cols.size(); ++j)
    M.col(Eigen::Index(j)) = Eigen::Map<const Eigen::VectorXf>(cols[j], n).cast<double>();
  // Q's first m columns: orthonormal, spanning M's columns (even where M is rank deficient).
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(M);
  Gd_ = (qr.householderQ() * Eigen::MatrixXd::Identity(n, m)).transpose();
  G_ = Gd_.cast<float>();
}

void ReassignSketch::Project(const Eigen::Ref<const RowMatrixXf>& X, float* g, double* e) const {
  BTF_CHECK(G_.rows() == Gd_.rows());  // not after EndProjections
  const Eigen::Index n = X.rows(), m = G_.rows();
  Eigen::Map<RowMatrixXf> gm(g, n, m);
  gm.noalias() = X * G_.transpose();
  constexpr Eigen::Index kRun = 32;  // rows of the reconstruction held at a time
  RowMatrixXf E;
  for (Eigen::Index i = 0; i < n; i += kRun) {
    const Eigen::Index w = std::min(kRun, n - i);
    E.noalias() = gm.middleRows(i, w) * G_;
    E = X.middleRows(i, w) - E;
    for (Eigen::Index r = 0; r < w; ++r) e[i + r] = std::sqrt(E.row(r).cast<double>().squaredNorm());
  }
}

void ReassignSketch::SetClusters(const std::vector<PcaResult>& clusters) {
  K_ = static_cast<int>(clusters.size());
  const Eigen::Index m = Gd_.rows();
  fitted_.assign(std::size_t(K_), 0);
  first_row_.assign(std::size_t(K_), 0);
  rows_.assign(std::size_t(K_), 0);
  int total = 0;
  for (int k = 0; k < K_; ++k) {
    const PcaResult& p = clusters[std::size_t(k)];
    fitted_[std::size_t(k)] = p.mean.size() > 0;
    first_row_[std::size_t(k)] = total;
    rows_[std::size_t(k)] = fitted_[std::size_t(k)] ? p.components() : 0;
    total += rows_[std::size_t(k)];
  }
  H_ = Eigen::MatrixXd::Zero(K_, m);
  hn_ = Eigen::VectorXd::Zero(K_);
  F_.resize(total, m);
  v_.resize(total);
  for (int k = 0; k < K_; ++k) {
    if (!fitted_[std::size_t(k)]) continue;
    const PcaResult& p = clusters[std::size_t(k)];
    const Eigen::VectorXd mean = p.mean.cast<double>();
    H_.row(k) = (Gd_ * mean).transpose();
    hn_[k] = mean.squaredNorm();
    const int r0 = first_row_[std::size_t(k)], c = rows_[std::size_t(k)];
    if (c == 0) continue;
    const Eigen::MatrixXd B = p.basis.cast<double>();
    F_.middleRows(r0, c).noalias() = B * Gd_.transpose();
    v_.segment(r0, c).noalias() = B * mean;
  }
}

void ReassignSketch::Candidates(const float* g, const double* e, const double* norm2, std::size_t n,
                                std::vector<std::vector<int>>& out) const {
  const Eigen::Index m = Gd_.rows();
  const Eigen::MatrixXd gd = Eigen::Map<const RowMatrixXf>(g, Eigen::Index(n), m).cast<double>();
  // |y - mean_k|^2 = |g|^2 - 2 g . h_k + |mean_k|^2 (y = G^T g; mean_k's part outside G adds to
  // both sides); basis_k (y - mean_k) = F_k g - v_k.
  const Eigen::MatrixXd gh = gd * H_.transpose(), gf = gd * F_.transpose();
  std::vector<double> dist(static_cast<std::size_t>(K_)), centred(static_cast<std::size_t>(K_));
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Index ii = Eigen::Index(i);
    const double gg = gd.row(ii).squaredNorm();
    const double eb = e[i] + kDistance * std::sqrt(norm2[i]);
    double ub = std::numeric_limits<double>::infinity();
    for (int k = 0; k < K_; ++k) {
      if (!fitted_[std::size_t(k)]) continue;
      const double c2 = std::max(0.0, gg - 2.0 * gh(ii, k) + hn_[k]);
      double r = c2;
      for (int j = 0; j < rows_[std::size_t(k)]; ++j) {
        const double s = gf(ii, first_row_[std::size_t(k)] + j) - v_[first_row_[std::size_t(k)] + j];
        r -= s * s;
      }
      dist[std::size_t(k)] = std::sqrt(std::max(0.0, r));
      centred[std::size_t(k)] = c2;
      ub = std::min(ub, dist[std::size_t(k)] + eb);
    }
    double ub_centred = 0;  // |y - mean|^2 of the cluster giving the smallest upper bound
    for (int k = 0, at = -1; k < K_; ++k)
      if (fitted_[std::size_t(k)] && (at < 0 || dist[std::size_t(k)] < dist[std::size_t(at)]))
        at = k, ub_centred = centred[std::size_t(k)];
    std::vector<int>& list = out[i];
    list.clear();
    for (int k = 0; k < K_; ++k) {
      if (!fitted_[std::size_t(k)]) continue;
      const double lb = std::max(0.0, dist[std::size_t(k)] - eb);
      if (lb * lb <= ub * ub + kSquared * (norm2[i] + ub_centred + centred[std::size_t(k)])) list.push_back(k);
    }
  }
}

}  // namespace btf
