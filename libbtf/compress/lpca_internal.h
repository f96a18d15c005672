#pragma once
// Local PCA (Mueller et al. 2003 as in Schneider 2004 section 3): k-means++ seeding, then rounds
// of per-cluster PCA and reassignment of every texel to the cluster that reconstructs it best.
// LPCA's phases and what they share; lpca.cpp drives them: LpcaRows (lpca_rows.cpp) holds and
// reads the texel-major matrix, LpcaSampler (lpca_sample.cpp) clusters a sample of it,
// LpcaFitter (lpca_fit.cpp) fits and reassigns every texel and stores the codec's model.
//
// Distributed (docs/scaling.md): rank r owns a contiguous range of whole kRows texel blocks and
// reads, holds and reassigns only those texels; vectors of one value per texel (assignment,
// residual, norm) are shared by every rank. The k-means sample's rows are gathered on rank 0,
// which seeds and runs Lloyd as one process would and broadcasts the centers. Per round, each
// cluster's member rows are gathered in texel order on the rank that fits it, its PCA is
// computed there exactly as in one process and broadcast. Every sum keeps its single-process
// order, and every GEMM block its rows, so the codec is bit-identical for any number of ranks.
#include <algorithm>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include <omp.h>

#include "libbtf/compress/lpca_reassign.h"
#include "libbtf/compress/method.h"
#include "libbtf/core/error.h"
#include "libbtf/core/memory.h"
#include "libbtf/io/half.h"

namespace btf::lpca {

inline constexpr std::size_t kRows = 256;  // texels per GEMM block (assignment, reassignment)
inline constexpr std::size_t kTile = 64;   // texels per transpose tile (LpcaRows::ReadRows)
// Texels per sketch projection GEMM (a part of a kRows block: the float rows it converts are a
// thread's largest buffer, 5 MB at the Bonn size's d = 19683, not 20).
inline constexpr std::size_t kProjectRows = 64;
// The reassignment sketch's span: each cluster's mean and its first basis row. On the 64^2
// twill (k = 32, c = 8): 4.2 / 2.2 / 1.35 clusters compared per texel with 0 / 1 / 3 rows, for a
// sketch of 32 / 64 / 128 dimensions (its cost, once: two GEMMs of that width).
inline constexpr int kSketchBasisRows = 1;

// One PageBuffer (core/memory.h) per thread of the OpenMP team that a parallel region started
// by the constructing thread gets: Get() from inside the region returns the calling thread's.
class ThreadPageBuffers {
 public:
  ThreadPageBuffers() : buffers_(std::size_t(std::max(1, omp_get_max_threads()))) {}
  template <typename T>
  T* Get(std::size_t n) {
    const std::size_t t = std::size_t(omp_get_thread_num());
    BTF_CHECK(t < buffers_.size());
    return buffers_[t].Get<T>(n);
  }

 private:
  std::vector<PageBuffer> buffers_;
};

class TexelMatrix {
 public:
  using HalfMatrix = Eigen::Matrix<Eigen::half, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  // Allocated with huge-page advice (core/memory.h): the read writes it all at once.
  void Resize(std::size_t rows, std::size_t cols, bool half) {
    Clear();
    half_ = half;
    if (half_) h_.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
    else f_.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
    AdviseHugePages(half_ ? static_cast<void*>(h_.data()) : static_cast<void*>(f_.data()), rows * cols * (half_ ? 2 : 4));
  }
  void Clear() { f_.resize(0, 0), h_.resize(0, 0); }
  std::size_t cols() const { return std::size_t(half_ ? h_.cols() : f_.cols()); }
  // Row i's storage, to fill: float values, or half bits (half.h).
  float* FloatRow(std::size_t i) { return f_.row(static_cast<Eigen::Index>(i)).data(); }
  std::uint16_t* HalfRow(std::size_t i) { return reinterpret_cast<std::uint16_t*>(h_.row(static_cast<Eigen::Index>(i)).data()); }
  // out[0, cols()) = row i, as float.
  void CopyRow(std::size_t i, float* out) const { CopyRows(i, 1, out); }
  // out[0, w) = row i's columns [c0, c0 + w), as float.
  void CopyRowPart(std::size_t i, std::size_t c0, std::size_t w, float* out) const { CopyValues(i * cols() + c0, w, out); }
  // X = rows [first, first + count), as float, in the calling thread's scratch buffer.
  Eigen::Map<RowMatrixXf> Rows(std::size_t first, std::size_t count, ThreadPageBuffers& scratch) const {
    Eigen::Map<RowMatrixXf> X(scratch.Get<float>(count * cols()), static_cast<Eigen::Index>(count),
                              static_cast<Eigen::Index>(cols()));
    CopyRows(first, count, X.data());
    return X;
  }
  template <typename F>
  decltype(auto) Visit(F&& f) const { return half_ ? f(h_) : f(f_); }

