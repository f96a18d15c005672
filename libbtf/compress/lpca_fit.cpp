// LPCA's rounds over every texel: per-cluster PCA, reassignment, the codec's model
// (lpca_internal.h, LpcaFitter).
#include <algorithm>
#include <cmath>
#include <numeric>

#include "libbtf/compress/lpca_internal.h"
#include "libbtf/core/error.h"

namespace btf::lpca {

std::vector<std::vector<std::size_t>> MembersFillingEmpty(std::vector<std::int32_t>& assign, int K,
                                                          const double* residual) {
  const std::size_t n = assign.size();
  std::vector<std::vector<std::size_t>> members(static_cast<std::size_t>(K));
  for (std::size_t i = 0; i < n; ++i) members[static_cast<std::size_t>(assign[i])].push_back(i);
  std::vector<std::size_t> order;
  std::size_t next_worst = 0;
  for (int k = 0; k < K; ++k) {
    if (!members[static_cast<std::size_t>(k)].empty()) continue;
    if (order.empty()) {
      order.resize(n);
      std::iota(order.begin(), order.end(), std::size_t(0));
      if (residual) std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return residual[a] > residual[b]; });
    }
    while (next_worst < n && members[static_cast<std::size_t>(assign[order[next_worst]])].size() <= 1) ++next_worst;
    if (next_worst == n) break;
    const std::size_t i = order[next_worst++];
    auto& from = members[static_cast<std::size_t>(assign[i])];
    from.erase(std::find(from.begin(), from.end(), i));
    assign[i] = k;
    members[static_cast<std::size_t>(k)].push_back(i);
  }
  return members;
}

// The clusters with a model (a mean), in increasing order.
std::vector<int> Fitted(const std::vector<PcaResult>& pca) {
  std::vector<int> fitted;
  for (std::size_t k = 0; k < pca.size(); ++k)
    if (pca[k].mean.size() > 0) fitted.push_back(int(k));
  return fitted;
}

const RowMatrixXf* WarmStart(bool enabled, const std::vector<PcaResult>* warm, int k) {
  if (!enabled || !warm) return nullptr;
  const PcaResult& p = (*warm)[static_cast<std::size_t>(k)];
  return p.components() > 0 ? &p.basis : nullptr;
}

std::vector<std::uint8_t> PackPca(const PcaResult& p) {
  dist::Packer b;
  for (int x : {p.requested, p.clamped_to, p.dropped_null, int(p.randomized)}) b.Put(x);
  for (double x : {p.total_energy, p.centered_energy, p.residual_energy}) b.Put(x);
  for (Eigen::Index x : {p.basis.rows(), p.basis.cols(), p.scores.rows(), p.scores.cols()}) b.Put(std::int64_t(x));
  b.PutVector(p.eigenvalues);
  b.PutVector(p.mean.data(), std::size_t(p.mean.size()));
  b.PutVector(p.basis.data(), std::size_t(p.basis.size()));
  b.PutVector(p.scores.data(), std::size_t(p.scores.size()));
  return std::move(b.bytes);
}

PcaResult UnpackPca(const std::vector<std::uint8_t>& bytes) {
  dist::Unpacker u(bytes);
  PcaResult p;
  p.requested = u.Get<int>();
  p.clamped_to = u.Get<int>();
  p.dropped_null = u.Get<int>();
  p.randomized = u.Get<int>() != 0;
  p.total_energy = u.Get<double>();
  p.centered_energy = u.Get<double>();
  p.residual_energy = u.Get<double>();
  const auto br = u.Get<std::int64_t>(), bc = u.Get<std::int64_t>(), sr = u.Get<std::int64_t>(), sc = u.Get<std::int64_t>();
  p.eigenvalues = u.GetVector<double>();
  const std::vector<float> mean = u.GetVector<float>();
  p.mean = Eigen::Map<const Eigen::VectorXf>(mean.data(), static_cast<Eigen::Index>(mean.size()));
  p.basis.resize(br, bc);
  u.GetVectorInto(p.basis.data(), std::size_t(br * bc));
  p.scores.resize(sr, sc);
  u.GetVectorInto(p.scores.data(), std::size_t(sr * sc));
  return p;
}

