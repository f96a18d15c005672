// LPCA's clustering of a sample of the texels (lpca_internal.h, LpcaSampler).
#include <algorithm>
#include <cmath>
#include <numeric>

#include "libbtf/compress/lpca_internal.h"
#include "libbtf/core/error.h"

namespace btf::lpca {

namespace {


// The split/merge proposals' model of every cluster: one GEMM row per cluster mean, then c rows
// per cluster basis (zero where a cluster has fewer components); the mean norms and mean-basis
// products in double. (The reassignments compare clusters with BestClusters.)
struct AllClustersModel {
  int K = 0, c = 0;
  RowMatrixXf big;
  Eigen::VectorXd mnorm;
  Eigen::MatrixXd me;
  std::vector<int> ck;  // components per cluster, -1 for a cluster still empty

  AllClustersModel(const std::vector<PcaResult>& pca, int components, std::size_t d)
      : K(static_cast<int>(pca.size())), c(components) {
    big = RowMatrixXf::Zero(Eigen::Index(K) * (c + 1), static_cast<Eigen::Index>(d));
    mnorm = Eigen::VectorXd::Zero(K);
    ck.assign(static_cast<std::size_t>(K), -1);
    for (int k = 0; k < K; ++k) {
      const PcaResult& p = pca[static_cast<std::size_t>(k)];
      if (p.mean.size() == 0) continue;  // still empty
      ck[static_cast<std::size_t>(k)] = p.components();
      big.row(k) = p.mean.transpose();
      mnorm[k] = p.mean.cast<double>().squaredNorm();
      for (int j = 0; j < p.components(); ++j) big.row(K + Eigen::Index(k) * c + j) = p.basis.row(j);
    }
    // m_k . e_kj
    me = Eigen::MatrixXd::Zero(K, std::max(c, 1));
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < std::max(ck[static_cast<std::size_t>(k)], 0); ++j)
        me(k, j) = big.row(k).cast<double>().dot(big.row(K + Eigen::Index(k) * c + j).cast<double>());
  }

  // Row i of P (= a texel's row times big^T; norm: its squared norm): its score on cluster k's
  // component j, and its squared residual under cluster k (infinity where k is still empty).
  double Score(const Eigen::MatrixXf& P, Eigen::Index i, int k, int j) const {
    return double(P(i, K + Eigen::Index(k) * c + j)) - me(k, j);
  }
  double Residual(const Eigen::MatrixXf& P, Eigen::Index i, double norm, int k) const {
    if (ck[static_cast<std::size_t>(k)] < 0) return std::numeric_limits<double>::infinity();
    double r = norm - 2.0 * P(i, k) + mnorm[k];
    for (int j = 0; j < ck[static_cast<std::size_t>(k)]; ++j) {
      const double proj = Score(P, i, k, j);
      r -= proj * proj;
    }
    return r;
  }
};

// LPCA's texel-major matrix (texels x d, a row = one texel's transformed ABRDF), held as IEEE half
// (--lpca-matrix half: 2 bytes a value) or float. Consumers convert rows to float where they use
// them: blocks of rows for the GEMMs, single rows for gathers; Visit hands the matrix itself to

// For rows rows[0..m) of M: the nearest center (squared Euclidean distance, the lower index
// on ties) and that distance (norms: of M's rows).
template <typename Mat>
void NearestCenters(const Mat& M, const double* norms, const RowMatrixXf& centers,
                           const std::size_t* rows, std::size_t m, std::int32_t* assign, double* dist) {
  const Eigen::VectorXd cn = centers.cast<double>().rowwise().squaredNorm();
  ThreadPageBuffers scratch;
  ForBlocks(m, [&](std::size_t first, std::size_t count) {
    const Eigen::Index w = static_cast<Eigen::Index>(count);
    const Eigen::MatrixXf P = GatheredProducts(M, rows, first, count, centers, scratch);
    for (Eigen::Index i = 0; i < w; ++i) {
      const std::size_t t = rows[first + std::size_t(i)];
      double best = std::numeric_limits<double>::infinity();
      int arg = 0;
      for (Eigen::Index k = 0; k < centers.rows(); ++k) {
        const double e = cn[k] - 2.0 * double(P(i, k));
        if (e < best) best = e, arg = static_cast<int>(k);
      }
      assign[first + std::size_t(i)] = arg;
      dist[first + std::size_t(i)] = std::max(0.0, best + norms[t]);
    }
  });
}

}  // namespace