 private:
  void CopyRows(std::size_t first, std::size_t count, float* out) const { CopyValues(first * cols(), count * cols(), out); }
  // out[0, n) = the n values from row-major index `at`, as float.
  void CopyValues(std::size_t at, std::size_t n, float* out) const {
    if (half_) HalvesToFloats(reinterpret_cast<const std::uint16_t*>(h_.data()) + at, out, n);
    else std::copy_n(f_.data() + at, n, out);
  }

  bool half_ = true;
  RowMatrixXf f_;
  HalfMatrix h_;
};

// out[0, w) = M(i, c0 .. c0 + w) as float (the texel matrix in half: F16C, half.h).
template <typename Mat>
void RowToFloat(const Mat& M, Eigen::Index i, float* out, Eigen::Index c0 = 0, Eigen::Index w = -1) {
  if (w < 0) w = M.cols();
  if constexpr (std::is_same_v<Mat, TexelMatrix::HalfMatrix>)
    HalvesToFloats(reinterpret_cast<const std::uint16_t*>(M.row(i).data()) + c0, out, std::size_t(w));
  else
    std::copy_n(M.row(i).data() + c0, w, out);
}

struct ClusterFit {
  std::vector<PcaResult> pca;           // per cluster
  std::vector<std::int32_t> assign;     // per texel (sample rounds: per sample texel)
  double error = 0;                     // relative error (transformed domain)
  std::vector<std::vector<std::size_t>> members;  // per cluster, in order (the rows each PCA was fitted on)
};

// A reassignment sketch (lpca_reassign.h) with, per row it was built for, the row's coordinates
// g (rows x dims, row-major) and residual e.
struct Sketch {
  ReassignSketch bounds;
  std::vector<float> g;
  std::vector<double> e;
  Sketch() = default;
  Sketch(const std::vector<PcaResult>& pca, std::size_t d, std::size_t rows)
      : bounds(pca, d, kSketchBasisRows), g(rows * std::size_t(bounds.dims())), e(rows) {}
  std::size_t dims() const { return std::size_t(bounds.dims()); }
  // Rows [first, first + X.rows()) from their values X.
  void Project(const Eigen::Ref<const RowMatrixXf>& X, std::size_t first) {
    bounds.Project(X, g.data() + first * dims(), e.data() + first);
  }
  // Candidates of rows [first, first + count) (norm2: their squared norms).
  void Candidates(std::size_t first, std::size_t count, const double* norm2, std::vector<std::vector<int>>& out) const {
    bounds.Candidates(g.data() + first * dims(), e.data() + first, norm2, count, out);
  }
};

// Members of each of K clusters (texel indices in order) under `assign`. An empty cluster takes
// the worst-fitted texel (largest residual; without residuals the first) of a cluster that can
// spare one, and `assign` is updated.
std::vector<std::vector<std::size_t>> MembersFillingEmpty(std::vector<std::int32_t>& assign, int K,
                                                          const double* residual);

// The clusters with a model (a mean), in increasing order.
std::vector<int> Fitted(const std::vector<PcaResult>& pca);

// The basis that starts cluster k's PCA (warm: per cluster, the previous model), or none
// (enabled false: LpcaOptions::warm_start off).
const RowMatrixXf* WarmStart(bool enabled, const std::vector<PcaResult>* warm, int k);

// A cluster's PCA as bytes: the model every rank needs, and the member scores for the codec.
std::vector<std::uint8_t> PackPca(const PcaResult& p);
PcaResult UnpackPca(const std::vector<std::uint8_t>& bytes);

// Runs f(first, count) over [0, m) in static blocks of kRows (the last one shorter), each
// block on one thread with Eigen single-threaded: which thread takes a block changes nothing
// in its result, so results do not depend on the thread count.
template <typename F>
inline void ForBlocks(std::size_t m, F&& f) {
  const std::ptrdiff_t blocks = static_cast<std::ptrdiff_t>((m + kRows - 1) / kRows);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t b = 0; b < blocks; ++b) {
    omp_set_num_threads(1);  // this thread's own setting: Eigen stays sequential here
    const std::size_t first = std::size_t(b) * kRows;
    f(first, std::min<std::size_t>(kRows, m - first));
  }
}

