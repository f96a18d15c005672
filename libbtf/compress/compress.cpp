// The compressors: per-view PCA (streamed slot by slot) and local PCA (texel-major matrix,
// reassignment in texel blocks).
#include <algorithm>
#include <cmath>
#include <functional>
#include <future>
#include <limits>
#include <numeric>
#include <random>

#include <omp.h>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/pca.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"

namespace btf {

namespace {

// A BTF read one view slot (L x H x W x C floats) at a time.
struct SlotInput {
  std::string name;
  Sampling views, lights;
  int height = 0, width = 0, channels = 0;
  DatasetInfo info;
  std::function<void(int, float*)> read;
  std::size_t image_size() const { return std::size_t(height) * width * channels; }
  std::size_t slot_size() const { return image_size() * lights.size(); }
};

// Keeps only what the scene uses: view/light subsets, a mip level (box filter over 2^m x 2^m
// texels; trailing rows/columns that do not fill a block are dropped), a channel subset.
SlotInput ApplyScene(const SlotInput& in, const SceneSpec& scene) {
  const std::vector<int> vi = NeededDirections(in.views, scene.views), li = NeededDirections(in.lights, scene.lights);
  std::vector<int> ci;
  if (scene.channels.empty()) {
    ci.resize(static_cast<std::size_t>(in.channels));
    std::iota(ci.begin(), ci.end(), 0);
  } else {
    for (const auto& name : scene.channels) {
      const auto it = std::find(in.info.channel_names.begin(), in.info.channel_names.end(), name);
      if (it == in.info.channel_names.end())
        ThrowBadInput("scene names channel '{}', which '{}' does not have (channels: {})", name, in.name,
                      fmt::join(in.info.channel_names, ","));
      ci.push_back(static_cast<int>(it - in.info.channel_names.begin()));
    }
  }
  const int b = 1 << scene.mip_level;
  if (in.height < b || in.width < b)
    ThrowBadInput("scene mip level {} needs at least {} x {} texels; '{}' has {} x {}", scene.mip_level, b, b, in.name,
                  in.width, in.height);
  SlotInput out;
  out.name = in.name;
  out.views = in.views.Subset(vi);
  out.lights = in.lights.Subset(li);
  out.height = in.height / b;
  out.width = in.width / b;
  out.channels = static_cast<int>(ci.size());
  out.info = in.info;
  out.info.channel_names.clear();
  for (int c : ci) out.info.channel_names.push_back(in.info.channel_names[static_cast<std::size_t>(c)]);
  out.info.texel_size_mm = in.info.texel_size_mm * b;
  const int H = out.height, W = out.width, C = out.channels, iW = in.width, iC = in.channels, iH = in.height;
  const std::size_t in_slot = in.slot_size();
  const SlotInput src = in;
  out.read = [src, vi, li, ci, b, H, W, C, iW, iC, iH, in_slot](int v, float* dst) {
    std::vector<float> buf(in_slot);
    src.read(vi[static_cast<std::size_t>(v)], buf.data());
    const double norm = 1.0 / (double(b) * b);
    for (std::size_t l = 0; l < li.size(); ++l) {
      const float* img = &buf[std::size_t(li[l]) * iH * iW * iC];
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          for (int c = 0; c < C; ++c) {
            double s = 0;
            for (int dy = 0; dy < b; ++dy)
              for (int dx = 0; dx < b; ++dx)
                s += img[(std::size_t(y * b + dy) * iW + (x * b + dx)) * iC + ci[static_cast<std::size_t>(c)]];
            dst[((l * H + y) * std::size_t(W) + x) * C + c] = static_cast<float>(s * norm);
          }
    }
  };
  return out;
}

void CheckFinite(const SlotInput& in, int v, const float* slot) {
  const std::size_t n = in.slot_size();
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(slot[i])) {
      const std::size_t c = i % in.channels, t = i / in.channels, x = t % in.width, y = (t / in.width) % in.height,
                        l = t / (std::size_t(in.width) * in.height);
      ThrowBadInput("'{}' holds {} at view {}, light {}, texel (x {}, y {}), channel {}: clean the data before compressing",
                    in.name, slot[i], v, l, x, y, c);
    }
}

struct Transform {
  bool log = false;
  double eps = 0;
  // Transforms in place; refuses values the log cannot take.
  void Apply(const SlotInput& in, int v, float* data, std::size_t n) const {
    if (!log) return;
    for (std::size_t i = 0; i < n; ++i) {
      if (!(data[i] > -eps))
        ThrowBadInput("'{}' view {}: value {} is <= -epsilon ({}), outside the log transform's domain; raise "
                      "--log-epsilon or drop --log",
                      in.name, v, data[i], eps);
      data[i] = static_cast<float>(std::log(double(data[i]) + eps));
    }
  }
  float Invert(float y) const { return log ? static_cast<float>(std::exp(double(y)) - eps) : y; }
};

// Error accumulators in the original domain.
struct ErrorAccumulator {
  double sse = 0, energy = 0, max_abs = 0, peak = 0;
  std::uint64_t count = 0;
  void Add(const float* ref, const float* test, std::size_t n) {
    double s = 0, e = 0, m = 0, p = 0;
#pragma omp parallel for reduction(+ : s, e) reduction(max : m, p)
    for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
      const double d = double(test[i]) - ref[i];
      s += d * d;
      e += double(ref[i]) * ref[i];
      m = std::max(m, std::abs(d));
      p = std::max(p, std::abs(double(ref[i])));
    }
    sse += s, energy += e, max_abs = std::max(max_abs, m), peak = std::max(peak, p), count += n;
  }
  void Merge(const ErrorAccumulator& o) {
    sse += o.sse, energy += o.energy, max_abs = std::max(max_abs, o.max_abs), peak = std::max(peak, o.peak);
    count += o.count;
  }
  void Fill(CompressSummary& s) const {
    s.rmse = count ? std::sqrt(sse / double(count)) : 0;
    s.relative_error = energy > 0 ? std::sqrt(sse / energy) : 0;
    s.max_abs_error = max_abs;
    s.psnr_peak = peak;
    s.psnr_db = s.rmse > 0 && peak > 0 ? 20 * std::log10(peak / s.rmse) : std::numeric_limits<double>::infinity();
  }
};

