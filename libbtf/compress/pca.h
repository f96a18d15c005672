#pragma once
// PCA of the rows of a float matrix (n observations x d variables), choosing the decomposition
// by shape: the Gram (n x n) or covariance (d x d) matrix of the smaller side in double, or a
// randomized range finder (Halko, Martinsson & Tropp 2011) when both sides are large.
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "libbtf/compress/gram_kernel.h"

namespace btf {

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

struct PcaRequest {
  int max_components = 16;
  double target_error = 0;     // > 0: smallest c with ||X - X'||_F / ||X||_F <= target_error
  double retained_energy = 0;  // > 0: smallest c retaining this fraction of the centered energy
  int gram_limit = 256;        // Gram/covariance path when min(n, d) <= gram_limit
  int oversampling = 10;       // randomized path: extra sketch columns
  // Randomized path: subspace iterations, one pass over the rows each; with the first pass (the
  // moments and X_c^T X_c Omega) and the last (X_c V, the scores), 2 + power_iterations passes.
  int power_iterations = 2;
  // Randomized path started from a previous basis (Pca's `start`): subspace iterations instead
  // of power_iterations (1: 3 passes over X instead of 4).
  int warm_power_iterations = 1;
  // Randomized path started from a previous basis: extra sketch columns instead of oversampling.
  // The start already holds about the c directions, so fewer Gaussian columns suffice: at Bonn
  // size (LPCA k = 32, c = 8) 4 instead of 10 changed the relative error by 2e-6 of itself and
  // made the full rounds 0.8x (bench/NOTES.md).
  int warm_oversampling = 4;
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
// start (optional, s x d rows, e.g. the basis of a previous fit to similar rows): a warm start
// for the randomized path (where the shape takes it; the Gram path ignores start): its test
// matrix V0 is start's rows followed by Gaussian columns up to c + warm_oversampling, with
// warm_power_iterations subspace iterations instead of power_iterations.
PcaResult Pca(const Eigen::Ref<const RowMatrixXf>& X, const PcaRequest& request, const RowMatrixXf* start = nullptr);

// The randomized path over PcaRows holds blocks of this many rows (the last one shorter), one at
// a time, in row order, once per pass; it asks for them in runs of a few rows.
inline constexpr Eigen::Index kPcaBlockRows = 128;

// An n x d matrix (rows x cols) whose rows get(first, count, out) writes as float to out
// (count x d, row-major): e.g. gathered from a larger matrix, converted from half. Optionally
// get_columns(c0, w, out, stride) writes columns [c0, c0 + w) of every row (n x w, row stride
// `stride`), for the Gram path to read a tile of columns at a time. Optionally `block`: room for
// kPcaBlockRows x cols floats, where the randomized path reads its blocks (a caller's buffer,
// reused over many calls), else it allocates its own.
struct PcaRows {
  using Columns = std::function<void(Eigen::Index c0, Eigen::Index w, float* out, Eigen::Index stride)>;
  Eigen::Index rows = 0, cols = 0;
  std::function<void(Eigen::Index first, Eigen::Index count, float* out)> get;
  Columns get_columns;
  float* block = nullptr;
};

// The same result as Pca on the matrix the rows make up, holding what each path needs: the
// Gram path (n <= d, n <= gram_limit or barely above the sketch's c + oversampling) is WidePca's
// (below), over tiles of kWideTile columns with get_columns, else over all rows at once as float;
// the covariance path (d < n, d small) all rows at once; the randomized path one block of
// kPcaBlockRows rows, its sketches (n x (c + oversampling) and d x (c + oversampling)) and the
// scores, never the n x d matrix.
PcaResult Pca(const PcaRows& X, const PcaRequest& request, const RowMatrixXf* start = nullptr);

// The straightforward reference: full SVD (Eigen::BDCSVD) of the centered matrix, first c
// components, no shape-dependent choice (benchmarks and tests compare against it).
PcaResult PcaFullSvd(const Eigen::Ref<const RowMatrixXf>& X, int components);

// Per-view PCA's shape: few observations (n, the lights) of many variables (d, the texel values),
// X row-major n x d with row stride d, decomposed in column tiles of kWideTile without a copy:
//   pass 1, per tile: finiteness check, column means (double; the float-rounded mean is the one
//     stored and used to centre), centring in double, Gram G += Tc Tc^T (double, LaneGram: its
//     summation order is fixed by the column index alone);
//   eigenpairs (lambda_k, u_k) of G, components chosen as in Pca;
//   pass 2, per tile: basis rows b_k = u_k^T Tc / sqrt(lambda_k) in double (BasisProduct), rounded to float (or
//     half-representable floats), weights U Lambda^(1/2) (= the projections Xc b_k^T in exact
//     arithmetic), and, if `sink` is set, the tile's reconstruction handed to it (for errors).
// Signs: each basis row's largest-magnitude entry (first in index order on ties) is positive,
// its weight column flipped with it. Results depend neither on the thread nor on the kernels'
// instruction set. request.gram_limit, oversampling and power_iterations are not used (always the Gram).
inline constexpr Eigen::Index kWideTile = 256;

struct WidePcaResult {
  int components = 0;
  std::vector<float> mean;          // d
  std::vector<float> basis;         // c x d, orthonormal rows, by decreasing eigenvalue
  std::vector<float> weights;       // n x c
  std::vector<double> eigenvalues;  // c: squared norm captured per component (lambda_k)
  double total_energy = 0, centered_energy = 0, residual_energy = 0;
  int clamped_to = 0, dropped_null = 0;
  // Index (row * d + column) of a NaN/Inf (the first found, tile by tile); then nothing else is set.
  std::int64_t non_finite = -1;
};

// Receives the reconstruction mean + weights * basis of columns [col0, col0 + tile.cols()).
using TileSink = std::function<void(Eigen::Index col0, const Eigen::Ref<const RowMatrixXf>& tile)>;

// half: mean, basis and weights rounded to IEEE half (stored as floats), before the
// reconstruction the sink sees.
// isa: the double kernels' instruction set (gram_kernel.h; every choice gives the same bits).
WidePcaResult WidePca(const float* X, Eigen::Index n, Eigen::Index d, const PcaRequest& request, bool half = false,
                      const TileSink& sink = {}, KernelIsa isa = KernelIsa::kAuto);

// Flips the sign of basis row k (and of its scores/weights column k) so that the row's
// largest-magnitude entry, the first one on ties, is positive.
void NormalizeSigns(float* basis, Eigen::Index c, Eigen::Index d, float* weights, Eigen::Index n);

// Rounds to the nearest IEEE half value (ties to even), kept as a float.
float RoundToHalf(float x);

}  // namespace btf