// X = the rows rows[first, first + count) of M, gathered as float into the calling thread's
// scratch buffer.
template <typename Mat>
inline Eigen::Map<RowMatrixXf> GatheredRows(const Mat& M, const std::size_t* rows, std::size_t first, std::size_t count,
                                            ThreadPageBuffers& scratch) {
  Eigen::Map<RowMatrixXf> X(scratch.Get<float>(count * std::size_t(M.cols())), static_cast<Eigen::Index>(count),
                            M.cols());
  for (Eigen::Index i = 0; i < X.rows(); ++i) RowToFloat(M, static_cast<Eigen::Index>(rows[first + std::size_t(i)]), X.row(i).data());
  return X;
}

// P = X right^T for X = GatheredRows (one ForBlocks block: the GEMM of a block does not depend
// on the thread that runs it).
template <typename Mat>
inline Eigen::MatrixXf GatheredProducts(const Mat& M, const std::size_t* rows, std::size_t first, std::size_t count,
                                        const RowMatrixXf& right, ThreadPageBuffers& scratch) {
  return GatheredRows(M, rows, first, count, scratch) * right.transpose();
}

// Each of `count` rows of M (row i: M's row at_row(i)) to the cluster that reconstructs it best
// (SubspaceResiduals), among `fitted` or, with candidates, among candidates[i]; the lowest index
// on ties; a row keeps its cluster if it compares none. Per row: assign and residual updated,
// changed (0/1) and compared (clusters) set. Per cluster, the rows that compare it are one batch.
template <typename Mat, typename AtRow>
inline void BestClusters(const Mat& M, AtRow at_row, std::size_t count, const std::vector<PcaResult>& pca,
                         const std::vector<int>& fitted, const std::vector<std::vector<int>>* candidates,
                         std::int32_t* assign, double* residual, std::uint8_t* changed, std::uint32_t* compared) {
  using Row = std::conditional_t<std::is_same_v<Mat, TexelMatrix::HalfMatrix>, std::uint16_t, float>;
  std::vector<std::vector<std::size_t>> batch(pca.size());
  for (std::size_t i = 0; i < count; ++i) {
    const std::vector<int>& list = candidates ? (*candidates)[i] : fitted;
    for (int k : list) batch[std::size_t(k)].push_back(i);
    if (compared) compared[i] = std::uint32_t(list.size());
  }
  std::vector<double> best(count, std::numeric_limits<double>::infinity()), r;
  std::vector<std::int32_t> arg(assign, assign + count);
  std::vector<const Row*> rows;
  for (std::size_t k = 0; k < pca.size(); ++k) {
    const std::vector<std::size_t>& list = batch[k];
    if (list.empty()) continue;
    rows.clear();
    for (std::size_t i : list) rows.push_back(reinterpret_cast<const Row*>(M.row(at_row(i)).data()));
    r.resize(list.size());
    const PcaResult& p = pca[k];
    SubspaceResiduals(rows.data(), rows.size(), p.mean.data(), p.basis.data(), p.components(), std::size_t(M.cols()),
                      r.data());
    for (std::size_t j = 0; j < list.size(); ++j)
      if (r[j] < best[list[j]]) best[list[j]] = r[j], arg[list[j]] = std::int32_t(k);
  }
  for (std::size_t i = 0; i < count; ++i) {
    residual[i] = std::max(best[i], 0.0);
    changed[i] = arg[i] != assign[i];
    assign[i] = arg[i];
  }
}