std::vector<int> LpcaFitter::FitClusters(ClusterFit& f, bool have_residuals, ClusterFit* prev,
                                         std::vector<PcaResult>* warm, bool release_warm) {
  std::vector<std::vector<std::size_t>> members = MembersFillingEmpty(f.assign, K_, have_residuals ? residual_.data() : nullptr);
  f.pca.assign(static_cast<std::size_t>(K_), PcaResult{});
  // Largest first (one cluster per thread, Eigen single-threaded inside the region); the
  // clusters that keep prev's PCA are left out.
  std::vector<int> order_k, kept;
  for (int k = 0; k < K_; ++k) {
    const auto& m = members[static_cast<std::size_t>(k)];
    if (prev && !m.empty() && prev->members.size() == members.size() &&
        prev->members[static_cast<std::size_t>(k)] == m) {
      f.pca[static_cast<std::size_t>(k)] = std::move(prev->pca[static_cast<std::size_t>(k)]);
      kept.push_back(k);
    } else {
      order_k.push_back(k);
    }
  }
  std::stable_sort(order_k.begin(), order_k.end(), [&](int a, int b) {
    return members[static_cast<std::size_t>(a)].size() > members[static_cast<std::size_t>(b)].size();
  });
  const WavePlan p = PlanWaves(members, order_k);
  std::vector<RowMatrixXf> X(static_cast<std::size_t>(K_));
  for (std::size_t w = 0; w < p.waves; ++w) {
    if (rows_.ooc_) rows_.ReadClusterRows(members, p.owned[0], w ? p.wave_end[w - 1] : 0, p.wave_end[w], X);
    if (R_ > 1) GatherWaveRows(p, members, w, X);
    FitWave(p, members, w, warm, release_warm, X, f);
  }
  if (R_ > 1)  // every rank gets every cluster's model (and scores, for the codec)
    for (int k : order_k) {
      if (members[static_cast<std::size_t>(k)].empty()) continue;
      const int o = p.owner[static_cast<std::size_t>(k)];
      auto bytes = ranks_.BroadcastBytes(o, rank_ == o ? PackPca(f.pca[static_cast<std::size_t>(k)])
                                                      : std::vector<std::uint8_t>());
      if (rank_ != o) f.pca[static_cast<std::size_t>(k)] = UnpackPca(bytes);
    }
  double res = 0;
  for (const PcaResult& p : f.pca) res += p.residual_energy;
  f.error = rows_.total_ > 0 ? std::sqrt(res / rows_.total_) : 0;
  f.members = std::move(members);
  ReleaseFreeHeap();  // the fits' working arrays, freed between the models they kept
  return kept;
}

LpcaFitter::WavePlan LpcaFitter::PlanWaves(const std::vector<std::vector<std::size_t>>& members,
                                           const std::vector<int>& order_k) const {
  WavePlan p;
  // The rank that fits each cluster: the least loaded so far (in texels), largest first.
  p.owner.assign(static_cast<std::size_t>(K_), 0);
  if (R_ > 1) {
    std::vector<std::size_t> load(static_cast<std::size_t>(R_), 0);
    for (int k : order_k) {
      const int r = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
      p.owner[static_cast<std::size_t>(k)] = r;
      load[static_cast<std::size_t>(r)] += members[static_cast<std::size_t>(k)].size();
    }
  }
  // Each rank fits its clusters (largest first) in waves of as many clusters as it has
  // threads (all of them in one process): per wave, the member rows held by other ranks are
  // gathered in (owner, cluster, sending rank) order, a fixed sequence of blocking transfers
  // (no deadlock), and the rank's own rows are copied when its cluster is fitted. Rows stay in
  // texel order. A rank so holds the rows of one wave's clusters at a time, not of all its
  // clusters.
  p.owned.assign(static_cast<std::size_t>(R_), {});
  for (int k : order_k)
    if (!members[static_cast<std::size_t>(k)].empty()) p.owned[static_cast<std::size_t>(p.owner[static_cast<std::size_t>(k)])].push_back(k);
  for (const auto& list : p.owned) p.wave = std::max(p.wave, list.size());
  if (R_ > 1) p.wave = std::size_t(std::max(1, omp_get_max_threads()));
  for (const auto& list : p.owned) p.waves = std::max(p.waves, p.wave ? (list.size() + p.wave - 1) / p.wave : 0);
  // Out of core: waves of consecutive clusters (largest first) whose rows fit rows_.budget_, each
  // gathered in one pass over the slots.
  for (std::size_t w = 0; w < p.waves; ++w) p.wave_end.push_back(std::min(p.owned[std::size_t(rank_)].size(), (w + 1) * p.wave));
  if (rows_.ooc_) {
    p.wave_end.clear();
    double bytes = 0;
    const auto& list = p.owned[0];
    for (std::size_t j = 0; j < list.size(); ++j) {
      const double b = 4.0 * double(members[std::size_t(list[j])].size()) * double(d_);
      if (b > rows_.budget_)
        ThrowBadInput("out-of-core LPCA: cluster {} has {} texels ({:.3g} GiB of rows), over the wave budget of {:.3g} "
                      "GiB (half the memory limit {:.3g} GiB); use more clusters (-k) or raise BTF_MAX_BYTES",
                      list[j], members[std::size_t(list[j])].size(), b / double(1ull << 30),
                      rows_.budget_ / double(1ull << 30), 2 * rows_.budget_ / double(1ull << 30));
      if (j > 0 && bytes + b > rows_.budget_) p.wave_end.push_back(j), bytes = 0;
      bytes += b;
    }
    if (!list.empty()) p.wave_end.push_back(list.size());
    p.waves = p.wave_end.size();
  }
  return p;
}

