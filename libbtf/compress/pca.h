#pragma once
// PCA of the rows of a float matrix (n observations x d variables), choosing the decomposition
// by shape: the Gram (n x n) or covariance (d x d) matrix of the smaller side in double, or a
// randomized range finder (Halko, Martinsson & Tropp 2011) when both sides are large.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace btf {

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct PcaRequest {
  int max_components = 16;
  double target_error = 0;     // > 0: smallest c with ||X - X'||_F / ||X||_F <= target_error
  double retained_energy = 0;  // > 0: smallest c retaining this fraction of the centered energy
  int gram_limit = 256;        // Gram/covariance path when min(n, d) <= gram_limit
  int oversampling = 10;       // randomized path: extra sketch columns
  int power_iterations = 2;    // randomized path: subspace iterations
  std::uint64_t seed = 1;
};

struct PcaResult {
  Eigen::VectorXf mean;                // d
  RowMatrixXf basis;                   // c x d, orthonormal rows, by decreasing eigenvalue
  RowMatrixXf scores;                  // n x c: (x - mean) . basis_k
  std::vector<double> eigenvalues;     // c: squared norm captured per component
  double total_energy = 0;             // sum ||x||^2 (uncentered)
  double centered_energy = 0;           // sum ||x - mean||^2
  double residual_energy = 0;          // centered_energy - captured, >= 0
  int requested = 0;                   // max_components asked for
  int clamped_to = 0;                  // the most the data allows (min(n - 1, d)), <= requested => clamped
  int dropped_null = 0;                // components dropped because their eigenvalue is ~0
  bool randomized = false;
  int components() const { return static_cast<int>(basis.rows()); }
};

// Components whose eigenvalue is below this fraction of the largest are dropped.
inline constexpr double kNullEigenvalueFraction = 1e-10;

// X must be finite (callers check). n >= 1, d >= 1.
PcaResult Pca(const Eigen::Ref<const RowMatrixXf>& X, const PcaRequest& request);

// The straightforward reference: full SVD (Eigen::BDCSVD) of the centered matrix, first c
// components, no shape-dependent choice (benchmarks and tests compare against it).
PcaResult PcaFullSvd(const Eigen::Ref<const RowMatrixXf>& X, int components);

}  // namespace btf