PcaResult SampleSubspace::Lift(const PcaResult& p) const {
  PcaResult f = p;
  f.scores.resize(0, 0);
  if (p.mean.size() == 0) return f;
  f.mean = pca.mean + pca.basis.transpose() * p.mean;
  f.basis = p.basis * pca.basis;
  return f;
}

template <typename Mat>
SampleSubspace LpcaSampler::Subspace(const Mat& M, const double* norms, const std::vector<std::size_t>& rows,
                                     int dims) const {
  const std::size_t S = rows.size(), n = std::min(S, 2 * std::size_t(dims));
  const Eigen::Index d = static_cast<Eigen::Index>(d_);
  SampleSubspace s;
  // A random subset (a strided one would alias with a weave's period), in sample order.
  std::vector<std::size_t> pick(S);
  std::iota(pick.begin(), pick.end(), std::size_t(0));
  std::mt19937_64 rng(o_.seed);
  std::shuffle(pick.begin(), pick.end(), rng);
  pick.resize(n);
  std::sort(pick.begin(), pick.end());
  WidePcaResult w;
  ThreadPageBuffers scratch;  // the picked rows here, then each thread's block of rows
  {
    std::vector<std::size_t> picked(n);
    for (std::size_t i = 0; i < n; ++i) picked[i] = rows[pick[i]];
    const auto X = GatheredRows(M, picked.data(), 0, n, scratch);
    PcaRequest q;
    q.max_components = dims;
    w = WidePca(X.data(), X.rows(), d, q);
  }
  const Eigen::Index r = w.components;
  s.pca.mean = Eigen::Map<const Eigen::VectorXf>(w.mean.data(), d);
  s.pca.basis = Eigen::Map<const RowMatrixXf>(w.basis.data(), r, d);
  s.pca.eigenvalues = w.eigenvalues;
  // Per block: P = X [W; mu]^T in one GEMM, z = P W-part - W mu, ||x - mu||^2 = ||x||^2 - 2 x.mu + ||mu||^2.
  RowMatrixXf right(r + 1, d);
  right.topRows(r) = s.pca.basis;
  right.row(r) = s.pca.mean.transpose();
  const Eigen::VectorXf wmu = (s.pca.basis.cast<double>() * s.pca.mean.cast<double>()).cast<float>();
  const double mu2 = s.pca.mean.cast<double>().squaredNorm();
  s.Z.resize(static_cast<Eigen::Index>(S), r);
  s.norms.resize(S);
  std::vector<double> outside(S);
  ForBlocks(S, [&](std::size_t first, std::size_t count) {
    const Eigen::MatrixXf P = GatheredProducts(M, rows.data(), first, count, right, scratch);
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      const std::size_t j = first + std::size_t(i);
      auto z = s.Z.row(static_cast<Eigen::Index>(j));
      z = P.row(i).head(r) - wmu.transpose();
      s.norms[j] = z.cast<double>().squaredNorm();
      outside[j] = std::max(0.0, norms[rows[j]] - 2.0 * double(P(i, r)) + mu2 - s.norms[j]);
    }
  });
  for (std::size_t i = 0; i < S; ++i) s.outside += outside[i], s.energy += norms[rows[i]];
  return s;
}

std::vector<std::size_t> LpcaSampler::Sample(std::mt19937_64& rng) const {
  std::vector<std::size_t> sample(N_);
  std::iota(sample.begin(), sample.end(), std::size_t(0));
  const std::size_t size = std::max<std::size_t>(std::size_t(o_.lpca.sample), std::size_t(K_));
  if (N_ > size) {
    std::shuffle(sample.begin(), sample.end(), rng);
    sample.resize(size);
    std::sort(sample.begin(), sample.end());
  }
  return sample;
}