void LpcaFitter::GatherWaveRows(const WavePlan& p, const std::vector<std::vector<std::size_t>>& members, std::size_t w,
                                std::vector<RowMatrixXf>& X) const {
  for (int o = 0; o < R_; ++o) {
    const auto& list = p.owned[static_cast<std::size_t>(o)];
    for (std::size_t j = w * p.wave; j < std::min(list.size(), (w + 1) * p.wave); ++j) {
      const int k = list[j];
      const auto& m = members[static_cast<std::size_t>(k)];
      if (rank_ != o && !rows_.OwnsAny(m)) continue;
      if (rank_ == o)
        X[static_cast<std::size_t>(k)].resize(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_));
      for (int r = 0; r < R_; ++r) {
        if (r == o) continue;
        const std::size_t lo = std::size_t(std::lower_bound(m.begin(), m.end(), rows_.TexelBegin(r)) - m.begin());
        const std::size_t hi = std::size_t(std::lower_bound(m.begin(), m.end(), rows_.TexelBegin(r + 1)) - m.begin());
        if (lo == hi) continue;
        if (rank_ == o) {
          ranks_.Recv(r, 2, X[static_cast<std::size_t>(k)].data() + lo * d_, (hi - lo) * d_ * sizeof(float));
        } else if (rank_ == r) {
          RowMatrixXf rows(static_cast<Eigen::Index>(hi - lo), static_cast<Eigen::Index>(d_));
          for (std::size_t i = lo; i < hi; ++i)
            rows_.A_.CopyRow(m[i] - rows_.t0_, rows.row(Eigen::Index(i - lo)).data());
          ranks_.Send(o, 2, rows.data(), std::size_t(rows.size()) * sizeof(float));
        }
      }
    }
  }
}