// What every phase reads: the input, the options, the summary it reports to, the ranks, and the
// shape (N texels, d = V L C values per texel).
struct LpcaSetup {
  const MethodContext& ctx;
  CompressSummary& sum;
  std::size_t N, d;
};

class LpcaPhase {
 protected:
  explicit LpcaPhase(const LpcaSetup& s)
      : in_(s.ctx.input), o_(s.ctx.options), tr_(s.ctx.transform), rep_(s.ctx.reporter), ranks_(s.ctx.ranks),
        ctx_(s.ctx), sum_(s.sum), N_(s.N), d_(s.d), R_(s.ctx.ranks.size()), rank_(s.ctx.ranks.rank()) {}
  void Warn(const std::string& w) const { ctx_.Warn(sum_, w); }

  const SlotSource& in_;
  const CompressOptions& o_;
  const ValueMap& tr_;
  const Reporter& rep_;
  const dist::Context& ranks_;
  const MethodContext& ctx_;
  CompressSummary& sum_;
  const std::size_t N_, d_;
  const int R_, rank_;  // ranks, this rank
};

// This rank's texels' rows of the texel-major matrix (in core), or one chunk of them at a time
// (out of core), read from the view slots; every texel's squared norm.
class LpcaRows : public LpcaPhase {
 public:
  explicit LpcaRows(const LpcaSetup& s);

  // First texel of rank r's range (whole blocks, ranges contiguous in rank order).
  std::size_t TexelBegin(int r) const;

  std::size_t local() const { return t1_ - t0_; }

  bool half() const { return o_.lpca.matrix == "half"; }

  double value_bytes() const { return half() ? 2.0 : 4.0; }  // of the texel matrix

  // One pass over the view slots: rows[i] (d values: float, or half bits) gets texel texels[i]'s
  // transformed ABRDF; with a half matrix, float rows get the half-rounded values, so that the
  // rows gathered out of core equal the in-core matrix's. Per slot, one parallel pass over tiles
  // of kTile texels does the rest, each tile on one thread: for each light, the tile's values
  // (one contiguous run of the slot where the tile's texels are consecutive, else gathered) are
  // converted to half (F16C) and range-checked in the thread's buffers and placed in its stage,
  // the tile's rows for this view (kTile x L x C values); then each row's part of the stage is
  // copied out in one piece (contiguous writes of the matrix, not C values per row and light).
  // norms (optional): norms[i] = the squared norm of row i as stored (half-rounded with a half
  // matrix), summed in double in (view, light, channel) order by the thread that writes the row,
  // so without a pass of its own over the matrix.
  template <typename T>
  void ReadRows(const std::vector<std::size_t>& texels, const std::vector<T*>& rows, double* norms = nullptr) const;

  // Whether x becomes an infinity in half (NaN, Inf, or |x| rounding past kHalfMax: |x| >= 65520).
  static bool BeyondHalf(float x) { return !(std::fabs(x) < 65520.0f); }

  // The first read of a half matrix measures, over whole slots (the same on every rank), the
  // energy of the transformed values below half's normal range (|x| < 2^-14): stored as
  // subnormals or flushed to zero, they keep only an absolute precision of 2^-25. Where they hold
  // more than kUnderflowShare of the energy (a relative L2 rounding error up to its square root,
  // 1e-3, against 2^-11 for normal values; a dataset scaled to 1e-30 would be stored as zeros),
  // ReadRows throws HalfUnderflow and the LPCA runs again on a float matrix.
  static constexpr double kUnderflowShare = 1e-6;
  struct HalfUnderflow {
    double share;  // of the energy below half's normal range
  };

  // Throws for the first value of slot v (in slot order) beyond the half range: a NaN or Inf as
  // CheckFiniteSlot refuses it, another value naming it (every rank reads whole slots: all refuse).
  [[noreturn]] void RefuseBeyondHalf(int v, const float* slot) const;

  // A = the rows of texels [t0_, t1_) (one pass); chunk_norms_ their squared norms.
  void LoadRows();