template <typename Mat>
Sketch LpcaSampler::MakeSampleSketch(const Mat& M, const std::vector<std::size_t>& rows, const std::vector<PcaResult>& pca) const {
  Sketch s(pca, d_, rows.size());
  if (s.bounds.empty()) return s;
  ThreadPageBuffers scratch;
  ForBlocks(rows.size(), [&](std::size_t first, std::size_t count) {
    for (std::size_t i = 0; i < count; i += kProjectRows)
      s.Project(GatheredRows(M, rows.data(), first + i, std::min(kProjectRows, count - i), scratch), first + i);
  });
  return s;
}

template <typename Mat>
std::vector<PcaResult> LpcaSampler::SampleRounds(const Mat& M, const double* norms, const std::vector<std::size_t>& rows,
                                    std::vector<std::int32_t> assign, std::vector<double>& errors,
                                    std::vector<double>& split_errors) const {
  // Progress: the first rounds, then each split/merge trial (the bar ends early when they stop).
  const std::size_t steps = std::size_t(o_.lpca.splits) + 1;
  rep_.Progress(0, steps, "sample rounds");
  double energy = energy_;
  if (energy < 0) {
    energy = 0;
    for (std::size_t t : rows) energy += norms[t];
  }
  std::vector<double> residual;
  ClusterFit fit{{}, std::move(assign), 0, {}};
  FitSample(M, rows, energy, residual, fit, nullptr);
  errors.push_back(fit.error);
  Sketch sketch;
  if (o_.lpca.prune) sketch = MakeSampleSketch(M, rows, fit.pca);
  RoundsOnSample(M, norms, rows, energy, residual, fit, &errors, sketch);
  for (int s = 0; s < o_.lpca.splits; ++s) {
    rep_.Progress(std::size_t(s) + 1, steps, "sample rounds");
    ClusterFit trial{{}, {}, 0, {}};
    if (!ProposeSplitMerge(M, norms, rows, fit, trial.assign)) break;
    FitSample(M, rows, energy, residual, trial, &fit);
    RoundsOnSample(M, norms, rows, energy, residual, trial, nullptr, sketch);
    split_errors.push_back(trial.error);
    const bool better = trial.error < fit.error;
    const bool enough = fit.error - trial.error >= o_.lpca.min_improvement * fit.error;
    if (better) fit = std::move(trial);
    if (!enough) break;
  }
  rep_.Progress(steps, steps, "sample rounds");
  return std::move(fit.pca);
}

template <typename Mat>
void LpcaSampler::RoundsOnSample(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, double energy,
                    std::vector<double>& residual, ClusterFit& fit, std::vector<double>* errors,
                    Sketch& sketch) const {
  for (int it = 0; it < o_.lpca.max_iterations; ++it) {
    ClusterFit next{{}, fit.assign, 0, {}};
    if (ReassignSample(M, norms, rows, fit.pca, next.assign, residual, sketch) == 0) break;
    FitSample(M, rows, energy, residual, next, &fit);
    if (errors) errors->push_back(next.error);
    const bool better = next.error < fit.error;
    const bool enough = fit.error - next.error >= o_.lpca.min_improvement * fit.error;
    if (better) fit = std::move(next);
    if (!enough) break;
  }
}