PcaRequest MakeRequest(const CompressOptions& o, std::uint64_t seed_offset) {
  PcaRequest q;
  q.max_components = o.components;
  q.target_error = o.target_error;
  q.retained_energy = o.retained_energy;
  q.gram_limit = o.gram_limit;
  q.seed = o.seed * 0x9E3779B97F4A7C15ull + seed_offset;
  return q;
}

// ---------------------------------------------------------------------------------------------
// Per-view PCA (Sattler et al. 2003, section 4.1): per view slot, the light images are the
// observations; eigen-normtextures over texels, weights per light.
void CompressPcaView(const SlotInput& in, const CompressOptions& o, const Transform& tr, Codec& codec,
                     CompressSummary& sum, const Reporter& rep) {
  const int V = in.views.size(), L = in.lights.size();
  const std::size_t D = in.image_size(), n = in.slot_size();
  auto& slots = CodecBuilder::slots(codec);
  slots.resize(static_cast<std::size_t>(V));
  if (o.components > L - 1) {
    sum.warnings.push_back(fmt::format("components {} clamped to {} per view slot (lights - 1: {} light images span "
                                       "at most {} centred directions)",
                                       o.components, std::max(L - 1, 0), L, std::max(L - 1, 0)));
    rep.Warn("{}", sum.warnings.back());
  }
  ErrorAccumulator err;
  Timer t;
  // Reads the next slot on another thread while this one is decomposed (HDF5 is only ever
  // called from one thread at a time).
  // Slots are decomposed P at a time, one per thread (coarse-grained parallelism: no barrier
  // per small GEMM, robust when the cores are shared), while the next P slots are read on
  // another thread (HDF5 is only ever called from one thread at a time).
  const int P = std::max(1, omp_get_max_threads());
  auto read = [&](int first) {
    std::vector<std::vector<float>> batch;
    for (int v = first; v < std::min(V, first + P); ++v) {
      batch.emplace_back(n);
      in.read(v, batch.back().data());
    }
    return batch;
  };
  std::future<std::vector<std::vector<float>>> next = std::async(std::launch::async, read, 0);
  int dropped = 0;
  for (int first = 0; first < V; first += P) {
    rep.Progress(std::size_t(first), std::size_t(V), "pca-view");
    t.Restart();
    std::vector<std::vector<float>> raw = next.get();
    if (first + P < V) next = std::async(std::launch::async, read, first + P);
    sum.times.Add("read", t.Seconds());
    t.Restart();
    const int count = static_cast<int>(raw.size());
    std::vector<ErrorAccumulator> errs(static_cast<std::size_t>(count));
    std::vector<std::exception_ptr> failures(static_cast<std::size_t>(count));
    std::vector<int> drops(static_cast<std::size_t>(count), 0);
#pragma omp parallel for schedule(static, 1) num_threads(count)
    for (int b = 0; b < count; ++b) {
      const int v = first + b;
      try {
        const std::vector<float>& r0 = raw[static_cast<std::size_t>(b)];
        CheckFinite(in, v, r0.data());
        std::vector<float> X(r0);
        tr.Apply(in, v, X.data(), n);
        const Eigen::Map<const RowMatrixXf> xm(X.data(), L, static_cast<Eigen::Index>(D));
        PcaResult r = Pca(xm, MakeRequest(o, std::uint64_t(v)));
        drops[static_cast<std::size_t>(b)] = r.dropped_null;
        PcaViewSlot& s = slots[static_cast<std::size_t>(v)];
        s.components = r.components();
        s.mean.assign(r.mean.data(), r.mean.data() + D);
        s.basis.assign(r.basis.data(), r.basis.data() + r.basis.size());
        s.weights.assign(r.scores.data(), r.scores.data() + r.scores.size());
        s.eigenvalues = r.eigenvalues;
        codec.DecodeViewSlot(v, X.data());  // reconstruction, for the errors
        errs[static_cast<std::size_t>(b)].Add(r0.data(), X.data(), n);
      } catch (...) {
        failures[static_cast<std::size_t>(b)] = std::current_exception();
      }
    }
    for (const auto& f : failures)
      if (f) std::rethrow_exception(f);
    for (int b = 0; b < count; ++b) {
      err.Merge(errs[static_cast<std::size_t>(b)]);
      dropped += drops[static_cast<std::size_t>(b)];
      sum.slot_components.push_back(slots[static_cast<std::size_t>(first + b)].components);
    }
    sum.times.Add("decompose", t.Seconds());
  }
  rep.Progress(std::size_t(V), std::size_t(V), "pca-view");
  if (dropped > 0) {
    sum.warnings.push_back(fmt::format("{} components with ~0 eigenvalue dropped (rank-deficient or constant slots)", dropped));
    rep.Info("{}", sum.warnings.back());
  }
  err.Fill(sum);
}