  // Runs f() with A_ holding the rows of texels [t0_, t1_): in core once (A_ holds this rank's
  // texels); out of core once per chunk of chunk_ texels (whole kRows blocks, so every GEMM block
  // has the in-core rows), one pass over the slots each.
  template <typename F>
  void ForChunks(F&& f) {
    if (!ooc_) return f();
    for (std::size_t first = 0; first < N_; first += chunk_) {
      t0_ = first, t1_ = std::min(N_, first + chunk_);
      LoadRows();
      f();
    }
    A_.Clear();
    t0_ = 0, t1_ = N_;
  }

  void SetNorms(const std::vector<double>& all);

  // Texel-major matrix A (this rank's texels x d, row = one texel's ABRDF), transformed; texel
  // norms (of every texel, on every rank).
  void ReadTexelMajor();

  // Out of core: the rows of the sample texels, in sample order (one pass).
  RowMatrixXf ReadSampleRows(const std::vector<std::size_t>& sample) const;

  // The rows of the sample texels, in sample order, on rank 0 (the sample is sorted and the
  // ranks' ranges contiguous: each rank's sample rows are one run of the sample).
  RowMatrixXf GatherSampleRows(const std::vector<std::size_t>& sample) const;

  // Out of core: X[k] = the member rows (texel order) of clusters list[first, last), one pass.
  void ReadClusterRows(const std::vector<std::vector<std::size_t>>& members, const std::vector<int>& list,
                       std::size_t first, std::size_t last, std::vector<RowMatrixXf>& X) const;

  // Whether this rank holds any of these (sorted) texels.
  bool OwnsAny(const std::vector<std::size_t>& texels) const;

  std::size_t t0_, t1_;              // this rank's texels [t0_, t1_) (out of core: the chunk in A_)
  bool ooc_ = false;                 // out of core: A_ holds one chunk of chunk_ texels at a time
  double budget_ = 0;                // out of core: bytes of one chunk or one wave of cluster rows
  std::size_t chunk_ = 0;
  std::vector<double> chunk_norms_;  // squared norms of A_'s rows
  TexelMatrix A_;                    // this rank's texels' rows
  Eigen::VectorXd norms_;            // every texel's squared norm
  double total_ = 0;                 // their sum
};

// The sample's principal subspace (LpcaOptions::subspace): the PCA of some of the sample's rows
// (mean mu, basis W: r x d, orthonormal rows) and each sample row's coordinates
// z = W (x - mu). A cluster model (mean m, basis E) in those coordinates is the model mu + W^T m,
// E W of the full rows, and a row's squared residual under it is the coordinates' residual plus
// ||x - mu||^2 - ||z||^2, the row's energy outside the subspace, the same under every such model.
struct SampleSubspace {
  PcaResult pca;              // mu and W (no scores)
  RowMatrixXf Z;              // S x r, in sample order
  std::vector<double> norms;  // ||z||^2 per sample row
  double outside = 0;         // the sample's energy outside the subspace (each row's clamped at 0)
  double energy = 0;          // the sample's energy, sum ||x||^2
  // A model fitted to rows of Z as the model of the full rows (an empty cluster's stays empty).
  PcaResult Lift(const PcaResult& p) const;
};

// k-means and local-PCA rounds on a sample of the texels (rows of a matrix M: the texel matrix
// in core, the gathered sample rows otherwise, or a SampleSubspace's coordinates), run by one
// rank. Instantiated for both matrices.
class LpcaSampler : public LpcaPhase {
 public:
  LpcaSampler(const LpcaSetup& s, int clusters) : LpcaPhase(s), K_(clusters) {}

  // The subspace of `dims` dimensions of the sample rows `rows` of M (norms: of M's rows): a
  // Gram-path PCA (single-threaded: the same bits for any thread count) of n = min(S, 2 dims)
  // sample rows drawn with the seed; the coordinates in static blocks of kRows.
  template <typename Mat>
  SampleSubspace Subspace(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, int dims) const;

  // A sampler of a subspace's coordinates: the sample's errors count the energy outside it and
  // are relative to the full rows' energy.
  void SetOutside(double outside, double energy) { outside_ = outside, energy_ = energy; }