template <typename Mat>
bool LpcaSampler::ProposeSplitMerge(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, const ClusterFit& f,
                       std::vector<std::int32_t>& assign) const {
  if (K_ < 2) return false;
  int j = 0;
  for (int k = 1; k < K_; ++k)
    if (f.pca[std::size_t(k)].residual_energy > f.pca[std::size_t(j)].residual_energy) j = k;
  if (f.pca[std::size_t(j)].components() == 0) return false;
  // Per sample texel: the best cluster other than its own (alt) and, for j's split, its score
  // on j's first component; per cluster, the cost of its removal.
  const AllClustersModel model(f.pca, o_.components, d_);
  const std::size_t S = rows.size();
  std::vector<std::int32_t> alt(S);
  std::vector<double> gap(S), score(S);
  ThreadPageBuffers scratch;
  ForBlocks(S, [&](std::size_t first, std::size_t count) {
    const Eigen::Index w = static_cast<Eigen::Index>(count);
    const Eigen::MatrixXf P = GatheredProducts(M, rows.data(), first, count, model.big, scratch);
    for (Eigen::Index i = 0; i < w; ++i) {
      const std::size_t s = first + std::size_t(i);
      const double norm = norms[rows[s]];
      const int own = f.assign[s];
      double best = std::numeric_limits<double>::infinity();
      alt[s] = own;
      for (int k = 0; k < K_; ++k) {
        if (k == own) continue;
        const double r = model.Residual(P, i, norm, k);
        if (r < best) best = r, alt[s] = k;
      }
      gap[s] = best - model.Residual(P, i, norm, own);
      score[s] = model.Score(P, i, j, 0);
    }
  });
  std::vector<double> cost(static_cast<std::size_t>(K_), 0.0);
  for (std::size_t s = 0; s < S; ++s) cost[std::size_t(f.assign[s])] += gap[s];
  int k = j == 0 ? 1 : 0;
  for (int l = 0; l < K_; ++l)
    if (l != j && cost[std::size_t(l)] < cost[std::size_t(k)]) k = l;
  assign = f.assign;
  std::size_t leaving = 0, staying = 0;
  for (std::size_t s = 0; s < S; ++s) {
    if (assign[s] == k) assign[s] = alt[s];
    if (assign[s] != j) continue;
    if (score[s] > 0) assign[s] = k, ++leaving;
    else ++staying;
  }
  return leaving > 0 && staying > 0;
}

template <typename Mat>
void LpcaSampler::FitSample(const Mat& M, const std::vector<std::size_t>& rows, double energy,
               const std::vector<double>& residual, ClusterFit& f, const ClusterFit* prev) const {
  std::vector<std::vector<std::size_t>> members = MembersFillingEmpty(f.assign, K_, residual.empty() ? nullptr : residual.data());
  f.pca.assign(static_cast<std::size_t>(K_), PcaResult{});
  std::vector<int> order_k;  // to fit, largest first; the others keep prev's PCA
  for (int k = 0; k < K_; ++k) {
    const auto& m = members[static_cast<std::size_t>(k)];
    if (m.empty()) continue;
    if (prev && prev->members[static_cast<std::size_t>(k)] == m)
      f.pca[static_cast<std::size_t>(k)] = prev->pca[static_cast<std::size_t>(k)];
    else
      order_k.push_back(k);
  }
  std::stable_sort(order_k.begin(), order_k.end(), [&](int a, int b) {
    return members[static_cast<std::size_t>(a)].size() > members[static_cast<std::size_t>(b)].size();
  });
  ThreadPageBuffers scratch;  // each thread's block of rows for the randomized path
#pragma omp parallel for schedule(dynamic, 1)
  for (std::ptrdiff_t kk = 0; kk < std::ptrdiff_t(order_k.size()); ++kk) {
    omp_set_num_threads(1);  // Eigen sequential in this cluster's task
    const int k = order_k[static_cast<std::size_t>(kk)];
    const auto& m = members[static_cast<std::size_t>(k)];
    PcaRows x{static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_),
              [&](Eigen::Index first, Eigen::Index count, float* out) {
                for (Eigen::Index i = 0; i < count; ++i)
                  RowToFloat(M, static_cast<Eigen::Index>(rows[m[std::size_t(first + i)]]), out + std::size_t(i) * d_);
              },
              [&](Eigen::Index c0, Eigen::Index w, float* out, Eigen::Index stride) {
                for (std::size_t i = 0; i < m.size(); ++i)
                  RowToFloat(M, static_cast<Eigen::Index>(rows[m[i]]), out + i * std::size_t(stride), c0, w);
              }};
    x.block = scratch.Get<float>(std::size_t(kPcaBlockRows) * d_);
    PcaResult p = Pca(x, MakeRequest(o_, std::uint64_t(k)), WarmStart(o_.lpca.warm_start, prev ? &prev->pca : nullptr, k));
    p.scores.resize(0, 0);
    f.pca[static_cast<std::size_t>(k)] = std::move(p);
  }
  double res = 0;
  for (const PcaResult& p : f.pca) res += p.residual_energy;
  f.error = energy > 0 ? std::sqrt((res + outside_) / energy) : 0;
  f.members = std::move(members);
}

