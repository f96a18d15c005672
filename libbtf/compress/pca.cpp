#include "libbtf/compress/pca.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "libbtf/compress/gram_kernel.h"
#include "libbtf/core/error.h"
#include "libbtf/io/half.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

namespace btf {

namespace {

using MatrixXd = Eigen::MatrixXd;
constexpr Eigen::Index kBlock = 2048;  // columns/rows per double block (fits L2 with n <= 256)

// Adds X's rows to `sum` and their squared norms to `total` (double). The rows are taken in runs
// of kRun: each column's sum is loaded once per run and the run's values added to it row by row
// (so `sum` is the row-by-row sum in row order); the squares go to 4 x 4 double accumulators
// (row mod 4, column mod 4), added to `total` per run. The result depends only on X. (Row by row,
// the column sums crossed L2 once per row: bench/NOTES.md.)
void AddMoments(const Eigen::Ref<const RowMatrixXf>& X, Eigen::VectorXd& sum, double& total) {
  constexpr Eigen::Index kRun = 8;
  const Eigen::Index d = X.cols();
  double* s = sum.data();
  for (Eigen::Index i = 0; i < X.rows(); i += kRun) {
    const Eigen::Index m = std::min(kRun, X.rows() - i);
    const float* r[kRun];
    for (Eigen::Index k = 0; k < m; ++k) r[k] = X.row(i + k).data();
    double lanes[4][4] = {};
    Eigen::Index j = 0;
    for (; j + 4 <= d; j += 4) {
      double a0 = s[j], a1 = s[j + 1], a2 = s[j + 2], a3 = s[j + 3];
      for (Eigen::Index k = 0; k < m; ++k) {
        const double v0 = r[k][j], v1 = r[k][j + 1], v2 = r[k][j + 2], v3 = r[k][j + 3];
        a0 += v0, a1 += v1, a2 += v2, a3 += v3;
        double* q = lanes[k & 3];
        q[0] += v0 * v0, q[1] += v1 * v1, q[2] += v2 * v2, q[3] += v3 * v3;
      }
      s[j] = a0, s[j + 1] = a1, s[j + 2] = a2, s[j + 3] = a3;
    }
    double t = 0;
    for (; j < d; ++j)
      for (Eigen::Index k = 0; k < m; ++k) {
        const double v = r[k][j];
        s[j] += v;
        t += v * v;
      }
    for (const auto& q : lanes) t += (q[0] + q[1]) + (q[2] + q[3]);
    total += t;
  }
}

// Mean (double accumulation) and total energy of X's rows.
void Moments(const Eigen::Ref<const RowMatrixXf>& X, PcaResult& r) {
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(X.cols());
  r.total_energy = 0;
  AddMoments(X, sum, r.total_energy);
  r.mean = (sum / double(X.rows())).cast<float>();
}

// Xc = X - mean, row by row (Xc may be X: centred in place); returns the centred energy (double),
// each row's norm taken while it is in cache.
double CentreRows(const Eigen::Ref<const RowMatrixXf>& X, const Eigen::VectorXf& mean, RowMatrixXf& Xc) {
  if (Xc.data() != X.data()) Xc.resize(X.rows(), X.cols());
  double centered = 0;
  for (Eigen::Index i = 0; i < X.rows(); ++i) {
    Xc.row(i) = X.row(i) - mean.transpose();
    centered += Xc.row(i).cast<double>().squaredNorm();
  }
  return centered;
}

// Mean and centred copy; energies in double.
void Center(const Eigen::Ref<const RowMatrixXf>& X, PcaResult& r, RowMatrixXf& Xc) {
  Moments(X, r);
  r.centered_energy = CentreRows(X, r.mean, Xc);
}

// Number of components to keep from eigenvalues sorted in decreasing order.
int ChooseComponents(const std::vector<double>& eig, const PcaRequest& q, double total_energy, double centered_energy,
                     int limit, int* dropped_null) {
  int c = std::min<int>(q.max_components, limit);
  c = std::min<int>(c, static_cast<int>(eig.size()));
  // Null components: relative to the largest, and to float rounding of the data (~1e-12 of the energy).
  const double floor = std::max(kNullEigenvalueFraction * (eig.empty() ? 0.0 : eig[0]), 1e-12 * total_energy);
  int kept = 0;
  while (kept < c && eig[static_cast<std::size_t>(kept)] > floor && eig[static_cast<std::size_t>(kept)] > 0) ++kept;
  *dropped_null = c - kept;
  c = kept;
  if (q.target_error > 0 && total_energy > 0) {
    double residual = centered_energy;
    for (int k = 0; k <= c; ++k) {
      if (std::sqrt(std::max(residual, 0.0) / total_energy) <= q.target_error) return k;
      if (k < c) residual -= eig[static_cast<std::size_t>(k)];
    }
  } else if (q.retained_energy > 0 && centered_energy > 0) {
    double captured = 0;
    for (int k = 0; k < c; ++k) {
      if (captured >= q.retained_energy * centered_energy) return k;
      captured += eig[static_cast<std::size_t>(k)];
    }
  }
  return c;
}
int ChooseComponents(const std::vector<double>& eig, const PcaRequest& q, PcaResult& r, int limit) {
  return ChooseComponents(eig, q, r.total_energy, r.centered_energy, limit, &r.dropped_null);
}

// An orthonormal basis (Householder QR, in double) of Y's columns; Y is overwritten (the QR in place).
MatrixXd Orth(MatrixXd& Y) {
  const Eigen::HouseholderQR<Eigen::Ref<MatrixXd>> qr(Y);
  return qr.householderQ() * MatrixXd::Identity(Y.rows(), Y.cols());
}

// r.eigenvalues from r.scores (n x c: the centred rows times the basis), the residual, the signs.
void FinishScores(PcaResult& r) {
  r.eigenvalues.assign(static_cast<std::size_t>(r.basis.rows()), 0.0);
  double captured = 0;
  for (Eigen::Index k = 0; k < r.basis.rows(); ++k) {
    const double e = r.scores.col(k).cast<double>().squaredNorm();
    r.eigenvalues[static_cast<std::size_t>(k)] = e;
    captured += e;
  }
  r.residual_energy = std::max(0.0, r.centered_energy - captured);
  NormalizeSigns(r.basis.data(), r.basis.rows(), r.basis.cols(), r.scores.data(), r.scores.rows());
}

void Finish(const RowMatrixXf& Xc, PcaResult& r) {
  r.scores.noalias() = Xc * r.basis.transpose();
  FinishScores(r);
}

// No components: the mean alone.
PcaResult NoComponents(PcaResult r, Eigen::Index n, Eigen::Index d) {
  r.basis.resize(0, d);
  r.scores.resize(n, 0);
  r.residual_energy = r.centered_energy;
  return r;
}

// The covariance path (n > d) on the centred rows Xc; r holds the mean and energies.
PcaResult CovariancePca(const RowMatrixXf& Xc, PcaResult r, const PcaRequest& q, int limit) {
  const Eigen::Index n = Xc.rows(), d = Xc.cols();
  if (std::min(q.max_components, limit) <= 0 || r.centered_energy <= 0) return NoComponents(std::move(r), n, d);
  std::vector<double> eig;
  MatrixXd C = MatrixXd::Zero(d, d);
  for (Eigen::Index b = 0; b < n; b += kBlock) {
    const Eigen::Index w = std::min(kBlock, n - b);
    const MatrixXd block = Xc.middleRows(b, w).cast<double>().transpose();
    C.selfadjointView<Eigen::Lower>().rankUpdate(block);
  }
  Eigen::SelfAdjointEigenSolver<MatrixXd> es(C.selfadjointView<Eigen::Lower>());
  for (Eigen::Index k = d - 1; k >= 0; --k) eig.push_back(std::max(0.0, es.eigenvalues()[k]));
  const int c = ChooseComponents(eig, q, r, limit);
  r.basis.resize(c, d);
  for (int k = 0; k < c; ++k) r.basis.row(k) = es.eigenvectors().col(d - 1 - k).cast<float>().transpose();
  Finish(Xc, r);
  return r;
}

// The randomized path over X's rows in blocks of kPcaBlockRows (one block held at a time), in
// 2 + iterations passes, each computing, block by block, Y_b = X_b V and (all but the last)
// Z += X_b^T Y_b, i.e. Z = X^T X V (the span of X^T Q for Q = orth(Y), one subspace iteration
// per pass):
//   pass 1: rows shifted by the first block's mean m0 (not yet the mean), the moments; with the
//     mean known, Z is corrected to the centred rows' Xc^T Xc Omega (a rank-two update in double);
//   passes 2 ..: the centred rows Xc, V = orth(Z);
//   the last: Y = Xc V alone; the basis is the best of span(V) (the eigenvectors W of Y^T Y,
//     basis^T = V W) and the scores are Y W, no further pass.
// After i iterations the basis lies in span((Xc^T Xc)^(i + 1) Omega), as with the two passes per
// iteration, B = Q^T Xc and the scores' pass of before (8 passes cold, 6 warm).
PcaResult RandomizedPca(const PcaRows& X, PcaResult r, const PcaRequest& q, const RowMatrixXf* start, int limit) {
  const Eigen::Index n = X.rows, d = X.cols;
  constexpr Eigen::Index kRun = 8;  // rows read and shifted together, while they are in L2
  std::vector<float> own(X.block ? 0 : std::size_t(std::min(kPcaBlockRows, n) * d));
  float* const block = X.block ? X.block : own.data();
  Eigen::RowVectorXf shift;  // subtracted from every row read: empty until the first block is in
  // f(first, T) for each block of rows [first, first + T.rows()), shifted as they are read.
  auto pass = [&](auto&& f) {
    for (Eigen::Index b = 0; b < n; b += kPcaBlockRows) {
      Eigen::Map<RowMatrixXf> T(block, std::min(kPcaBlockRows, n - b), d);
      const bool shifted = shift.size() == d;
      for (Eigen::Index i = 0; i < T.rows(); i += kRun) {
        const Eigen::Index m = std::min(kRun, T.rows() - i);
        X.get(b + i, m, T.row(i).data());
        if (shifted) T.middleRows(i, m).rowwise() -= shift;
      }
      if (!shifted) {  // the first block: its mean (in double) is m0
        Eigen::RowVectorXd sum = Eigen::RowVectorXd::Zero(d);
        for (Eigen::Index i = 0; i < T.rows(); ++i) sum += T.row(i).cast<double>();
        shift = (sum / double(T.rows())).cast<float>();
        T.rowwise() -= shift;
      }
      f(b, T);
    }
  };
  r.randomized = true;
  const int want = std::min(q.max_components, limit);
  const bool warm = start && start->rows() > 0 && start->cols() == d;
  const Eigen::Index rank = std::min<Eigen::Index>(want + (warm ? q.warm_oversampling : q.oversampling), std::min(n, d));
  std::mt19937_64 rng(q.seed);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  Eigen::MatrixXf V(d, rank);
  const Eigen::Index warm_cols = warm ? std::min(start->rows(), rank) : 0;
  if (warm_cols > 0) V.leftCols(warm_cols) = start->topRows(warm_cols).transpose();
  for (Eigen::Index j = warm_cols; j < rank; ++j)
    for (Eigen::Index i = 0; i < d; ++i) V(i, j) = normal(rng);
  Eigen::MatrixXf Yb(kPcaBlockRows, rank), Z = Eigen::MatrixXf::Zero(d, rank);
  auto sketch = [&](Eigen::Index, const auto& x) {
    auto y = Yb.topRows(x.rows());
    y.noalias() = x * V;
    Z.noalias() += x.transpose() * y;
  };
  // Pass 1: rows x0 = x - m0; s0 = sum x0 and e0 = sum ||x0||^2 in double.
  Eigen::VectorXd s0 = Eigen::VectorXd::Zero(d);
  double e0 = 0;
  pass([&](Eigen::Index b, const auto& x0) {
    AddMoments(x0, s0, e0);
    if (want > 0) sketch(b, x0);
  });
  const Eigen::VectorXd m0 = shift.transpose().cast<double>();
  r.mean = (m0 + s0 / double(n)).cast<float>();
  // With delta = mean - m0 (exact in double), Xc = X0 - 1 delta^T:
  //   sum ||x||^2 = e0 + 2 m0.s0 + n |m0|^2,  sum ||xc||^2 = e0 - 2 delta.s0 + n |delta|^2,
  //   Xc^T Xc V = X0^T X0 V - s0 (V^T delta)^T - delta (V^T s0 - n V^T delta)^T.
  // Cancellation is mild: X0 is centred up to the first block's sampling error.
  const Eigen::VectorXd delta = r.mean.cast<double>() - m0;
  r.total_energy = e0 + 2 * m0.dot(s0) + double(n) * m0.squaredNorm();
  r.centered_energy = std::max(0.0, e0 - 2 * delta.dot(s0) + double(n) * delta.squaredNorm());
  if (want <= 0 || r.centered_energy <= 0) {
    r.randomized = false;
    return NoComponents(std::move(r), n, d);
  }
  Eigen::VectorXd u(rank), v(rank);  // V^T delta, V^T s0 (no double copy of V)
  for (Eigen::Index j = 0; j < rank; ++j)
    u[j] = V.col(j).cast<double>().dot(delta), v[j] = V.col(j).cast<double>().dot(s0);
  MatrixXd Zd = Z.cast<double>() - s0 * u.transpose() - delta * (v - double(n) * u).transpose();
  shift = r.mean.transpose();
  for (int it = 0; it < (warm ? q.warm_power_iterations : q.power_iterations); ++it) {
    V = Orth(Zd).cast<float>();
    Z.setZero();
    pass(sketch);
    Zd = Z.cast<double>();
  }
  V = Orth(Zd).cast<float>();
  Z.resize(0, 0), Zd.resize(0, 0);
  Eigen::MatrixXf Y(n, rank);
  pass([&](Eigen::Index b, const auto& xc) { Y.middleRows(b, xc.rows()).noalias() = xc * V; });
  // Rayleigh-Ritz in span(V): Y^T Y = W Lambda W^T (double); basis^T = V W, scores = Y W.
  const MatrixXd Y64 = Y.cast<double>();
  Eigen::SelfAdjointEigenSolver<MatrixXd> es(Y64.transpose() * Y64);
  const MatrixXd W = es.eigenvectors().rowwise().reverse();
  std::vector<double> eig;
  for (Eigen::Index k = rank - 1; k >= 0; --k) eig.push_back(std::max(0.0, es.eigenvalues()[k]));
  const int c = ChooseComponents(eig, q, r, limit);
  r.basis = (V.cast<double>() * W.leftCols(c)).transpose().cast<float>();
  r.scores = (Y64 * W.leftCols(c)).cast<float>();
  FinishScores(r);
  return r;
}

}  // namespace

namespace {

// Where WidePcaOf reads X's rows, a tile of columns at a time: Load(c0, w), then Row(i) points at
// row i's values in columns [c0, c0 + w). In memory (row stride d, read in place), or written by
// a PcaRows' get_columns into a buffer of one tile.
class WideTiles {
 public:
  WideTiles(const float* X, Eigen::Index d) : X_(X), stride_(d) {}
  WideTiles(const PcaRows& rows)
      : get_(&rows.get_columns), buffer_(std::size_t(rows.rows) * kWideTile), stride_(kWideTile) {}
  void Load(Eigen::Index c0, Eigen::Index w) {
    c0_ = c0;
    if (get_) (*get_)(c0, w, buffer_.data(), kWideTile);
  }
  const float* Row(Eigen::Index i) const { return get_ ? buffer_.data() + i * stride_ : X_ + i * stride_ + c0_; }