  // Deterministic sample of max(lpca_sample, K) texels (sorted; all texels if fewer), drawn with the seed.
  std::vector<std::size_t> Sample(std::mt19937_64& rng) const;

  // The sample rounds' reassignment sketch (o_.lpca.prune): built from the first fit of Lloyd's
  // clusters, with the sample texels' coordinates (sample order) and residuals.
  template <typename Mat>
  Sketch MakeSampleSketch(const Mat& M, const std::vector<std::size_t>& rows, const std::vector<PcaResult>& pca) const;

  // Local-PCA rounds on the sample (rows `rows` of M, norms of M's rows), from Lloyd's
  // assignment `assign` of the sample texels: per-cluster PCA of the sample members, then every
  // sample texel to the cluster that reconstructs it best, until nothing moves, a round improves
  // the sample's relative error by less than min_improvement or max_iterations rounds. Then at
  // most lpca_splits split/merge trials (ProposeSplitMerge, then rounds from there), each kept
  // if it lowers the sample's error, until one does not lower it by min_improvement (relative).
  // errors: the sample's relative error after each fit of the first rounds (the first from
  // Lloyd's clusters); split_errors: after each trial's rounds. Returns the best fit's models
  // (mean and basis; the scores are dropped).
  template <typename Mat>
  std::vector<PcaResult> SampleRounds(const Mat& M, const double* norms, const std::vector<std::size_t>& rows,
                                      std::vector<std::int32_t> assign, std::vector<double>& errors,
                                      std::vector<double>& split_errors) const;

  // SampleRounds' rounds from the fitted fit (kept: the best); errors (if given): the sample's
  // error after each fit.
  template <typename Mat>
  void RoundsOnSample(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, double energy,
                      std::vector<double>& residual, ClusterFit& fit, std::vector<double>* errors,
                      Sketch& sketch) const;

  // A split/merge proposal from the sample fit f (its models and members): the cluster j with
  // the largest residual energy is split at its mean along its first component (the members
  // scoring above 0 leave it), and the cluster k != j whose removal costs least (summed over its
  // members: the squared residual under the best other cluster minus that under k) is emptied
  // into those other clusters and takes j's leaving members. assign: the proposal's sample
  // assignment. False (no proposal) when j has no component or one side of the split is empty.
  template <typename Mat>
  bool ProposeSplitMerge(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, const ClusterFit& f,
                         std::vector<std::int32_t>& assign) const;

  // FitClusters on the sample (f.assign: per sample texel, members: sample positions); residual:
  // per sample texel after the last reassignment, empty before the first (then empty clusters
  // take the first sample texels of clusters that can spare one).
  template <typename Mat>
  void FitSample(const Mat& M, const std::vector<std::size_t>& rows, double energy,
                 const std::vector<double>& residual, ClusterFit& f, const ClusterFit* prev) const;

  // Reassign on the sample: each sample texel (rows `rows` of M) to the cluster whose model
  // reconstructs it best (BestClusters, with the sketch's candidates unless it is empty), in
  // static blocks of kRows sample texels; returns the number moved.
  template <typename Mat>
  std::size_t ReassignSample(const Mat& M, const double* norms, const std::vector<std::size_t>& rows,
                             const std::vector<PcaResult>& pca, std::vector<std::int32_t>& assign,
                             std::vector<double>& residual, Sketch& sketch) const;

  // Seeds and Lloyd rounds on the rows `sample` of M (norms: of M's rows); returns the rounds.
  // assign: the sample texels' nearest centers.
  template <typename Mat>
  int Lloyd(const Mat& M, const double* norms, const std::vector<std::size_t>& sample, std::mt19937_64& rng,
            std::vector<std::int32_t>& assign) const;

  // Lloyd's update: each center the mean of its sample texels (double, in sample order, columns
  // split statically); an empty cluster takes the farthest sample texel of a cluster that can
  // spare one.
  template <typename Mat>
  void UpdateMeans(const Mat& M, const std::vector<std::size_t>& sample, std::vector<std::int32_t>& assign,
                   const std::vector<double>& dist, RowMatrixXf& centers) const;

  // k-means++ seeds (D^2 sampling) on the sample.
  template <typename Mat>
  RowMatrixXf SeedCenters(const Mat& M, const std::vector<std::size_t>& sample, std::mt19937_64& rng) const;