template <typename Mat>
std::size_t LpcaSampler::ReassignSample(const Mat& M, const double* norms, const std::vector<std::size_t>& rows,
                           const std::vector<PcaResult>& pca, std::vector<std::int32_t>& assign,
                           std::vector<double>& residual, Sketch& sketch) const {
  const std::size_t S = rows.size();
  const std::vector<int> fitted = Fitted(pca);
  if (!sketch.bounds.empty()) sketch.bounds.SetClusters(pca);
  residual.resize(S);
  std::vector<std::uint8_t> changed(S, 0);
  ForBlocks(S, [&](std::size_t first, std::size_t count) {
    std::vector<std::vector<int>> candidates;
    if (!sketch.bounds.empty()) {
      std::vector<double> norm2(count);
      for (std::size_t i = 0; i < count; ++i) norm2[i] = norms[rows[first + i]];
      sketch.Candidates(first, count, norm2.data(), candidates);
    }
    BestClusters(M, [&](std::size_t i) { return Eigen::Index(rows[first + i]); }, count, pca, fitted,
                 sketch.bounds.empty() ? nullptr : &candidates, assign.data() + first, residual.data() + first,
                 changed.data() + first, nullptr);
  });
  return std::accumulate(changed.begin(), changed.end(), std::size_t(0));
}

template <typename Mat>
int LpcaSampler::Lloyd(const Mat& M, const double* norms, const std::vector<std::size_t>& sample, std::mt19937_64& rng,
          std::vector<std::int32_t>& assign) const {
  rep_.Progress(0, std::size_t(kLloydRounds), "k-means");
  RowMatrixXf centers = SeedCenters(M, sample, rng);
  const std::size_t S = sample.size();
  std::vector<std::int32_t> next(S);
  assign.assign(S, -1);
  std::vector<double> dist(S);
  double objective = std::numeric_limits<double>::infinity();
  int rounds = 0;
  for (; rounds < kLloydRounds; ++rounds) {
    rep_.Progress(std::size_t(rounds), std::size_t(kLloydRounds), "k-means");
    NearestCenters(M, norms, centers, sample.data(), S, next.data(), dist.data());
    const bool moved = next != assign;
    assign.swap(next);
    double obj = 0;
    for (double e : dist) obj += e;
    if (!moved || !(objective - obj > kLloydTolerance * obj)) break;
    objective = obj;
    UpdateMeans(M, sample, assign, dist, centers);
  }
  rep_.Progress(std::size_t(kLloydRounds), std::size_t(kLloydRounds), "k-means");  // converged: the bar ends
  return rounds;
}