// ---------------------------------------------------------------------------------------------
// Local PCA (Mueller et al. 2003 as in Schneider 2004 section 3).
struct ClusterFit {
  std::vector<PcaResult> pca;           // per cluster
  std::vector<std::int32_t> assign;     // per texel
  double error = 0;                     // relative error (transformed domain)
};

void CompressLpca(const SlotInput& in, const CompressOptions& o, const Transform& tr, Codec& codec,
                  CompressSummary& sum, const Reporter& rep) {
  const int V = in.views.size(), L = in.lights.size(), C = in.channels;
  const std::size_t N = std::size_t(in.height) * in.width, d = std::size_t(V) * L * C;
  CheckAllocation(4.0 * double(N) * double(d), fmt::format("texel-major copy of '{}' for LPCA", in.name));
  Timer t;
  // Texel-major matrix A (N x d), transformed.
  RowMatrixXf A(static_cast<Eigen::Index>(N), static_cast<Eigen::Index>(d));
  {
    std::vector<float> slot(in.slot_size());
    for (int v = 0; v < V; ++v) {
      rep.Progress(std::size_t(v), std::size_t(V), "read");
      in.read(v, slot.data());
      CheckFinite(in, v, slot.data());
      tr.Apply(in, v, slot.data(), slot.size());
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t ti = 0; ti < static_cast<std::ptrdiff_t>(N); ++ti)
        for (int l = 0; l < L; ++l)
          for (int c = 0; c < C; ++c)
            A(ti, (std::ptrdiff_t(v) * L + l) * C + c) = slot[(std::size_t(l) * N + std::size_t(ti)) * C + c];
    }
  }
  sum.times.Add("read", t.Seconds());
  t.Restart();
  Eigen::VectorXd norms(static_cast<Eigen::Index>(N));
  for (Eigen::Index i = 0; i < A.rows(); ++i) norms[i] = A.row(i).cast<double>().squaredNorm();
  const double total = norms.sum();

  int K = o.clusters;
  if (std::size_t(K) > N) {
    sum.warnings.push_back(fmt::format("clusters {} clamped to the number of texels {}", K, N));
    rep.Warn("{}", sum.warnings.back());
    K = static_cast<int>(N);
  }
  // k-means++ seeding on a deterministic sample of at most 8192 texels.
  std::mt19937_64 rng(o.seed);
  std::vector<std::size_t> sample(N);
  std::iota(sample.begin(), sample.end(), std::size_t(0));
  if (N > 8192) {
    std::shuffle(sample.begin(), sample.end(), rng);
    sample.resize(8192);
    std::sort(sample.begin(), sample.end());
  }
  RowMatrixXf centres(K, static_cast<Eigen::Index>(d));
  {
    std::vector<double> dist(sample.size(), std::numeric_limits<double>::infinity());
    std::size_t pick = sample[std::uniform_int_distribution<std::size_t>(0, sample.size() - 1)(rng)];
    for (int k = 0; k < K; ++k) {
      centres.row(k) = A.row(static_cast<Eigen::Index>(pick));
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(sample.size()); ++i)
        dist[i] = std::min(dist[i], (A.row(static_cast<Eigen::Index>(sample[i])) - centres.row(k)).cast<double>().squaredNorm());
      const double s = std::accumulate(dist.begin(), dist.end(), 0.0);
      if (!(s > 0)) {  // fewer distinct ABRDFs than clusters: duplicate centres (clusters stay empty, re-seeded)
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
  }
  const Eigen::Index block = 4096;
  ClusterFit fit;
  fit.assign.assign(N, 0);
  {
    Eigen::VectorXf cn = centres.rowwise().squaredNorm();
    for (Eigen::Index b = 0; b < Eigen::Index(N); b += block) {
      const Eigen::Index w = std::min<Eigen::Index>(block, Eigen::Index(N) - b);
      const Eigen::MatrixXf P = A.middleRows(b, w) * centres.transpose();
#pragma omp parallel for schedule(static)
      for (Eigen::Index i = 0; i < w; ++i) {
        Eigen::Index best;
        (cn.transpose() - 2 * P.row(i)).minCoeff(&best);
        fit.assign[static_cast<std::size_t>(b + i)] = static_cast<std::int32_t>(best);
      }
    }
  }
  sum.times.Add("cluster", t.Seconds());
  t.Restart();

  std::vector<double> residual(N, 0.0);
  // Per-cluster PCA on the current assignment; empty clusters re-seeded from the worst texels.
  auto fit_clusters = [&](ClusterFit& f, bool have_residuals) {
    std::vector<std::vector<std::size_t>> members(static_cast<std::size_t>(K));
    for (std::size_t i = 0; i < N; ++i) members[static_cast<std::size_t>(f.assign[i])].push_back(i);
    std::vector<std::size_t> order;
    std::size_t next_worst = 0;
    for (int k = 0; k < K; ++k) {
      if (!members[static_cast<std::size_t>(k)].empty()) continue;
      if (order.empty()) {
        order.resize(N);
        std::iota(order.begin(), order.end(), std::size_t(0));
        if (have_residuals)
          std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return residual[a] > residual[b]; });
      }
      // Take the worst-fitted texel whose cluster can spare it.
      while (next_worst < N && members[static_cast<std::size_t>(f.assign[order[next_worst]])].size() <= 1) ++next_worst;
      if (next_worst == N) break;
      const std::size_t i = order[next_worst++];
      auto& from = members[static_cast<std::size_t>(f.assign[i])];
      from.erase(std::find(from.begin(), from.end(), i));
      f.assign[i] = k;
      members[static_cast<std::size_t>(k)].push_back(i);
    }
    f.pca.assign(static_cast<std::size_t>(K), PcaResult{});
    double res = 0;
    // One cluster per thread (Eigen runs single-threaded inside a parallel region), largest first.
    std::vector<int> order_k(static_cast<std::size_t>(K));
    std::iota(order_k.begin(), order_k.end(), 0);
    std::stable_sort(order_k.begin(), order_k.end(), [&](int a, int b) {
      return members[static_cast<std::size_t>(a)].size() > members[static_cast<std::size_t>(b)].size();
    });
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : res)
    for (int kk = 0; kk < K; ++kk) {
      const int k = order_k[static_cast<std::size_t>(kk)];
      const auto& m = members[static_cast<std::size_t>(k)];
      if (m.empty()) continue;
      RowMatrixXf X(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d));
      for (std::size_t i = 0; i < m.size(); ++i) X.row(Eigen::Index(i)) = A.row(static_cast<Eigen::Index>(m[i]));
      f.pca[static_cast<std::size_t>(k)] = Pca(X, MakeRequest(o, std::uint64_t(k)));
      res += f.pca[static_cast<std::size_t>(k)].residual_energy;
    }
    f.error = total > 0 ? std::sqrt(res / total) : 0;
  };
  // Reassigns each texel to the cluster that reconstructs it best; returns the number moved.
  auto reassign = [&](const ClusterFit& f, std::vector<std::int32_t>& assign) {
    const int c = o.components;
    RowMatrixXf big = RowMatrixXf::Zero(Eigen::Index(K) * (c + 1), static_cast<Eigen::Index>(d));
    Eigen::VectorXd mnorm = Eigen::VectorXd::Zero(K);
    std::vector<int> ck(static_cast<std::size_t>(K), -1);
    for (int k = 0; k < K; ++k) {
      const PcaResult& p = f.pca[static_cast<std::size_t>(k)];
      if (p.mean.size() == 0) continue;  // still empty
      ck[static_cast<std::size_t>(k)] = p.components();
      big.row(k) = p.mean.transpose();
      mnorm[k] = p.mean.cast<double>().squaredNorm();
      for (int j = 0; j < p.components(); ++j) big.row(K + Eigen::Index(k) * c + j) = p.basis.row(j);
    }
    // m_k . e_kj
    Eigen::MatrixXd me(K, std::max(c, 1));
    me.setZero();
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < std::max(ck[static_cast<std::size_t>(k)], 0); ++j)
        me(k, j) = big.row(k).cast<double>().dot(big.row(K + Eigen::Index(k) * c + j).cast<double>());
    std::size_t moved = 0;
    for (Eigen::Index b = 0; b < Eigen::Index(N); b += block) {
      const Eigen::Index w = std::min<Eigen::Index>(block, Eigen::Index(N) - b);
      const Eigen::MatrixXf P = A.middleRows(b, w) * big.transpose();
#pragma omp parallel for schedule(static) reduction(+ : moved)
      for (Eigen::Index i = 0; i < w; ++i) {
        const std::size_t ti = static_cast<std::size_t>(b + i);
        double best = std::numeric_limits<double>::infinity();
        int arg = assign[ti];
        for (int k = 0; k < K; ++k) {
          if (ck[static_cast<std::size_t>(k)] < 0) continue;
          double r = norms[Eigen::Index(ti)] - 2.0 * P(i, k) + mnorm[k];
          for (int j = 0; j < ck[static_cast<std::size_t>(k)]; ++j) {
            const double proj = double(P(i, K + Eigen::Index(k) * c + j)) - me(k, j);
            r -= proj * proj;
          }
          if (r < best) best = r, arg = k;
        }
        residual[ti] = std::max(best, 0.0);
        if (arg != assign[ti]) ++moved;
        assign[ti] = arg;
      }
    }
    return moved;
  };

  fit_clusters(fit, false);
  sum.iteration_errors.push_back(fit.error);
  sum.iteration_changes.push_back(0);
  rep.Info("lpca: initial clustering, relative error {:.5f}", fit.error);
  for (int it = 0; it < o.max_iterations; ++it) {
    rep.Progress(std::size_t(it), std::size_t(o.max_iterations), "lpca");
    ClusterFit next{{}, fit.assign, 0};
    const std::size_t moved = reassign(fit, next.assign);
    if (moved == 0) break;
    fit_clusters(next, true);
    sum.iteration_errors.push_back(next.error);
    sum.iteration_changes.push_back(static_cast<int>(moved));
    rep.Info("lpca: iteration {}: {} texels reassigned, relative error {:.5f}", it + 1, moved, next.error);
    const bool better = next.error < fit.error;
    const bool enough = fit.error - next.error >= o.min_improvement * fit.error;
    if (better) fit = std::move(next);
    if (!enough) break;
  }
  sum.times.Add("iterate", t.Seconds());

  // Codec arrays; the stride is the largest component count any cluster kept.
  LpcaModel& m = CodecBuilder::lpca(codec);
  int c = 0;
  for (const auto& p : fit.pca) c = std::max(c, p.components());
  m.clusters = K;
  m.components = c;
  m.means.assign(std::size_t(K) * d, 0.0f);
  m.basis.assign(std::size_t(K) * c * d, 0.0f);
  m.cluster_components.assign(static_cast<std::size_t>(K), 0);
  m.cluster_of = fit.assign;
  m.weights.assign(N * c, 0.0f);
  int small = 0, dropped = 0;
  std::vector<std::size_t> seen(static_cast<std::size_t>(K), 0);
  for (int k = 0; k < K; ++k) {
    const PcaResult& p = fit.pca[static_cast<std::size_t>(k)];
    sum.slot_components.push_back(p.components());
    if (p.mean.size() == 0) continue;
    if (p.clamped_to < std::min(o.components, int(d))) ++small;
    dropped += p.dropped_null;
    m.cluster_components[static_cast<std::size_t>(k)] = p.components();
    std::copy(p.mean.data(), p.mean.data() + d, m.means.data() + std::size_t(k) * d);
    std::copy(p.basis.data(), p.basis.data() + p.basis.size(), m.basis.data() + std::size_t(k) * c * d);
  }
  // Members are visited in texel order, as fit_clusters gathered them.
  for (std::size_t i = 0; i < N; ++i) {
    const int k = fit.assign[i];
    const PcaResult& p = fit.pca[static_cast<std::size_t>(k)];
    const std::size_t row = seen[static_cast<std::size_t>(k)]++;
    for (int j = 0; j < p.components(); ++j) m.weights[i * c + j] = p.scores(Eigen::Index(row), j);
  }
  if (small > 0) {
    sum.warnings.push_back(fmt::format("{} clusters have too few texels for {} components (clamped to members - 1)",
                                       small, o.components));
    rep.Warn("{}", sum.warnings.back());
  }
  if (dropped > 0) sum.warnings.push_back(fmt::format("{} components with ~0 eigenvalue dropped", dropped));
  sum.clusters = K;

  // Errors in the original domain: decode slot by slot against the input.
  t.Restart();
  ErrorAccumulator err;
  std::vector<float> ref(in.slot_size()), dec(in.slot_size());
  for (int v = 0; v < V; ++v) {
    in.read(v, ref.data());
    codec.DecodeViewSlot(v, dec.data());
    err.Add(ref.data(), dec.data(), ref.size());
  }
  err.Fill(sum);
  sum.times.Add("evaluate", t.Seconds());
}