 private:
  static constexpr int kLloydRounds = 100;         // k-means rounds at most
  static constexpr double kLloydTolerance = 1e-5;  // stop when the objective improves by less (relative)
  const int K_;
  double outside_ = 0, energy_ = -1;  // SetOutside; energy_ < 0: the sample's energy from the norms
};

// Per-cluster PCA and reassignment rounds over every texel, and the codec's model.
class LpcaFitter : public LpcaPhase {
 public:
  LpcaFitter(const LpcaSetup& s, LpcaRows& rows, int clusters)
      : LpcaPhase(s), rows_(rows), K_(clusters), residual_(s.N, 0.0) {}

  // Per-cluster PCA on the current assignment; empty clusters re-seeded from the worst texels. A
  // cluster whose members are those it had in `prev` takes prev's PCA (the same rows in the same
  // order: its fit), moved, not copied: those clusters are returned, for Iterate to move back
  // where the new fit is not better. warm (with o_.lpca.warm_start): per cluster, the model whose basis starts its PCA (Pca's
  // `start`; none where it has no components); release_warm: each freed once its cluster is fitted.
  std::vector<int> FitClusters(ClusterFit& f, bool have_residuals, ClusterFit* prev, std::vector<PcaResult>* warm,
                               bool release_warm = false);

  // Reassigns each texel to the cluster that reconstructs it best (the lowest index on ties; a
  // texel keeps its cluster if none is fitted); returns the number moved. Each texel's residual
  // is computed (SubspaceResidual, from its stored row) under every cluster, or with
  // o_.lpca.prune under the candidates of the sketch's bounds (lpca_reassign.h; the sketch is
  // built at the first reassignment, from its models, with each texel's sketch coordinates),
  // which always hold the best: the same assignment either way.
  std::size_t Reassign(const std::vector<PcaResult>& pca, std::vector<std::int32_t>& assign);

  // PCA/reassignment rounds until nothing moves, the error stops improving or max_iterations.
  void Iterate(ClusterFit& fit);

  // Codec arrays; the stride is the largest component count any cluster kept.
  void StoreModel(const ClusterFit& fit, Codec& codec);

 private:
  // Which rank fits which cluster, and in which waves (FitClusters).
  struct WavePlan {
    std::vector<int> owner;               // per cluster: the rank that fits it
    std::vector<std::vector<int>> owned;  // per rank: its clusters to fit, largest first
    std::size_t wave = 0, waves = 0;      // clusters per rank and wave; waves
    std::vector<std::size_t> wave_end;    // one past wave w's last index in this rank's list
  };
  WavePlan PlanWaves(const std::vector<std::vector<std::size_t>>& members, const std::vector<int>& order_k) const;
  // Distributed: the member rows of wave w's clusters that other ranks hold, into X on the
  // clusters' owners.
  void GatherWaveRows(const WavePlan& p, const std::vector<std::vector<std::size_t>>& members, std::size_t w,
                      std::vector<RowMatrixXf>& X) const;
  // The PCA of this rank's clusters of wave w into f.pca.
  void FitWave(const WavePlan& p, const std::vector<std::vector<std::size_t>>& members, std::size_t w,
               std::vector<PcaResult>* warm, bool release_warm, std::vector<RowMatrixXf>& X, ClusterFit& f) const;

  LpcaRows& rows_;
  const int K_;
  std::vector<double> residual_;  // every texel's squared residual under its cluster (after Reassign)
  // The reassignment's sketch (o_.lpca.prune): built at the first reassignment, with every
  // texel's row (on each rank only its own texels' are set).
  Sketch sketch_;
};

// The energies of an LPCA run, in the transformed domain: of the input, and of the kept fit's
// residual.
struct LpcaEnergies {
  double total = 0, residual = 0;
};

// LPCA of the context's input into the codec's lpca model; with measure, the summary's errors of
// the codec too (lpca-tensor measures its own codec instead).
LpcaEnergies RunLpca(const MethodContext& ctx, Codec& codec, CompressSummary& sum, bool measure);

}  // namespace btf::lpca