void LpcaFitter::FitWave(const WavePlan& p, const std::vector<std::vector<std::size_t>>& members, std::size_t w,
                         std::vector<PcaResult>* warm, bool release_warm, std::vector<RowMatrixXf>& X,
                         ClusterFit& f) const {
  // Each cluster's PCA is computed by one thread alone (Eigen single-threaded inside the
  // region) and the residuals are summed in cluster order: the result does not depend on
  // which thread or rank took which cluster.
  const auto& list = p.owned[static_cast<std::size_t>(rank_)];
  const std::size_t last = std::min(list.size(), p.wave_end[w]), first = std::min(last, w ? p.wave_end[w - 1] : 0);
  ThreadPageBuffers scratch;  // each thread's block of rows for the randomized path
#pragma omp parallel for schedule(dynamic, 1)
  for (std::ptrdiff_t kk = std::ptrdiff_t(first); kk < std::ptrdiff_t(last); ++kk) {
    omp_set_num_threads(1);  // Eigen sequential in this cluster's task
    const int k = list[static_cast<std::size_t>(kk)];
    const auto& m = members[static_cast<std::size_t>(k)];
    const PcaRequest q = MakeRequest(o_, std::uint64_t(k));
    if (R_ == 1 && !rows_.ooc_) {  // in core, one process: the rows come from rows_.A_ a block at a time
      PcaRows rows{static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_),
                   [&](Eigen::Index first, Eigen::Index count, float* out) {
                     for (Eigen::Index i = 0; i < count; ++i)
                       rows_.A_.CopyRow(m[std::size_t(first + i)], out + std::size_t(i) * d_);
                   },
                   [&](Eigen::Index c0, Eigen::Index w, float* out, Eigen::Index stride) {
                     for (std::size_t i = 0; i < m.size(); ++i)
                       rows_.A_.CopyRowPart(m[i], std::size_t(c0), std::size_t(w), out + i * std::size_t(stride));
                   }};
      rows.block = scratch.Get<float>(std::size_t(kPcaBlockRows) * d_);
      f.pca[static_cast<std::size_t>(k)] = Pca(rows, q, WarmStart(o_.lpca.warm_start, warm, k));
      if (release_warm) (*warm)[static_cast<std::size_t>(k)] = PcaResult();  // this thread's cluster alone
      continue;
    }
    RowMatrixXf& x = X[static_cast<std::size_t>(k)];
    if (x.rows() == 0) x.resize(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_));
    for (std::size_t i = 0; i < m.size() && !rows_.ooc_; ++i)
      if (m[i] >= rows_.t0_ && m[i] < rows_.t1_) rows_.A_.CopyRow(m[i] - rows_.t0_, x.row(Eigen::Index(i)).data());
    f.pca[static_cast<std::size_t>(k)] = Pca(x, q, WarmStart(o_.lpca.warm_start, warm, k));
    if (release_warm) (*warm)[static_cast<std::size_t>(k)] = PcaResult();
    x.resize(0, 0);
  }
}

std::size_t LpcaFitter::Reassign(const std::vector<PcaResult>& pca, std::vector<std::int32_t>& assign) {
  const bool build = o_.lpca.prune && sketch_.e.empty();
  if (build) sketch_ = Sketch(pca, d_, N_);
  if (!sketch_.bounds.empty()) sketch_.bounds.SetClusters(pca);
  const std::vector<int> fitted = Fitted(pca);
  std::vector<std::uint8_t> changed(N_, 0);
  std::vector<std::uint32_t> compared(N_, 0);
  ThreadPageBuffers scratch;
  rows_.ForChunks([&] { rows_.A_.Visit([&](const auto& M) { ForBlocks(rows_.local(), [&](std::size_t b, std::size_t count) {
    const std::size_t t = rows_.t0_ + b;  // the block's first texel
    std::vector<std::vector<int>> candidates;
    if (!sketch_.bounds.empty()) {
      for (std::size_t i = 0; build && i < count; i += kProjectRows)
        sketch_.Project(rows_.A_.Rows(b + i, std::min(kProjectRows, count - i), scratch), t + i);
      sketch_.Candidates(t, count, rows_.norms_.data() + t, candidates);
    }
    BestClusters(M, [&](std::size_t i) { return Eigen::Index(b + i); }, count, pca, fitted,
                 sketch_.bounds.empty() ? nullptr : &candidates, assign.data() + t, residual_.data() + t, changed.data() + t,
                 compared.data() + t);
  }); }); });
  if (build) sketch_.bounds.EndProjections();  // every texel's g and e are in
  // Mean clusters compared per texel (this rank's texels; the sum of integers is exact).
  std::uint64_t pairs = std::accumulate(compared.begin(), compared.end(), std::uint64_t(0));
  if (R_ > 1) {
    std::uint64_t all = 0;
    for (std::uint64_t v : ranks_.AllGatherConcat(std::vector<std::uint64_t>{pairs})) all += v;
    pairs = all;
  }
  sum_.lpca_compared.push_back(N_ ? double(pairs) / double(N_) : 0.0);
  std::uint64_t moved = std::accumulate(changed.begin(), changed.end(), std::uint64_t(0));
  if (R_ > 1) {  // share this rank's texels' assignments and residuals
    const std::vector<std::int32_t> a =
        ranks_.AllGatherConcat(std::vector<std::int32_t>(assign.begin() + std::ptrdiff_t(rows_.t0_), assign.begin() + std::ptrdiff_t(rows_.t1_)));
    const std::vector<double> r = ranks_.AllGatherConcat(
        std::vector<double>(residual_.begin() + std::ptrdiff_t(rows_.t0_), residual_.begin() + std::ptrdiff_t(rows_.t1_)));
    BTF_CHECK(a.size() == N_ && r.size() == N_);
    assign = a;
    residual_ = r;
    moved = 0;
    for (std::uint64_t m : ranks_.AllGatherConcat(std::vector<std::uint64_t>{std::accumulate(
             changed.begin(), changed.end(), std::uint64_t(0))}))
      moved += m;
  }
  ReleaseFreeHeap();  // the reassignment's working arrays
  return static_cast<std::size_t>(moved);
}

