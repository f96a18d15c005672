#include "libbtf/compress/pca.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

namespace btf {

namespace {

using MatrixXd = Eigen::MatrixXd;
constexpr Eigen::Index kBlock = 2048;  // columns/rows per double block (fits L2 with n <= 256)

// Mean (double accumulation) and centered copy; energies in double.
void Center(const Eigen::Ref<const RowMatrixXf>& X, PcaResult& r, RowMatrixXf& Xc) {
  const Eigen::Index n = X.rows(), d = X.cols();
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(d);
  double total = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto row = X.row(i).cast<double>();
    mean += row.transpose();
    total += row.squaredNorm();
  }
  mean /= double(n);
  r.mean = mean.cast<float>();
  r.total_energy = total;
  Xc = X.rowwise() - r.mean.transpose();
  double centered = 0;
  for (Eigen::Index i = 0; i < n; ++i) centered += Xc.row(i).cast<double>().squaredNorm();
  r.centered_energy = centered;
}

// Number of components to keep from eigenvalues sorted in decreasing order.
int ChooseComponents(const std::vector<double>& eig, const PcaRequest& q, PcaResult& r, int limit) {
  int c = std::min<int>(q.max_components, limit);
  c = std::min<int>(c, static_cast<int>(eig.size()));
  // Null components: relative to the largest, and to float rounding of the data (~1e-12 of the energy).
  const double floor = std::max(kNullEigenvalueFraction * (eig.empty() ? 0.0 : eig[0]), 1e-12 * r.total_energy);
  int kept = 0;
  while (kept < c && eig[static_cast<std::size_t>(kept)] > floor && eig[static_cast<std::size_t>(kept)] > 0) ++kept;
  r.dropped_null = c - kept;
  c = kept;
  if (q.target_error > 0 && r.total_energy > 0) {
    double residual = r.centered_energy;
    for (int k = 0; k <= c; ++k) {
      if (std::sqrt(std::max(residual, 0.0) / r.total_energy) <= q.target_error) return k;
      if (k < c) residual -= eig[static_cast<std::size_t>(k)];
    }
  } else if (q.retained_energy > 0 && r.centered_energy > 0) {
    double captured = 0;
    for (int k = 0; k < c; ++k) {
      if (captured >= q.retained_energy * r.centered_energy) return k;
      captured += eig[static_cast<std::size_t>(k)];
    }
  }
  return c;
}

// Orthonormalizes the rows of `basis` in order (Householder QR keeps the span of every prefix),
// keeping each row's sign.
void Orthonormalize(RowMatrixXf& basis) {
  const Eigen::Index c = basis.rows(), d = basis.cols();
  if (c == 0) return;
  const MatrixXd bt = basis.transpose().cast<double>();
  Eigen::HouseholderQR<MatrixXd> qr(bt);
  MatrixXd q = qr.householderQ() * MatrixXd::Identity(d, c);
  for (Eigen::Index k = 0; k < c; ++k)
    if (q.col(k).dot(bt.col(k)) < 0) q.col(k) = -q.col(k);
  basis = q.transpose().cast<float>();
}

// basis rows = (u_k^T Xc) / sqrt(lambda_k) for the top c eigenvectors U of Xc Xc^T.
void BasisFromLeft(const RowMatrixXf& Xc, const MatrixXd& U, const std::vector<double>& eig, int c,
                   PcaResult& r) {
  Eigen::MatrixXf uc(U.rows(), c);
  for (int k = 0; k < c; ++k) uc.col(k) = (U.col(k) / std::sqrt(eig[static_cast<std::size_t>(k)])).cast<float>();
  r.basis.noalias() = uc.transpose() * Xc;
  Orthonormalize(r.basis);
}

Eigen::MatrixXd Orth(const Eigen::MatrixXf& Y) {
  const MatrixXd yd = Y.cast<double>();
  Eigen::HouseholderQR<MatrixXd> qr(yd);
  return qr.householderQ() * MatrixXd::Identity(Y.rows(), Y.cols());
}

void Finish(const RowMatrixXf& Xc, PcaResult& r) {
  r.scores.noalias() = Xc * r.basis.transpose();
  double captured = 0;
  for (Eigen::Index k = 0; k < r.basis.rows(); ++k) {
    const double e = r.scores.col(k).cast<double>().squaredNorm();
    r.eigenvalues[static_cast<std::size_t>(k)] = e;
    captured += e;
  }
  r.residual_energy = std::max(0.0, r.centered_energy - captured);
}

}  // namespace