 private:
  const float* X_ = nullptr;
  const PcaRows::Columns* get_ = nullptr;
  std::vector<float> buffer_;
  Eigen::Index stride_, c0_ = 0;
};

// Tiles are row-major (n x w) like X, so loading and centring one reads X's rows contiguously
// (vectorised), and the kernels (gram_kernel.h) take rows of them; a tile's width is padded with
// zero columns to a multiple of 8, which change no sum.
WidePcaResult WidePcaOf(WideTiles& X, Eigen::Index n, Eigen::Index d, const PcaRequest& q, bool half,
                        const TileSink& sink, KernelIsa isa) {
  using TileD = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  WidePcaResult r;
  r.mean.resize(static_cast<std::size_t>(d));
  LaneGram gram(n, isa);
  TileD T = TileD::Zero(n, kWideTile);
  auto padded = [](Eigen::Index w) { return (w + 7) / 8 * 8; };
  std::vector<double> colsum(static_cast<std::size_t>(kWideTile)), colsq(static_cast<std::size_t>(kWideTile));
  // Loads columns [c0, c0 + w) centred by the stored (float) mean into T; with `sq`, adds each
  // column's centred sum of squares to sq[j] (per column: no serial chain across the tile).
  auto load_centred = [&](Eigen::Index c0, Eigen::Index w, double* sq) {
    const float* m = r.mean.data() + c0;
    for (Eigen::Index i = 0; i < n; ++i) {
      const float* row = X.Row(i);
      double* t = T.row(i).data();
      for (Eigen::Index j = 0; j < w; ++j) t[j] = double(row[j]) - double(m[j]);
      std::fill(t + w, t + padded(w), 0.0);
      if (sq)
        for (Eigen::Index j = 0; j < w; ++j) sq[j] += t[j] * t[j];
    }
  };
  // Pass 1: check, mean, centre, Gram; energies in double. Sums per column (no serial chain
  // across the tile, so the loops vectorise), added to the totals in column order.
  double total = 0, centred = 0;
  for (Eigen::Index c0 = 0; c0 < d; c0 += kWideTile) {
    const Eigen::Index w = std::min(kWideTile, d - c0);
    std::fill(colsum.begin(), colsum.end(), 0.0);
    std::fill(colsq.begin(), colsq.end(), 0.0);
    X.Load(c0, w);
    for (Eigen::Index i = 0; i < n; ++i) {
      const float* row = X.Row(i);
      for (Eigen::Index j = 0; j < w; ++j) {
        const double x = row[j];
        colsum[static_cast<std::size_t>(j)] += x;
        colsq[static_cast<std::size_t>(j)] += x * x;
      }
    }
    // A NaN or Inf makes its column's sum of squares non-finite (squares of finite floats cannot
    // overflow a double); then the first non-finite value in row order is located.
    double tile_sq = 0;
    for (Eigen::Index j = 0; j < w; ++j) tile_sq += colsq[static_cast<std::size_t>(j)];
    if (!std::isfinite(tile_sq)) {
      for (Eigen::Index i = 0; i < n; ++i)
        for (Eigen::Index j = 0; j < w; ++j)
          if (!std::isfinite(X.Row(i)[j])) {
            r.non_finite = std::int64_t(i * d + c0 + j);
            return r;
          }
    }
    total += tile_sq;
    for (Eigen::Index j = 0; j < w; ++j) {
      float m = static_cast<float>(colsum[static_cast<std::size_t>(j)] / double(n));
      r.mean[static_cast<std::size_t>(c0 + j)] = half ? RoundToHalf(m) : m;
    }
    std::fill(colsq.begin(), colsq.end(), 0.0);
    load_centred(c0, w, colsq.data());
    for (Eigen::Index j = 0; j < w; ++j) centred += colsq[static_cast<std::size_t>(j)];
    gram.Add(T.data(), kWideTile, padded(w));
  }
  r.total_energy = total;
  r.centered_energy = centred;
  // n observations span at most n - 1 centred directions.
  const int limit = static_cast<int>(std::min<Eigen::Index>(n - 1, d));
  r.clamped_to = limit;
  int c = 0;
  MatrixXd U;
  if (std::min(q.max_components, limit) > 0 && centred > 0) {
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(gram.Reduce());
    U = es.eigenvectors().rowwise().reverse();
    for (Eigen::Index k = n - 1; k >= 0; --k) r.eigenvalues.push_back(std::max(0.0, es.eigenvalues()[k]));
    c = ChooseComponents(r.eigenvalues, q, total, centred, limit, &r.dropped_null);
  }
  r.eigenvalues.resize(static_cast<std::size_t>(c));
  r.components = c;
  double captured = 0;
  for (double e : r.eigenvalues) captured += e;
  r.residual_energy = std::max(0.0, centred - captured);
  // Weights U Lambda^(1/2); S = Lambda^(-1/2) U^T maps a centred tile to basis rows.
  TileD S(c, n);
  RowMatrixXf W(n, c);
  for (int k = 0; k < c; ++k) {
    const double s = std::sqrt(r.eigenvalues[static_cast<std::size_t>(k)]);
    S.row(k) = U.col(k).transpose() / s;
    for (Eigen::Index l = 0; l < n; ++l) {
      const float x = static_cast<float>(U(l, k) * s);
      W(l, k) = half ? RoundToHalf(x) : x;
    }
  }
  r.basis.resize(static_cast<std::size_t>(c) * static_cast<std::size_t>(d));
  // Pass 2: basis rows and (for the sink) the reconstruction, tile by tile.
  const Eigen::Map<const Eigen::RowVectorXf> mean(r.mean.data(), d);
  TileD Bd(c, kWideTile);
  RowMatrixXf Bf(c, kWideTile), R(n, kWideTile);
  Eigen::Map<RowMatrixXf> basis(r.basis.data(), c, d);
  for (Eigen::Index c0 = 0; c0 < d && (c > 0 || sink); c0 += kWideTile) {
    const Eigen::Index w = std::min(kWideTile, d - c0);
    if (c > 0) {
      X.Load(c0, w);
      load_centred(c0, w, nullptr);
      BasisProduct(S.data(), c, n, T.data(), kWideTile, padded(w), Bd.data(), kWideTile, gram.isa());
      Bf.leftCols(w) = Bd.leftCols(w).cast<float>();
      if (half)
        for (int k = 0; k < c; ++k) RoundToHalves(Bf.row(k).data(), static_cast<std::size_t>(w));
      basis.middleCols(c0, w) = Bf.leftCols(w);
    }
    if (!sink) continue;
    if (c > 0)
      R.leftCols(w).noalias() = W * Bf.leftCols(w);
    else
      R.leftCols(w).setZero();
    R.leftCols(w).rowwise() += mean.segment(c0, w);
    sink(c0, R.leftCols(w));
  }
  r.weights.assign(W.data(), W.data() + W.size());
  NormalizeSigns(r.basis.data(), c, d, r.weights.data(), n);
  return r;
}

}  // namespace

PcaResult Pca(const PcaRows& X, const PcaRequest& q, const RowMatrixXf* start) {
  const Eigen::Index n = X.rows, d = X.cols;
  PcaResult r;
  r.requested = q.max_components;
  // n observations span at most n - 1 centered directions.
  const int limit = static_cast<int>(std::min<Eigen::Index>(n - 1, d));
  r.clamped_to = limit;
  const Eigen::Index small = std::min(n, d);
  const int want = std::min(q.max_components, limit);
  if (!(small <= q.gram_limit || 2 * (want + q.oversampling) >= small))
    return RandomizedPca(X, std::move(r), q, start, limit);
  if (n > d) {  // d <= gram_limit (or barely above the sketch): all rows at once
    RowMatrixXf Xc(n, d);
    X.get(0, n, Xc.data());
    Center(Xc, r, Xc);  // in place
    return CovariancePca(Xc, std::move(r), q, limit);
  }
  // The Gram path is WidePca's: by column tiles where the rows give them, else on all rows at once.
  WidePcaResult w;
  if (X.get_columns) {
    WideTiles tiles(X);
    w = WidePcaOf(tiles, n, d, q, false, {}, KernelIsa::kAuto);
  } else {
    RowMatrixXf A(n, d);
    X.get(0, n, A.data());
    WideTiles tiles(A.data(), d);
    w = WidePcaOf(tiles, n, d, q, false, {}, KernelIsa::kAuto);
  }
  BTF_CHECK(w.non_finite < 0);  // callers check that X is finite
  const Eigen::Index c = w.components;
  r.mean = Eigen::Map<const Eigen::VectorXf>(w.mean.data(), d);
  r.basis = Eigen::Map<const RowMatrixXf>(w.basis.data(), c, d);
  r.scores = Eigen::Map<const RowMatrixXf>(w.weights.data(), n, c);
  r.eigenvalues = std::move(w.eigenvalues);
  r.total_energy = w.total_energy;
  r.centered_energy = w.centered_energy;
  r.residual_energy = w.residual_energy;
  r.dropped_null = w.dropped_null;
  return r;
}

PcaResult Pca(const Eigen::Ref<const RowMatrixXf>& X, const PcaRequest& q, const RowMatrixXf* start) {
  const PcaRows rows{X.rows(), X.cols(),
                     [&](Eigen::Index first, Eigen::Index count, float* out) {
                       Eigen::Map<RowMatrixXf>(out, count, X.cols()) = X.middleRows(first, count);
                     },
                     [&](Eigen::Index c0, Eigen::Index w, float* out, Eigen::Index stride) {
                       for (Eigen::Index i = 0; i < X.rows(); ++i)
                         std::copy_n(X.row(i).data() + c0, w, out + i * stride);
                     }};
  return Pca(rows, q, start);
}

PcaResult PcaFullSvd(const Eigen::Ref<const RowMatrixXf>& X, int components) {
  PcaResult r;
  RowMatrixXf Xc;
  Center(X, r, Xc);
  r.requested = components;
  const Eigen::MatrixXf xc = Xc;
  Eigen::BDCSVD<Eigen::MatrixXf> svd(xc, Eigen::ComputeThinV);
  const int c = static_cast<int>(std::min<Eigen::Index>(components, svd.nonzeroSingularValues()));
  r.clamped_to = c;
  r.basis = svd.matrixV().leftCols(c).transpose();
  Finish(Xc, r);
  return r;
}

float RoundToHalf(float x) { return HalfToFloat(FloatToHalf(x)); }

void NormalizeSigns(float* basis, Eigen::Index c, Eigen::Index d, float* weights, Eigen::Index n) {
  for (Eigen::Index k = 0; k < c; ++k) {
    const float* row = basis + k * d;
    if (d == 0) continue;
    // The largest magnitude (vectorised), then the first entry that has it.
    const float best = Eigen::Map<const Eigen::ArrayXf>(row, d).abs().maxCoeff();
    Eigen::Index arg = 0;
    while (arg + 1 < d && std::abs(row[arg]) != best) ++arg;
    if (!(row[arg] < 0)) continue;
    for (Eigen::Index i = 0; i < d; ++i) basis[k * d + i] = -basis[k * d + i];
    for (Eigen::Index l = 0; l < n; ++l) weights[l * c + k] = -weights[l * c + k];
  }
}

WidePcaResult WidePca(const float* X, Eigen::Index n, Eigen::Index d, const PcaRequest& q, bool half,
                      const TileSink& sink, KernelIsa isa) {
  WideTiles tiles(X, d);
  return WidePcaOf(tiles, n, d, q, half, sink, isa);
}

}  // namespace btf