template <typename Mat>
void LpcaSampler::UpdateMeans(const Mat& M, const std::vector<std::size_t>& sample, std::vector<std::int32_t>& assign,
                 const std::vector<double>& dist, RowMatrixXf& centers) const {
  const std::size_t S = sample.size();
  std::vector<std::size_t> count(static_cast<std::size_t>(K_), 0);
  for (std::int32_t k : assign) ++count[static_cast<std::size_t>(k)];
  std::vector<std::size_t> order;
  for (int k = 0; k < K_; ++k) {
    if (count[static_cast<std::size_t>(k)] > 0) continue;
    if (order.empty()) {
      order.resize(S);
      std::iota(order.begin(), order.end(), std::size_t(0));
      std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return dist[a] > dist[b]; });
    }
    for (std::size_t i : order)
      if (count[static_cast<std::size_t>(assign[i])] > 1) {
        --count[static_cast<std::size_t>(assign[i])];
        assign[i] = k;
        count[static_cast<std::size_t>(k)] = 1;
        break;
      }
  }
  const Eigen::Index d = M.cols();
  constexpr Eigen::Index kCols = 512;
  const std::ptrdiff_t chunks = static_cast<std::ptrdiff_t>((d + kCols - 1) / kCols);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t ch = 0; ch < chunks; ++ch) {
    const Eigen::Index c0 = ch * kCols, w = std::min(kCols, d - c0);
    // Row-major: a texel's values are added to one contiguous row of sums.
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> sums =
        Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>::Zero(K_, w);
    Eigen::RowVectorXf x(w);
    for (std::size_t i = 0; i < S; ++i) {
      RowToFloat(M, static_cast<Eigen::Index>(sample[i]), x.data(), c0, w);
      sums.row(assign[i]) += x.cast<double>();
    }
    for (int k = 0; k < K_; ++k)
      if (count[static_cast<std::size_t>(k)] > 0)
        centers.row(k).segment(c0, w) = (sums.row(k) / double(count[static_cast<std::size_t>(k)])).cast<float>();
  }
}

template <typename Mat>
RowMatrixXf LpcaSampler::SeedCenters(const Mat& M, const std::vector<std::size_t>& sample, std::mt19937_64& rng) const {
  RowMatrixXf centers(K_, static_cast<Eigen::Index>(d_));
  std::vector<double> dist(sample.size(), std::numeric_limits<double>::infinity());
  std::size_t pick = sample[std::uniform_int_distribution<std::size_t>(0, sample.size() - 1)(rng)];
  for (int k = 0; k < K_; ++k) {
    RowToFloat(M, static_cast<Eigen::Index>(pick), centers.row(k).data());
#pragma omp parallel
    {
      Eigen::RowVectorXf x(M.cols());
#pragma omp for schedule(static)
      for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(sample.size()); ++i) {
        RowToFloat(M, static_cast<Eigen::Index>(sample[i]), x.data());
        dist[i] = std::min(dist[i], double((x - centers.row(k)).squaredNorm()));
      }
    }
    const double s = std::accumulate(dist.begin(), dist.end(), 0.0);
    if (!(s > 0)) {  // fewer distinct ABRDFs than clusters: duplicate centers (clusters stay empty, re-seeded)
      pick = sample[std::size_t(k + 1) % sample.size()];
      continue;
    }
    double u = std::uniform_real_distribution<double>(0.0, s)(rng);
    std::size_t i = 0;
    for (; i + 1 < dist.size(); ++i) {
      u -= dist[i];
      if (u <= 0) break;
    }
    pick = sample[i];
  }
  return centers;
}

template SampleSubspace LpcaSampler::Subspace(const TexelMatrix::HalfMatrix&, const double*,
                                              const std::vector<std::size_t>&, int) const;
template SampleSubspace LpcaSampler::Subspace(const RowMatrixXf&, const double*, const std::vector<std::size_t>&,
                                              int) const;
template int LpcaSampler::Lloyd(const TexelMatrix::HalfMatrix&, const double*, const std::vector<std::size_t>&,
                                std::mt19937_64&, std::vector<std::int32_t>&) const;
template int LpcaSampler::Lloyd(const RowMatrixXf&, const double*, const std::vector<std::size_t>&, std::mt19937_64&,
                                std::vector<std::int32_t>&) const;
template std::vector<PcaResult> LpcaSampler::SampleRounds(const TexelMatrix::HalfMatrix&, const double*,
                                                          const std::vector<std::size_t>&, std::vector<std::int32_t>,
                                                          std::vector<double>&, std::vector<double>&) const;
template std::vector<PcaResult> LpcaSampler::SampleRounds(const RowMatrixXf&, const double*,
                                                          const std::vector<std::size_t>&, std::vector<std::int32_t>,
                                                          std::vector<double>&, std::vector<double>&) const;

}  // namespace btf::lpca