PcaResult Pca(const Eigen::Ref<const RowMatrixXf>& X, const PcaRequest& q) {
  PcaResult r;
  const Eigen::Index n = X.rows(), d = X.cols();
  RowMatrixXf Xc;
  Center(X, r, Xc);
  r.requested = q.max_components;
  // n observations span at most n - 1 centered directions.
  const int limit = static_cast<int>(std::min<Eigen::Index>(n - 1, d));
  r.clamped_to = limit;
  const Eigen::Index small = std::min(n, d);
  const int want = std::min(q.max_components, limit);
  const bool gram = small <= q.gram_limit || 2 * (want + q.oversampling) >= small;
  std::vector<double> eig;
  if (want <= 0 || r.centered_energy <= 0) {
    r.basis.resize(0, d);
    r.scores.resize(n, 0);
    r.residual_energy = r.centered_energy;
    return r;
  }
  if (gram && n <= d) {
    MatrixXd G = MatrixXd::Zero(n, n);
    for (Eigen::Index b = 0; b < d; b += kBlock) {
      const Eigen::Index w = std::min(kBlock, d - b);
      const MatrixXd block = Xc.middleCols(b, w).cast<double>();
      G.selfadjointView<Eigen::Lower>().rankUpdate(block);
    }
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(G.selfadjointView<Eigen::Lower>());
    const MatrixXd U = es.eigenvectors().rowwise().reverse();
    for (Eigen::Index k = n - 1; k >= 0; --k) eig.push_back(std::max(0.0, es.eigenvalues()[k]));
    const int c = ChooseComponents(eig, q, r, limit);
    BasisFromLeft(Xc, U, eig, c, r);
  } else if (gram) {
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
  } else {
    r.randomized = true;
    const Eigen::Index rank = std::min<Eigen::Index>(want + q.oversampling, small);
    std::mt19937_64 rng(q.seed);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    Eigen::MatrixXf omega(d, rank);
    for (Eigen::Index j = 0; j < rank; ++j)
      for (Eigen::Index i = 0; i < d; ++i) omega(i, j) = normal(rng);
    Eigen::MatrixXf Y = Xc * omega;
    MatrixXd Q = Orth(Y);
    for (int it = 0; it < q.power_iterations; ++it) {
      const Eigen::MatrixXf Z = Xc.transpose() * Q.cast<float>();
      const MatrixXd Qz = Orth(Z);
      Y.noalias() = Xc * Qz.cast<float>();
      Q = Orth(Y);
    }
    const RowMatrixXf B = Q.cast<float>().transpose() * Xc;  // rank x d
    MatrixXd G = MatrixXd::Zero(rank, rank);
    for (Eigen::Index b = 0; b < d; b += kBlock) {
      const Eigen::Index w = std::min(kBlock, d - b);
      const MatrixXd block = B.middleCols(b, w).cast<double>();
      G.selfadjointView<Eigen::Lower>().rankUpdate(block);
    }
    Eigen::SelfAdjointEigenSolver<MatrixXd> es(G.selfadjointView<Eigen::Lower>());
    const MatrixXd U = es.eigenvectors().rowwise().reverse();
    for (Eigen::Index k = rank - 1; k >= 0; --k) eig.push_back(std::max(0.0, es.eigenvalues()[k]));
    const int c = ChooseComponents(eig, q, r, limit);
    BasisFromLeft(B, U, eig, c, r);
  }
  r.eigenvalues.assign(static_cast<std::size_t>(r.basis.rows()), 0.0);
  Finish(Xc, r);
  return r;
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
  r.eigenvalues.assign(static_cast<std::size_t>(c), 0.0);
  Finish(Xc, r);
  return r;
}

}  // namespace btf