void LpcaFitter::Iterate(ClusterFit& fit) {
  for (int it = 0; it < o_.lpca.max_iterations; ++it) {
    rep_.Progress(std::size_t(it), std::size_t(o_.lpca.max_iterations), "lpca");
    ClusterFit next{{}, fit.assign, 0, {}};
    const std::size_t moved = Reassign(fit.pca, next.assign);
    if (moved == 0) break;
    const std::vector<int> kept = FitClusters(next, true, &fit, &fit.pca);  // kept: moved from fit
    sum_.iteration_errors.push_back(next.error);
    sum_.iteration_changes.push_back(static_cast<int>(moved));
    rep_.Info("lpca: iteration {}: {} texels reassigned, relative error {:.5f}", it + 1, moved, next.error);
    const bool better = next.error < fit.error;
    const bool enough = fit.error - next.error >= o_.lpca.min_improvement * fit.error;
    if (better) {
      fit = std::move(next);
    } else {
      for (int k : kept) fit.pca[std::size_t(k)] = std::move(next.pca[std::size_t(k)]);
    }
    if (!enough) break;
  }
  rep_.Progress(std::size_t(o_.lpca.max_iterations), std::size_t(o_.lpca.max_iterations), "lpca");  // converged
}

void LpcaFitter::StoreModel(const ClusterFit& fit, Codec& codec) {
  const int K = K_;
  LpcaModel& m = CodecBuilder::lpca(codec);
  int c = 0;
  for (const auto& p : fit.pca) c = std::max(c, p.components());
  m.clusters = K;
  m.components = c;
  m.means.assign(std::size_t(K) * d_, 0.0f);
  m.basis.assign(std::size_t(K) * c * d_, 0.0f);
  m.cluster_components.assign(static_cast<std::size_t>(K), 0);
  m.cluster_of = fit.assign;
  m.weights.assign(N_ * c, 0.0f);
  int small = 0, dropped = 0;
  for (int k = 0; k < K; ++k) {
    const PcaResult& p = fit.pca[static_cast<std::size_t>(k)];
    sum_.slot_components.push_back(p.components());
    if (p.mean.size() == 0) continue;
    if (p.clamped_to < std::min(o_.components, int(d_))) ++small;
    dropped += p.dropped_null;
    m.cluster_components[static_cast<std::size_t>(k)] = p.components();
    std::copy(p.mean.data(), p.mean.data() + d_, m.means.data() + std::size_t(k) * d_);
    std::copy(p.basis.data(), p.basis.data() + p.basis.size(), m.basis.data() + std::size_t(k) * c * d_);
  }
  // Members are visited in texel order, as FitClusters gathered them.
  std::vector<std::size_t> seen(static_cast<std::size_t>(K), 0);
  for (std::size_t i = 0; i < N_; ++i) {
    const int k = fit.assign[i];
    const PcaResult& p = fit.pca[static_cast<std::size_t>(k)];
    const std::size_t row = seen[static_cast<std::size_t>(k)]++;
    for (int j = 0; j < p.components(); ++j) m.weights[i * c + j] = p.scores(Eigen::Index(row), j);
  }
  if (o_.storage == CodecStorage::kHalf)
    for (auto* a : {&m.means, &m.basis, &m.weights})
      for (float& x : *a) x = RoundToHalf(x);
  if (small > 0)
    Warn(fmt::format("{} clusters have too few texels for {} components (clamped to members - 1)", small,
                     o_.components));
  if (dropped > 0) sum_.warnings.push_back(fmt::format("{} components with ~0 eigenvalue dropped", dropped));
  sum_.clusters = K;
}

}  // namespace btf::lpca
