#pragma once
// LPCA's reassignment without the all-clusters GEMM: every texel is compared with the clusters
// that can still reconstruct it best, found from bounds on a low-dimensional sketch, and its
// residual under each of those is computed by a kernel whose result does not depend on what else
// is computed (so pruning never changes the chosen cluster, and the result is the same for any
// grouping of texels into blocks, threads, chunks or ranks).
//
// Sketch (Build): G, m orthonormal rows (m <= d) spanning the clusters' means and their first
// `per_cluster` basis rows (Householder QR in double). For a row x: g = G x (float GEMM) and e =
// |x - G^T g| (the sketch's residual, summed in double). For y = G^T g and cluster k's affine
// subspace S_k = mean_k + span(basis_k), dist(y, S_k) is exact from m-dimensional quantities, and
// by the triangle inequality
//     dist(y, S_k) - e  <=  dist(x, S_k)  <=  dist(y, S_k) + e.
// Candidates (Candidates): the clusters whose lower bound is at most the smallest upper bound,
// with margins above the rounding of g, e and of the residuals compared (kDistance, kSquared):
// the best cluster is always among them.
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "libbtf/compress/pca.h"

namespace btf {

// Squared residual of row x (d values) under mean + span(basis rows): sum (x - mean)^2 minus
// sum_j ((x - mean) . basis_j)^2 over the c rows of basis (c x d, row-major; orthonormal rows
// make it the squared distance to the affine subspace). Each sum is accumulated in 8 float lanes
// (lane l takes the values at indices = l mod 8, in index order, with fused multiply-adds), the
// lanes added in double in lane order: the same value for the same inputs, whatever the caller
// computes around it. x as float, or as IEEE half bits (converted exactly).
double SubspaceResidual(const float* x, const float* mean, const float* basis, int c, std::size_t d);
double SubspaceResidual(const std::uint16_t* x, const float* mean, const float* basis, int c, std::size_t d);
// out[r] = SubspaceResidual(rows[r], ...) for n rows, the same values: the rows pass over the
// cluster's values in chunks together, so that the mean and basis are read from cache, not from
// memory, once per row.
void SubspaceResiduals(const float* const* rows, std::size_t n, const float* mean, const float* basis, int c,
                       std::size_t d, double* out);
void SubspaceResiduals(const std::uint16_t* const* rows, std::size_t n, const float* mean, const float* basis, int c,
                       std::size_t d, double* out);

class ReassignSketch {
 public:
  // Margins of the comparison. kDistance |x| widens e: it covers the rounding of g, of e and of
  // G's float copy (a few 1e-7 |x|). kSquared (|x|^2 + |y - mean_j|^2 + |y - mean_k|^2), j the
  // cluster of the smallest upper bound, is added to that bound, squared, before cluster k's lower
  // bound, squared, is compared with it: it covers the rounding of the squared residuals that
  // SubspaceResidual computes for j and k (8 float lanes of about d / 8 terms each: about 3e-6 of
  // |x - mean|^2 for d = 19683), so a pruned cluster's computed residual exceeds j's.
  static constexpr double kDistance = 1e-6, kSquared = 1e-5;

  ReassignSketch() = default;
  // clusters[k]: cluster k's model (mean and basis; an empty mean: an empty cluster, never a
  // candidate); per_cluster: basis rows of each cluster that enter the span with its mean.
  ReassignSketch(const std::vector<PcaResult>& clusters, std::size_t d, int per_cluster);
  bool empty() const { return Gd_.rows() == 0; }
  Eigen::Index dims() const { return Gd_.rows(); }

  // For rows X (float, row-major n x d): g (n x m, row-major) and e (n). Not after EndProjections.
  void Project(const Eigen::Ref<const RowMatrixXf>& X, float* g, double* e) const;
  // Frees what only Project uses (G's float copy), once every row is projected.
  void EndProjections() { G_.resize(0, 0); }

  // The cluster models the bounds refer to (recomputed per reassignment: they change every round;
  // G does not). Empty clusters get no bound.
  void SetClusters(const std::vector<PcaResult>& clusters);

  // Candidates for n rows with sketch coordinates g (n x m), sketch residuals e and squared norms
  // norm2 (of x): out[i] lists, in increasing order, the clusters whose lower bound is at most
  // the smallest upper bound (plus the margins). Empty when no cluster is fitted.
  void Candidates(const float* g, const double* e, const double* norm2, std::size_t n,
                  std::vector<std::vector<int>>& out) const;

 private:
  Eigen::MatrixXd Gd_;  // m x d, orthonormal rows
  RowMatrixXf G_;       // the same, float (Project's GEMMs)
  // Per fitted cluster (SetClusters): H (K x m) rows G mean_k, hn_k = |G mean_k|^2 + |mean_k
  // outside G|^2, F (rows: the fitted clusters' basis rows times G^T) and v = basis mean_k.
  int K_ = 0;
  std::vector<int> fitted_, first_row_, rows_;  // per cluster: fitted?, its first row in F, its rows
  Eigen::MatrixXd H_, F_;
  Eigen::VectorXd hn_, v_;
};

}  // namespace btf