Codec CompressInput(const SlotInput& input_full, const CompressOptions& options_in, const Reporter& rep,
                    CompressSummary* summary) {
  options_in.Check();
  CompressOptions o = options_in;
  CompressSummary sum;
  sum.input = input_full.name;
  SlotInput in = input_full;
  if (o.scene) {
    in = ApplyScene(input_full, *o.scene);
    if (o.scene->max_relative_error > 0 && o.target_error == 0 && o.retained_energy == 0)
      o.target_error = o.scene->max_relative_error;
    sum.scene_used = true;
    sum.input_views = input_full.views.size();
    sum.input_lights = input_full.lights.size();
    sum.input_height = input_full.height;
    sum.input_width = input_full.width;
    sum.input_channels = input_full.channels;
    rep.Info("scene keeps {} of {} views, {} of {} lights, {} x {} texels, {} channels", in.views.size(),
             input_full.views.size(), in.lights.size(), input_full.lights.size(), in.width, in.height, in.channels);
  }
  const Transform tr{o.log_transform, o.log_epsilon};
  Codec codec = CodecBuilder::Make(o.method, in.views, in.lights, in.height, in.width, in.channels, in.info,
                                   o.log_transform ? ValueTransform::kLog : ValueTransform::kNone,
                                   o.log_transform ? o.log_epsilon : 0.0);
  sum.method = MethodName(o.method);
  sum.views = in.views.size();
  sum.lights = in.lights.size();
  sum.height = in.height;
  sum.width = in.width;
  sum.channels = in.channels;
  if (o.method == CodecMethod::kPcaView)
    CompressPcaView(in, o, tr, codec, sum, rep);
  else
    CompressLpca(in, o, tr, codec, sum, rep);
  sum.components = 0;
  for (int c : sum.slot_components) sum.components = std::max(sum.components, c);
  sum.codec_bytes = codec.StoredBytes();
  sum.raw_float32_bytes = codec.RawBytes(4);
  sum.raw_half_bytes = codec.RawBytes(2);
  sum.ratio_float32 = sum.codec_bytes ? double(sum.raw_float32_bytes) / double(sum.codec_bytes) : 0;
  sum.ratio_half = sum.codec_bytes ? double(sum.raw_half_bytes) / double(sum.codec_bytes) : 0;
  if (sum.scene_used) {
    // What the full input would take with the same component counts (mean per slot/cluster).
    double cbar = 0;
    for (int c : sum.slot_components) cbar += c;
    cbar /= std::max<std::size_t>(sum.slot_components.size(), 1);
    const double Vf = sum.input_views, Lf = sum.input_lights, T = double(sum.input_height) * sum.input_width,
                 Cf = sum.input_channels;
    double values = 0;
    if (o.method == CodecMethod::kPcaView) {
      values = Vf * (T * Cf * (1 + cbar) + Lf * cbar);
    } else {
      const double K = codec.lpca().clusters, c = codec.lpca().components;
      values = K * (c + 1) * Vf * Lf * Cf + T * (c + 1) + K;
    }
    sum.full_codec_bytes = static_cast<std::uint64_t>(values * 4);
    sum.bytes_saved = sum.full_codec_bytes > sum.codec_bytes ? sum.full_codec_bytes - sum.codec_bytes : 0;
  }
  nlohmann::json prov;
  prov["options"] = {{"method", sum.method},
                     {"components", o.components},
                     {"clusters", o.clusters},
                     {"target_error", o.target_error},
                     {"retained_energy", o.retained_energy},
                     {"seed", o.seed},
                     {"log_transform", o.log_transform},
                     {"log_epsilon", o.log_epsilon},
                     {"max_iterations", o.max_iterations},
                     {"min_improvement", o.min_improvement},
                     {"gram_limit", o.gram_limit}};
  if (o.scene) prov["scene"] = o.scene->ToJson();
  prov["summary"] = sum.ToJson();
  CodecBuilder::provenance(codec) = prov;
  if (summary) *summary = std::move(sum);
  return codec;
}

}  // namespace

Codec Compress(const Dataset& dataset, const CompressOptions& options, const Reporter& reporter,
               CompressSummary* summary) {
  SlotInput in;
  in.name = "in-memory dataset";
  in.views = dataset.views();
  in.lights = dataset.lights();
  in.height = dataset.height();
  in.width = dataset.width();
  in.channels = dataset.channels();
  in.info = dataset.info();
  in.read = [&dataset](int v, float* out) {
    const auto s = dataset.view_slot(v);
    std::copy(s.begin(), s.end(), out);
  };
  return CompressInput(in, options, reporter, summary);
}

Codec CompressFile(const std::filesystem::path& dataset_path, const CompressOptions& options, const Reporter& reporter,
                   CompressSummary* summary) {
  options.Check();
  auto reader = std::make_shared<DatasetReader>(dataset_path);
  const DatasetHeader& h = reader->header();
  SlotInput in;
  in.name = dataset_path.string();
  in.views = h.views;
  in.lights = h.lights;
  in.height = h.height;
  in.width = h.width;
  in.channels = h.channels;
  in.info = h.info;
  in.read = [reader](int v, float* out) { reader->ReadViewSlot(v, out); };
  return CompressInput(in, options, reporter, summary);
}

}  // namespace btf
