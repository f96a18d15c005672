// The compressors: per-view PCA (streamed slot by slot) and local PCA (texel-major matrix,
// reassignment in texel blocks).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <fstream>
#include <limits>
#include <mutex>
#include <numeric>
#include <random>
#include <type_traits>

#include <omp.h>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/codec_writer.h"
#include "libbtf/compress/lpca_reassign.h"
#include "libbtf/compress/pca.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/error.h"
#include "libbtf/core/error_stats.h"
#include "libbtf/io/half.h"
#include "libbtf/io/slot_source.h"

namespace btf {

std::uint64_t LpcaMemoryLimit() {
  std::uint64_t limit = MaxAllocationBytes();
  std::ifstream meminfo("/proc/meminfo");
  std::string key;
  std::uint64_t kib = 0;
  while (meminfo >> key >> kib)
    if (key == "MemAvailable:") return std::min(limit, kib * 1024);
    else meminfo.ignore(std::numeric_limits<std::streamsize>::max(), '\n');
  return limit;
}

namespace {

// Keeps only what the scene uses: view/light subsets, a mip level (box filter over 2^m x 2^m
// texels; trailing rows/columns that do not fill a block are dropped), a channel subset.
class SceneSlotSource final : public SlotSource {
 public:
  SceneSlotSource(const SlotSource& in, const SceneSpec& scene)
      : in_(in),
        view_index_(NeededDirections(in.views(), scene.views)),
        light_index_(NeededDirections(in.lights(), scene.lights)),
        block_(1 << scene.mip_level) {
    const DatasetInfo in_info = in.info();
    if (scene.channels.empty()) {
      channel_index_.resize(static_cast<std::size_t>(in.channels()));
      std::iota(channel_index_.begin(), channel_index_.end(), 0);
    } else {
      for (const auto& name : scene.channels) {
        const auto it = std::find(in_info.channel_names.begin(), in_info.channel_names.end(), name);
        if (it == in_info.channel_names.end())
          ThrowBadInput("scene names channel '{}', which '{}' does not have (channels: {})", name, in.name(),
                        fmt::join(in_info.channel_names, ","));
        channel_index_.push_back(static_cast<int>(it - in_info.channel_names.begin()));
      }
    }
    if (in.height() < block_ || in.width() < block_)
      ThrowBadInput("scene mip level {} needs at least {} x {} texels; '{}' has {} x {}", scene.mip_level, block_,
                    block_, in.name(), in.width(), in.height());
    views_ = in.views().Subset(view_index_);
    lights_ = in.lights().Subset(light_index_);
    info_ = in_info;
    info_.channel_names.clear();
    for (int c : channel_index_) info_.channel_names.push_back(in_info.channel_names[static_cast<std::size_t>(c)]);
    info_.texel_size_mm = in_info.texel_size_mm * block_;
  }
  const std::string& name() const override { return in_.name(); }
  std::string kind() const override { return in_.kind(); }
  const Sampling& views() const override { return views_; }
  const Sampling& lights() const override { return lights_; }
  int height() const override { return in_.height() / block_; }
  int width() const override { return in_.width() / block_; }
  int channels() const override { return static_cast<int>(channel_index_.size()); }
  DatasetInfo info() const override { return info_; }
  void ReadViewSlot(int v, float* dst) const override {
    std::vector<float> buf(in_.slot_size());
    in_.ReadViewSlot(view_index_[static_cast<std::size_t>(v)], buf.data());
    const int b = block_, H = height(), W = width(), C = channels(), iW = in_.width(), iC = in_.channels();
    const double norm = 1.0 / (double(b) * b);
    for (std::size_t l = 0; l < light_index_.size(); ++l) {
      const float* img = &buf[std::size_t(light_index_[l]) * in_.image_size()];
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          for (int c = 0; c < C; ++c) {
            double s = 0;
            for (int dy = 0; dy < b; ++dy)
              for (int dx = 0; dx < b; ++dx)
                s += img[(std::size_t(y * b + dy) * iW + (x * b + dx)) * iC +
                         channel_index_[static_cast<std::size_t>(c)]];
            dst[((l * H + y) * std::size_t(W) + x) * C + c] = static_cast<float>(s * norm);
          }
    }
  }

 private:
  const SlotSource& in_;
  std::vector<int> view_index_, light_index_, channel_index_;
  int block_;
  Sampling views_, lights_;
  DatasetInfo info_;
};

struct Transform {
  bool log = false;
  double eps = 0;
  // Transforms in place; refuses values the log cannot take.
  void Apply(const SlotSource& in, int v, float* data, std::size_t n) const {
    if (!log) return;
    for (std::size_t i = 0; i < n; ++i) {
      if (!(data[i] > -eps))
        ThrowBadInput("'{}' view {}: value {} is <= -epsilon ({}), outside the log transform's domain; raise "
                      "--log-epsilon or drop --log",
                      in.name(), v, data[i], eps);
      data[i] = static_cast<float>(std::log(double(data[i]) + eps));
    }
  }
  float Invert(float y) const { return log ? static_cast<float>(std::exp(double(y)) - eps) : y; }
};

// Errors in the original domain (the summary's definitions are ErrorStats').
void FillErrors(const ErrorStats& e, CompressSummary& s) {
  s.rmse = e.Rmse();
  s.relative_error = e.RelativeL2().value_or(0.0);
  s.max_abs_error = e.max_abs_error;
  s.psnr_peak = e.max_abs_reference;
  s.psnr_db = e.PsnrDb(e.max_abs_reference).value_or(std::numeric_limits<double>::infinity());
}

// Errors of a codec in the original domain (lpca, lpca-tensor, fmf, dfmf): decode slot by slot
// against the input, one image per task, merged in (view, light) order. Distributed, each rank
// decodes and reads the view slots it owns (round robin) and every rank merges every image's
// sums in the same order.
ErrorStats MeasureErrors(const SlotSource& in, const Codec& codec) {
  const int V = in.views().size(), L = in.lights().size();
  const std::size_t image = in.image_size();
  std::vector<ErrorStats> per_image(std::size_t(V) * L);
  std::vector<float> ref(in.slot_size()), dec(in.slot_size());
  for (int v = 0; v < V; ++v) {
    if (!dist::Owns(v)) continue;
    in.ReadViewSlot(v, ref.data());
    codec.DecodeViewSlot(v, dec.data());
#pragma omp parallel for schedule(static)
    for (int l = 0; l < L; ++l)
      per_image[std::size_t(v) * L + l].Add(ref.data() + l * image, dec.data() + l * image, image);
  }
  if (dist::Distributed()) {
    std::vector<ErrorStats> mine;
    for (int v = dist::Rank(); v < V; v += dist::Size())
      mine.insert(mine.end(), per_image.begin() + std::ptrdiff_t(v) * L, per_image.begin() + std::ptrdiff_t(v + 1) * L);
    const std::vector<ErrorStats> all = dist::AllGatherConcat(mine);
    std::size_t at = 0;
    for (int r = 0; r < dist::Size(); ++r)
      for (int v = r; v < V; v += dist::Size())
        for (int l = 0; l < L; ++l) per_image[std::size_t(v) * L + l] = all[at++];
    BTF_CHECK(at == all.size());
  }
  ErrorStats err;
  for (const auto& e : per_image) err.Merge(e);
  return err;
}

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

// Decomposes one view slot into `slot` (WidePca: two tiled passes over the slot, no copy of it
// unless the log transform needs one); returns the errors of its reconstruction, measured on the
// tiles as WidePca reconstructs them.
ErrorStats CompressViewSlot(const SlotSource& in, int v, const float* raw, const CompressOptions& o,
                            const Transform& tr, PcaViewSlot& slot, int* dropped) {
  const int L = in.lights().size();
  const std::size_t D = in.image_size(), n = in.slot_size();
  std::vector<float> transformed;
  if (tr.log) {  // the log's domain check would misname a NaN: check finiteness first
    CheckFiniteSlot(in, v, raw);
    transformed.assign(raw, raw + n);
    tr.Apply(in, v, transformed.data(), n);
  }
  ErrorStats e;
  std::vector<float> row;
  auto sink = [&](Eigen::Index c0, const Eigen::Ref<const RowMatrixXf>& rec) {
    row.resize(static_cast<std::size_t>(rec.cols()));
    for (Eigen::Index l = 0; l < rec.rows(); ++l) {
      const float* x = rec.row(l).data();  // row-major: the row is contiguous
      if (tr.log) {
        for (Eigen::Index j = 0; j < rec.cols(); ++j) row[static_cast<std::size_t>(j)] = tr.Invert(x[j]);
        x = row.data();
      }
      e.Add(raw + std::size_t(l) * D + std::size_t(c0), x, static_cast<std::size_t>(rec.cols()));
    }
  };
  WidePcaResult r = WidePca(tr.log ? transformed.data() : raw, L, static_cast<Eigen::Index>(D),
                            MakeRequest(o, std::uint64_t(v)), o.storage == CodecStorage::kHalf, sink);
  if (r.non_finite >= 0) CheckFiniteSlot(in, v, raw);  // throws, naming the item
  BTF_CHECK(r.non_finite < 0);
  *dropped = r.dropped_null;
  slot.components = r.components;
  slot.mean = std::move(r.mean);
  slot.basis = std::move(r.basis);
  slot.weights = std::move(r.weights);
  slot.eigenvalues = std::move(r.eigenvalues);
  return e;
}

// One view slot's decomposition and the errors of its reconstruction, as bytes (distributed runs).
std::vector<std::uint8_t> PackSlot(const PcaViewSlot& s, const ErrorStats& e, int dropped) {
  dist::Packer p;
  p.Put(s.components);
  p.Put(e);
  p.Put(dropped);
  p.PutVector(s.mean);
  p.PutVector(s.basis);
  p.PutVector(s.weights);
  p.PutVector(s.eigenvalues);
  return std::move(p.bytes);
}

void UnpackSlot(const std::vector<std::uint8_t>& bytes, PcaViewSlot& s, ErrorStats& e, int& dropped) {
  dist::Unpacker u(bytes);
  s.components = u.Get<int>();
  e = u.Get<ErrorStats>();
  dropped = u.Get<int>();
  s.mean = u.GetVector<float>();
  s.basis = u.GetVector<float>();
  s.weights = u.GetVector<float>();
  s.eigenvalues = u.GetVector<double>();
}

// Distributed (docs/scaling.md): each rank decomposes and reads only the view slots it owns
// (round robin); rank 0 receives the others' slots in view order. A slot's decomposition does
// not depend on which rank computes it, and the errors are merged in slot order, so rank 0's
// codec and summary are those of the single-process run. The other ranks end with only their
// own slots.
//
// With a writer (one process only), each slot goes to the file as soon as it and the slots before
// it are done, in view order, and its arrays are freed: at most one slot per thread waits in
// memory, and the kernel writes the codec back while the decomposition goes on. Returns the
// bytes of the slots so written (the codec keeps only their component counts).
std::uint64_t CompressPcaView(const SlotSource& in, const CompressOptions& o, const Transform& tr, Codec& codec,
                              CompressSummary& sum, const Reporter& rep, CodecFileWriter* writer) {
  const int V = in.views().size(), L = in.lights().size();
  const std::size_t n = in.slot_size();
  auto& slots = CodecBuilder::slots(codec);
  slots.resize(static_cast<std::size_t>(V));
  if (o.components > L - 1) {
    sum.warnings.push_back(fmt::format("components {} clamped to {} per view slot (lights - 1: {} light images span "
                                       "at most {} centred directions)",
                                       o.components, std::max(L - 1, 0), L, std::max(L - 1, 0)));
    if (dist::Rank() == 0) rep.Warn("{}", sum.warnings.back());
  }
  std::vector<int> mine;  // the slots this rank decomposes
  for (int v = 0; v < V; ++v)
    if (dist::Owns(v)) mine.push_back(v);
  const int M = static_cast<int>(mine.size());
  std::vector<ErrorStats> slot_err(static_cast<std::size_t>(V));
  std::vector<int> slot_dropped(static_cast<std::size_t>(V), 0);
  Timer t;
  // One slot per thread at a time (coarse-grained parallelism: no barrier per small GEMM, robust
  // when the cores are shared), taken in turn from a shared counter; each thread reads its slot
  // itself, one thread at a time (HDF5 is never called concurrently), so one thread reads and
  // inflates while the other decomposes, on the same cores and without a reader thread of its
  // own; a source that holds its slots in memory is read where it is (no copy). A slot's result
  // does not depend on the thread that computes it. The first thread (the caller's) reports
  // progress after each of its slots.
  const int P = std::max(1, std::min(omp_get_max_threads(), M));
  std::mutex reading;
  std::atomic<int> next{0}, done{0};
  std::atomic<bool> stop{false};
  std::vector<std::exception_ptr> failures(static_cast<std::size_t>(M));
  std::exception_ptr cancelled;
  BTF_CHECK(!writer || M == V);
  std::vector<char> finished_slot(static_cast<std::size_t>(V), 0);
  int written = 0;
  std::uint64_t written_values = 0;
#pragma omp parallel num_threads(P)
  {
    omp_set_num_threads(1);  // Eigen and the reader's inflate sequential in this thread
    std::vector<float> buffer;
    for (int i = next++; i < M && !stop; i = next++) {
      const int v = mine[static_cast<std::size_t>(i)];
      try {
        const float* raw = in.ViewSlotData(v);
        if (!raw) {
          buffer.resize(n);
          const std::lock_guard<std::mutex> lock(reading);
          in.ReadViewSlot(v, buffer.data());
          raw = buffer.data();
        }
        const std::size_t u = static_cast<std::size_t>(v);
        slot_err[u] = CompressViewSlot(in, v, raw, o, tr, slots[u], &slot_dropped[u]);
        if (writer) {  // under the reading lock: HDF5 is never called concurrently
          const std::lock_guard<std::mutex> lock(reading);
          finished_slot[u] = 1;
          for (; written < V && finished_slot[static_cast<std::size_t>(written)]; ++written) {
            PcaViewSlot& s = slots[static_cast<std::size_t>(written)];
            writer->WritePcaViewSlot(written, s);
            written_values += s.mean.size() + s.basis.size() + s.weights.size();
            s = PcaViewSlot{s.components, {}, {}, {}, {}};
          }
        }
      } catch (...) {
        failures[static_cast<std::size_t>(i)] = std::current_exception();
        stop = true;
      }
      const int finished = ++done;
      if (omp_get_thread_num() == 0 && !stop) try {
          rep.Progress(std::size_t(finished), std::size_t(M), "pca-view");
        } catch (...) {
          cancelled = std::current_exception();
          stop = true;
        }
    }
  }
  for (const auto& f : failures)  // the first failed slot in order, whichever thread saw it first
    if (f) std::rethrow_exception(f);
  if (cancelled) std::rethrow_exception(cancelled);
  sum.times.Add("read+decompose", t.Seconds());
  rep.Progress(std::size_t(M), std::size_t(M), "pca-view");
  if (dist::Distributed()) {
    t.Restart();
    for (int v = 0; v < V; ++v) {
      const int owner = dist::Owner(v);
      if (owner == 0) continue;
      const std::size_t i = static_cast<std::size_t>(v);
      if (dist::Rank() == owner) {
        dist::SendBytes(0, v, PackSlot(slots[i], slot_err[i], slot_dropped[i]));
        slots[i] = PcaViewSlot{};
      } else if (dist::Rank() == 0) {
        UnpackSlot(dist::RecvBytes(owner, v), slots[i], slot_err[i], slot_dropped[i]);
      }
    }
    sum.times.Add("gather", t.Seconds());
  }
  ErrorStats err;
  int dropped = 0;
  for (int v = 0; v < V; ++v) {  // merged in slot order: sums independent of thread and rank counts
    err.Merge(slot_err[static_cast<std::size_t>(v)]);
    dropped += slot_dropped[static_cast<std::size_t>(v)];
    sum.slot_components.push_back(slots[static_cast<std::size_t>(v)].components);
  }
  if (dropped > 0) {
    sum.warnings.push_back(fmt::format("{} components with ~0 eigenvalue dropped (rank-deficient or constant slots)", dropped));
    rep.Info("{}", sum.warnings.back());
  }
  FillErrors(err, sum);
  return written_values * (o.storage == CodecStorage::kHalf ? 2 : 4);
}

// ---------------------------------------------------------------------------------------------
// Local PCA (Mueller et al. 2003 as in Schneider 2004 section 3): k-means++ seeding, then rounds
// of per-cluster PCA and reassignment of every texel to the cluster that reconstructs it best.
struct ClusterFit {
  std::vector<PcaResult> pca;           // per cluster
  std::vector<std::int32_t> assign;     // per texel (sample rounds: per sample texel)
  double error = 0;                     // relative error (transformed domain)
  std::vector<std::vector<std::size_t>> members;  // per cluster, in order (the rows each PCA was fitted on)
};

// Members of each of K clusters (texel indices in order) under `assign`. An empty cluster takes
// the worst-fitted texel (largest residual; without residuals the first) of a cluster that can
// spare one, and `assign` is updated.
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
// code templated on it (k-means on the whole matrix).
class TexelMatrix {
 public:
  using HalfMatrix = Eigen::Matrix<Eigen::half, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  void Resize(std::size_t rows, std::size_t cols, bool half) {
    Clear();
    half_ = half;
    if (half_) h_.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
    else f_.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
  }
  void Clear() { f_.resize(0, 0), h_.resize(0, 0); }
  std::size_t cols() const { return std::size_t(half_ ? h_.cols() : f_.cols()); }
  // Row i's storage, to fill: float values, or half bits (half.h).
  float* FloatRow(std::size_t i) { return f_.row(static_cast<Eigen::Index>(i)).data(); }
  std::uint16_t* HalfRow(std::size_t i) { return reinterpret_cast<std::uint16_t*>(h_.row(static_cast<Eigen::Index>(i)).data()); }
  // out[0, cols()) = row i, as float.
  void CopyRow(std::size_t i, float* out) const { CopyRows(i, 1, out); }
  // X = rows [first, first + count), as float.
  void Rows(std::size_t first, std::size_t count, RowMatrixXf& X) const {
    X.resize(static_cast<Eigen::Index>(count), static_cast<Eigen::Index>(cols()));
    CopyRows(first, count, X.data());
  }
  template <typename F>
  decltype(auto) Visit(F&& f) const { return half_ ? f(h_) : f(f_); }

 private:
  void CopyRows(std::size_t first, std::size_t count, float* out) const {
    const std::size_t n = count * cols();
    if (half_) HalvesToFloats(reinterpret_cast<const std::uint16_t*>(h_.data()) + first * cols(), out, n);
    else std::copy_n(f_.data() + first * cols(), n, out);
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

// Distributed (docs/scaling.md): rank r owns a contiguous range of whole kRows texel blocks and
// reads, holds and reassigns only those texels; vectors of one value per texel (assignment,
// residual, norm) are shared by every rank. The k-means sample's rows are gathered on rank 0,
// which seeds and runs Lloyd as one process would and broadcasts the centers. Per round, each
// cluster's member rows are gathered in texel order on the rank that fits it, its PCA is
// computed there exactly as in one process and broadcast. Every sum keeps its single-process
// order, and every GEMM block its rows, so the codec is bit-identical for any number of ranks.
class LpcaCompressor {
 public:
  LpcaCompressor(const SlotSource& in, const CompressOptions& o, const Transform& tr, CompressSummary& sum,
                 const Reporter& rep)
      : in_(in), o_(o), tr_(tr), sum_(sum), rep_(rep),
        N_(std::size_t(in.height()) * in.width()),
        d_(std::size_t(in.views().size()) * in.lights().size() * in.channels()),
        R_(dist::Size()), rank_(dist::Rank()), t0_(TexelBegin(rank_)), t1_(TexelBegin(rank_ + 1)) {
    const double matrix = value_bytes() * double(N_) * double(d_), limit = double(LpcaMemoryLimit());
    ooc_ = o_.lpca_memory == "out-of-core" || (o_.lpca_memory == "auto" && R_ == 1 && matrix > limit);
    if (ooc_ && R_ > 1) ThrowUsage("--lpca-memory out-of-core runs on one rank (ranks split the texel matrix instead)");
    budget_ = limit / 2;  // out of core: the texel chunk, or one wave of clusters' rows
    chunk_ = std::max<std::size_t>(kRows, std::size_t(budget_ / (value_bytes() * double(d_))) / kRows * kRows);
    sum_.lpca_memory = ooc_ ? "out-of-core" : "in-core";
    sum_.lpca_matrix = o_.lpca_matrix;
  }

  // measure = false: no error pass (lpca-tensor measures its own codec).
  void Run(Codec& codec, bool measure = true) {
    Timer t;
    if (ooc_) {
      std::vector<double> all(N_);
      ForChunks([&] { std::copy(chunk_norms_.begin(), chunk_norms_.end(), all.begin() + std::ptrdiff_t(t0_)); });
      SetNorms(all);
    } else {
      ReadTexelMajor();
    }
    sum_.times.Add("read", t.Seconds());
    ClusterFit fit = InitialClustering();
    t.Restart();
    Iterate(fit);
    sum_.times.Add("iterate", t.Seconds());
    A_.Clear();  // the evaluation decodes the codec; the texel matrix is no longer needed
    StoreModel(fit, codec);
    residual_energy_ = fit.error * fit.error * total_;
    sum_.peak_rss_bytes = dist::PeakResidentBytes();
    if (!measure) return;
    t.Restart();
    FillErrors(MeasureErrors(in_, codec), sum_);
    ++sum_.lpca_passes;
    sum_.times.Add("evaluate", t.Seconds());
    sum_.peak_rss_bytes = dist::PeakResidentBytes();
  }

  // Of the transformed input: sum of squares, and the squared residual of the kept fit.
  double total_energy() const { return total_; }
  double residual_energy() const { return residual_energy_; }

 private:
  static constexpr std::size_t kRows = 256;      // texels per GEMM block (assignment, reassignment)
  static constexpr std::size_t kTile = 64;       // texels per transpose tile (ReadRows)
  static constexpr int kLloydRounds = 100;       // k-means rounds at most
  static constexpr double kLloydTolerance = 1e-5;  // stop when the objective improves by less (relative)
  // The reassignment sketch's span: each cluster's mean and its first basis row. On the 64^2
  // twill (k = 32, c = 8): 4.2 / 2.2 / 1.35 clusters compared per texel with 0 / 1 / 3 rows, for a
  // sketch of 32 / 64 / 128 dimensions (its cost, once: two GEMMs of that width); measured with
  // temporary builds (docs/btf-compress.md, "Pruned reassignment").
  static constexpr int kSketchBasisRows = 1;

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
    void Project(const RowMatrixXf& X, std::size_t first) { bounds.Project(X, g.data() + first * dims(), e.data() + first); }
    // Candidates of rows [first, first + count) (norm2: their squared norms).
    void Candidates(std::size_t first, std::size_t count, const double* norm2, std::vector<std::vector<int>>& out) const {
      bounds.Candidates(g.data() + first * dims(), e.data() + first, norm2, count, out);
    }
  };

  // First texel of rank r's range (whole blocks, ranges contiguous in rank order).
  std::size_t TexelBegin(int r) const {
    const std::size_t blocks = (N_ + kRows - 1) / kRows;
    return std::min(N_, blocks * std::size_t(r) / std::size_t(R_) * kRows);
  }
  std::size_t local() const { return t1_ - t0_; }
  bool half() const { return o_.lpca_matrix == "half"; }
  double value_bytes() const { return half() ? 2.0 : 4.0; }  // of the texel matrix
  void Warn(const std::string& w) const {
    sum_.warnings.push_back(w);
    if (rank_ == 0) rep_.Warn("{}", w);  // the same on every rank: reported once
  }

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
  void ReadRows(const std::vector<std::size_t>& texels, const std::vector<T*>& rows, double* norms = nullptr) const {
    static_assert(std::is_same_v<T, float> || std::is_same_v<T, std::uint16_t>);
    BTF_CHECK((std::is_same_v<T, float> || half()));
    const int V = in_.views().size(), L = in_.lights().size(), C = in_.channels();
    const std::size_t tiles = (texels.size() + kTile - 1) / kTile, run = kTile * std::size_t(C);
    const std::size_t part = std::size_t(L) * std::size_t(C);  // a row's values of one view
    std::vector<char> consecutive(tiles);
    for (std::size_t b = 0; b < tiles; ++b) {
      const std::size_t i0 = b * kTile, i1 = std::min(texels.size(), i0 + kTile);
      bool c = true;
      for (std::size_t i = i0; i < i1; ++i) c = c && texels[i] == texels[i0] + (i - i0);
      consecutive[b] = c;
    }
    // Per thread: one light's values of a tile (gathered, or half-rounded), as half bits, and the stage.
    const std::size_t threads = std::size_t(std::max(1, omp_get_max_threads()));
    std::vector<float> values(threads * run);
    std::vector<std::uint16_t> halves(half() ? threads * run : 0);
    std::vector<T> stages(threads * kTile * part);
    // Rows that miss texels of the slot (ranks, out-of-core chunks, samples) see only theirs
    // in the tiles: the slot is range-checked on its own then, so that every read of a slot
    // refuses what it holds beyond the half range, as one that covers it does.
    const bool covers = texels.size() == N_;
    std::vector<float> buffer;  // the slot, where the source does not hold it or the log changes it
    if (norms) std::fill(norms, norms + texels.size(), 0.0);
    for (int v = 0; v < V; ++v) {
      rep_.Progress(std::size_t(v), std::size_t(V), "read");
      const float* slot = tr_.log ? nullptr : in_.ViewSlotData(v);
      if (!slot) {
        buffer.resize(in_.slot_size());
        in_.ReadViewSlot(v, buffer.data());
        slot = buffer.data();
      }
      // With a half matrix and no log, the range check below also finds NaN and Inf (and
      // RefuseBeyondHalf names them as CheckFiniteSlot does), so the slot is not scanned twice.
      if (tr_.log || !half()) CheckFiniteSlot(in_, v, slot);
      tr_.Apply(in_, v, buffer.data(), buffer.size());  // (with the log, slot is the buffer)
      bool beyond = false;
      // channels: a compile-time 3 (RGB: the copies inlined) or C.
      const auto transpose = [&](auto channels) {
        const std::size_t cc = channels;
#pragma omp parallel for schedule(static) reduction(|| : beyond)
        for (std::ptrdiff_t b = 0; b < static_cast<std::ptrdiff_t>(tiles); ++b) {
          const std::size_t i0 = std::size_t(b) * kTile, i1 = std::min(texels.size(), i0 + kTile), w = (i1 - i0) * cc;
          const std::size_t th = std::size_t(omp_get_thread_num());
          float* own = values.data() + th * run;
          std::uint16_t* bits = half() ? halves.data() + th * run : nullptr;
          T* stage = stages.data() + th * kTile * part;
          bool any = false;
          for (int l = 0; l < L; ++l) {
            const float* from = slot + std::size_t(l) * N_ * cc;
            const float* x = from + texels[i0] * cc;  // the tile's values, as float
            if (!consecutive[std::size_t(b)]) {
              for (std::size_t i = i0; i < i1; ++i)
                for (std::size_t c = 0; c < cc; ++c) own[(i - i0) * cc + c] = from[texels[i] * cc + c];
              x = own;
            }
            if (half()) {
              FloatsToHalves(x, bits, w);
              for (std::size_t j = 0; j < w; ++j) any |= (bits[j] & 0x7c00u) == 0x7c00u;
              if (std::is_same_v<T, float> || norms) {  // the stored values, as float
                HalvesToFloats(bits, own, w);
                x = own;
              }
            }
            const T* stored;
            if constexpr (std::is_same_v<T, std::uint16_t>) stored = bits;
            else stored = x;
            for (std::size_t j = 0; j < i1 - i0; ++j)
              for (std::size_t c = 0; c < cc; ++c) stage[j * part + std::size_t(l) * cc + c] = stored[j * cc + c];
            if (!norms) continue;
            for (std::size_t i = i0; i < i1; ++i)
              for (std::size_t c = 0; c < cc; ++c) {
                const double y = x[(i - i0) * cc + c];
                norms[i] += y * y;
              }
          }
          for (std::size_t i = i0; i < i1; ++i) std::copy_n(stage + (i - i0) * part, part, rows[i] + std::size_t(v) * part);
          beyond = beyond || any;
        }
      };
      if (C == 3) transpose(std::integral_constant<std::size_t, 3>());
      else transpose(std::size_t(C));
      if (half() && (beyond || (!covers && std::any_of(slot, slot + in_.slot_size(), BeyondHalf))))
        RefuseBeyondHalf(v, slot);
    }
    ++sum_.lpca_passes;
  }

  // Whether x becomes an infinity in half (NaN, Inf, or |x| rounding past kHalfMax: |x| >= 65520).
  static bool BeyondHalf(float x) { return !(std::fabs(x) < 65520.0f); }

  // Throws for the first value of slot v (in slot order) beyond the half range: a NaN or Inf as
  // CheckFiniteSlot refuses it, another value naming it (every rank reads whole slots: all refuse).
  [[noreturn]] void RefuseBeyondHalf(int v, const float* slot) const {
    if (!tr_.log) CheckFiniteSlot(in_, v, slot);  // after the log, the slot is finite
    const std::size_t i = std::size_t(std::find_if(slot, slot + in_.slot_size(), BeyondHalf) - slot);
    const std::size_t C = std::size_t(in_.channels()), W = std::size_t(in_.width());
    ThrowBadInput("'{}' holds {} at view {}, light {}, texel (y {}, x {}), channel {}{}: beyond the half range (|x| <= "
                  "{}) of LPCA's texel matrix; use --lpca-matrix float (4 bytes a value instead of 2){}",
                  in_.name(), slot[i], v, i / (N_ * C), i / C % N_ / W, i / C % W, i % C,
                  tr_.log ? " (after the log transform)" : "", kHalfMax, tr_.log ? "" : " or --log");
  }

  // A = the rows of texels [t0_, t1_) (one pass); chunk_norms_ their squared norms.
  void LoadRows() {
    A_.Resize(local(), d_, half());
    std::vector<std::size_t> texels(local());
    std::iota(texels.begin(), texels.end(), t0_);
    chunk_norms_.resize(local());
    if (half()) {
      std::vector<std::uint16_t*> rows(local());
      for (std::size_t i = 0; i < local(); ++i) rows[i] = A_.HalfRow(i);
      ReadRows(texels, rows, chunk_norms_.data());
    } else {
      std::vector<float*> rows(local());
      for (std::size_t i = 0; i < local(); ++i) rows[i] = A_.FloatRow(i);
      ReadRows(texels, rows, chunk_norms_.data());
    }
  }

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

  void SetNorms(const std::vector<double>& all) {
    BTF_CHECK(all.size() == N_);
    norms_ = Eigen::Map<const Eigen::VectorXd>(all.data(), static_cast<Eigen::Index>(N_));
    total_ = norms_.sum();
    residual_.assign(N_, 0.0);
  }

  // Texel-major matrix A (this rank's texels x d, row = one texel's ABRDF), transformed; texel
  // norms (of every texel, on every rank).
  void ReadTexelMajor() {
    CheckAllocation(value_bytes() * double(local()) * double(d_),
                    R_ > 1 ? fmt::format("texel-major copy of '{}' for LPCA (texels {}-{} of {} on this rank)", in_.name(),
                                         t0_, t1_, N_)
                           : fmt::format("texel-major copy of '{}' for LPCA (--lpca-memory out-of-core streams it)", in_.name()));
    LoadRows();
    SetNorms(R_ > 1 ? dist::AllGatherConcat(chunk_norms_) : chunk_norms_);
  }

  // Runs f(first, count) over [0, m) in static blocks of kRows (the last one shorter), each
  // block on one thread with Eigen single-threaded: which thread takes a block changes nothing
  // in its result, so results do not depend on the thread count.
  template <typename F>
  static void ForBlocks(std::size_t m, F&& f) {
    const std::ptrdiff_t blocks = static_cast<std::ptrdiff_t>((m + kRows - 1) / kRows);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t b = 0; b < blocks; ++b) {
      omp_set_num_threads(1);  // this thread's own setting: Eigen stays sequential here
      const std::size_t first = std::size_t(b) * kRows;
      f(first, std::min<std::size_t>(kRows, m - first));
    }
  }

  // P = X right^T for X = the rows rows[first, first + count) of M, gathered as float (one
  // ForBlocks block: the GEMM of a block does not depend on the thread that runs it).
  template <typename Mat>
  static Eigen::MatrixXf GatheredProducts(const Mat& M, const std::size_t* rows, std::size_t first, std::size_t count,
                                          const RowMatrixXf& right) {
    RowMatrixXf X(static_cast<Eigen::Index>(count), M.cols());
    for (Eigen::Index i = 0; i < X.rows(); ++i) RowToFloat(M, static_cast<Eigen::Index>(rows[first + std::size_t(i)]), X.row(i).data());
    return X * right.transpose();
  }

  // For rows rows[0..m) of M: the nearest center (squared Euclidean distance, the lower index
  // on ties) and that distance (norms: of M's rows).
  template <typename Mat>
  static void NearestCenters(const Mat& M, const double* norms, const RowMatrixXf& centers,
                             const std::size_t* rows, std::size_t m, std::int32_t* assign, double* dist) {
    const Eigen::VectorXd cn = centers.cast<double>().rowwise().squaredNorm();
    ForBlocks(m, [&](std::size_t first, std::size_t count) {
      const Eigen::Index w = static_cast<Eigen::Index>(count);
      const Eigen::MatrixXf P = GatheredProducts(M, rows, first, count, centers);
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

  // Deterministic sample of max(lpca_sample, K) texels (sorted; all texels if fewer), drawn with the seed.
  std::vector<std::size_t> Sample(std::mt19937_64& rng) const {
    std::vector<std::size_t> sample(N_);
    std::iota(sample.begin(), sample.end(), std::size_t(0));
    const std::size_t size = std::max<std::size_t>(std::size_t(o_.lpca_sample), std::size_t(K_));
    if (N_ > size) {
      std::shuffle(sample.begin(), sample.end(), rng);
      sample.resize(size);
      std::sort(sample.begin(), sample.end());
    }
    return sample;
  }

  // Out of core: the rows of the sample texels, in sample order (one pass).
  RowMatrixXf ReadSampleRows(const std::vector<std::size_t>& sample) const {
    CheckAllocation(4.0 * double(sample.size()) * double(d_), fmt::format("k-means sample of '{}'", in_.name()));
    RowMatrixXf S(static_cast<Eigen::Index>(sample.size()), static_cast<Eigen::Index>(d_));
    std::vector<float*> rows(sample.size());
    for (std::size_t i = 0; i < sample.size(); ++i) rows[i] = S.row(Eigen::Index(i)).data();
    ReadRows(sample, rows);
    return S;
  }

  // The rows of the sample texels, in sample order, on rank 0 (the sample is sorted and the
  // ranks' ranges contiguous: each rank's sample rows are one run of the sample).
  RowMatrixXf GatherSampleRows(const std::vector<std::size_t>& sample) const {
    const auto lo = std::lower_bound(sample.begin(), sample.end(), t0_) - sample.begin();
    const auto hi = std::lower_bound(sample.begin(), sample.end(), t1_) - sample.begin();
    RowMatrixXf S;
    if (rank_ == 0) {
      CheckAllocation(4.0 * double(sample.size()) * double(d_), fmt::format("k-means sample of '{}' on rank 0", in_.name()));
      S.resize(static_cast<Eigen::Index>(sample.size()), static_cast<Eigen::Index>(d_));
      for (auto i = lo; i < hi; ++i) A_.CopyRow(sample[std::size_t(i)] - t0_, S.row(i).data());
      std::size_t at = std::size_t(hi);
      for (int r = 1; r < R_; ++r) {
        const std::size_t end = std::size_t(
            std::lower_bound(sample.begin(), sample.end(), TexelBegin(r + 1)) - sample.begin());
        dist::Recv(r, 1, S.data() + at * d_, (end - at) * d_ * sizeof(float));
        at = end;
      }
    } else {
      RowMatrixXf mine(hi - lo, static_cast<Eigen::Index>(d_));
      for (auto i = lo; i < hi; ++i) A_.CopyRow(sample[std::size_t(i)] - t0_, mine.row(i - lo).data());
      dist::Send(0, 1, mine.data(), std::size_t(mine.size()) * sizeof(float));
    }
    return S;
  }

  // k-means on a sample: k-means++ seeds, then Lloyd rounds (means in double, summed in sample
  // order) until no sample texel moves, the k-means objective improves by less than
  // kLloydTolerance (relative) or kLloydRounds. Then local-PCA rounds and split/merge steps on the
  // sample alone (SampleRounds; the sample is every texel when there are no more than
  // lpca_sample), every texel to the cluster whose sample model reconstructs it best, and the
  // first per-cluster PCA of all texels.
  ClusterFit InitialClustering() {
    K_ = o_.clusters;
    if (std::size_t(K_) > N_) {
      Warn(fmt::format("clusters {} clamped to the number of texels {}", K_, N_));
      K_ = static_cast<int>(N_);
    }
    std::mt19937_64 rng(o_.seed);
    const std::vector<std::size_t> sample = Sample(rng);
    const std::size_t S = sample.size();
    int rounds = 0;
    std::vector<PcaResult> models;  // the sample rounds' per-cluster models (no scores)
    std::vector<double> sample_errors, split_errors;
    // Phases: kmeans (the sample, seeds and Lloyd; on ranks other than 0 also the wait for rank 0's
    // sample rounds), sample_rounds, first_fit (the first assignment of all texels and their PCA).
    Timer t;
    double kmeans_s = 0;
    auto on_sample = [&](const auto& M, const double* norms, const std::vector<std::size_t>& rows) {
      std::vector<std::int32_t> assign;
      rounds = Lloyd(M, norms, rows, rng, assign);
      kmeans_s = t.Seconds();
      models = SampleRounds(M, norms, rows, std::move(assign), sample_errors, split_errors);
    };
    if (R_ == 1 && !ooc_) {
      A_.Visit([&](const auto& M) { on_sample(M, norms_.data(), sample); });
    } else {  // the sample's rows gathered (by rank 0, or in one pass out of core): the same Lloyd
      const RowMatrixXf rows = ooc_ ? ReadSampleRows(sample) : GatherSampleRows(sample);
      if (rank_ == 0) {
        std::vector<std::size_t> index(S);
        std::iota(index.begin(), index.end(), std::size_t(0));
        std::vector<double> norms(S);
        for (std::size_t i = 0; i < S; ++i) norms[i] = norms_[static_cast<Eigen::Index>(sample[i])];
        on_sample(rows, norms.data(), index);
      }
      dist::Broadcast(0, &rounds, sizeof rounds);
      if (R_ > 1) {  // every rank reassigns its texels with the sample models
        models.resize(static_cast<std::size_t>(K_));
        for (int k = 0; k < K_; ++k) {
          auto bytes = dist::BroadcastBytes(0, rank_ == 0 ? PackPca(models[std::size_t(k)]) : std::vector<std::uint8_t>());
          if (rank_ != 0) models[std::size_t(k)] = UnpackPca(bytes);
        }
        dist::Packer pe;
        pe.PutVector(sample_errors);
        pe.PutVector(split_errors);
        const std::vector<std::uint8_t> errors = dist::BroadcastBytes(0, rank_ == 0 ? std::move(pe.bytes) : std::vector<std::uint8_t>());
        dist::Unpacker u(errors);  // holds a reference to the bytes
        sample_errors = u.GetVector<double>();
        split_errors = u.GetVector<double>();
      }
    }
    if (kmeans_s == 0) kmeans_s = t.Seconds();
    sum_.times.Add("kmeans", kmeans_s);
    sum_.times.Add("sample_rounds", t.Seconds() - kmeans_s);
    t.Restart();
    ClusterFit fit;
    fit.assign.assign(N_, 0);
    Reassign(models, fit.assign);
    FitClusters(fit, true, nullptr, &models);
    sum_.times.Add("first_fit", t.Seconds());
    sum_.sample_errors = sample_errors;
    sum_.split_errors = split_errors;
    sum_.iteration_errors.push_back(fit.error);
    sum_.iteration_changes.push_back(0);
    rep_.Info("lpca: k-means on {} texels ({} Lloyd rounds), {} local-PCA rounds and {} split/merge trials on them, "
              "relative error {:.5f}",
              S, rounds, sample_errors.size() - 1, split_errors.size(), fit.error);
    return fit;
  }

  // The clusters with a model (a mean), in increasing order.
  static std::vector<int> Fitted(const std::vector<PcaResult>& pca) {
    std::vector<int> fitted;
    for (std::size_t k = 0; k < pca.size(); ++k)
      if (pca[k].mean.size() > 0) fitted.push_back(int(k));
    return fitted;
  }

  // Each of `count` rows of M (row i: M's row at_row(i)) to the cluster that reconstructs it best
  // (SubspaceResiduals), among `fitted` or, with candidates, among candidates[i]; the lowest index
  // on ties; a row keeps its cluster if it compares none. Per row: assign and residual updated,
  // changed (0/1) and compared (clusters) set. Per cluster, the rows that compare it are one batch.
  template <typename Mat, typename AtRow>
  static void BestClusters(const Mat& M, AtRow at_row, std::size_t count, const std::vector<PcaResult>& pca,
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

  // The sample rounds' reassignment sketch (o_.lpca_prune): built from the first fit of Lloyd's
  // clusters, with the sample texels' coordinates (sample order) and residuals.
  template <typename Mat>
  Sketch MakeSampleSketch(const Mat& M, const std::vector<std::size_t>& rows, const std::vector<PcaResult>& pca) const {
    Sketch s(pca, d_, rows.size());
    if (s.bounds.empty()) return s;
    ForBlocks(rows.size(), [&](std::size_t first, std::size_t count) {
      RowMatrixXf X(static_cast<Eigen::Index>(count), M.cols());
      for (Eigen::Index i = 0; i < X.rows(); ++i) RowToFloat(M, static_cast<Eigen::Index>(rows[first + std::size_t(i)]), X.row(i).data());
      s.Project(X, first);
    });
    return s;
  }

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
                                      std::vector<double>& split_errors) const {
    double energy = 0;
    for (std::size_t t : rows) energy += norms[t];
    std::vector<double> residual;
    ClusterFit fit{{}, std::move(assign), 0, {}};
    FitSample(M, rows, energy, residual, fit, nullptr);
    errors.push_back(fit.error);
    Sketch sketch;
    if (o_.lpca_prune) sketch = MakeSampleSketch(M, rows, fit.pca);
    RoundsOnSample(M, norms, rows, energy, residual, fit, &errors, sketch);
    for (int s = 0; s < o_.lpca_splits; ++s) {
      ClusterFit trial{{}, {}, 0, {}};
      if (!ProposeSplitMerge(M, norms, rows, fit, trial.assign)) break;
      FitSample(M, rows, energy, residual, trial, &fit);
      RoundsOnSample(M, norms, rows, energy, residual, trial, nullptr, sketch);
      split_errors.push_back(trial.error);
      const bool better = trial.error < fit.error;
      const bool enough = fit.error - trial.error >= o_.min_improvement * fit.error;
      if (better) fit = std::move(trial);
      if (!enough) break;
    }
    return std::move(fit.pca);
  }

  // SampleRounds' rounds from the fitted fit (kept: the best); errors (if given): the sample's
  // error after each fit.
  template <typename Mat>
  void RoundsOnSample(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, double energy,
                      std::vector<double>& residual, ClusterFit& fit, std::vector<double>* errors,
                      Sketch& sketch) const {
    for (int it = 0; it < o_.max_iterations; ++it) {
      ClusterFit next{{}, fit.assign, 0, {}};
      if (ReassignSample(M, norms, rows, fit.pca, next.assign, residual, sketch) == 0) break;
      FitSample(M, rows, energy, residual, next, &fit);
      if (errors) errors->push_back(next.error);
      const bool better = next.error < fit.error;
      const bool enough = fit.error - next.error >= o_.min_improvement * fit.error;
      if (better) fit = std::move(next);
      if (!enough) break;
    }
  }

  // A split/merge proposal from the sample fit f (its models and members): the cluster j with
  // the largest residual energy is split at its mean along its first component (the members
  // scoring above 0 leave it), and the cluster k != j whose removal costs least (summed over its
  // members: the squared residual under the best other cluster minus that under k) is emptied
  // into those other clusters and takes j's leaving members. assign: the proposal's sample
  // assignment. False (no proposal) when j has no component or one side of the split is empty.
  template <typename Mat>
  bool ProposeSplitMerge(const Mat& M, const double* norms, const std::vector<std::size_t>& rows, const ClusterFit& f,
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
    ForBlocks(S, [&](std::size_t first, std::size_t count) {
      const Eigen::Index w = static_cast<Eigen::Index>(count);
      const Eigen::MatrixXf P = GatheredProducts(M, rows.data(), first, count, model.big);
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

  // FitClusters on the sample (f.assign: per sample texel, members: sample positions); residual:
  // per sample texel after the last reassignment, empty before the first (then empty clusters
  // take the first sample texels of clusters that can spare one).
  template <typename Mat>
  void FitSample(const Mat& M, const std::vector<std::size_t>& rows, double energy,
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
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t kk = 0; kk < std::ptrdiff_t(order_k.size()); ++kk) {
      omp_set_num_threads(1);  // Eigen sequential in this cluster's task
      const int k = order_k[static_cast<std::size_t>(kk)];
      const auto& m = members[static_cast<std::size_t>(k)];
      const PcaRows x{static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_),
                      [&](Eigen::Index first, Eigen::Index count, float* out) {
                        for (Eigen::Index i = 0; i < count; ++i)
                          RowToFloat(M, static_cast<Eigen::Index>(rows[m[std::size_t(first + i)]]), out + std::size_t(i) * d_);
                      }};
      PcaResult p = Pca(x, MakeRequest(o_, std::uint64_t(k)), WarmStart(prev ? &prev->pca : nullptr, k));
      p.scores.resize(0, 0);
      f.pca[static_cast<std::size_t>(k)] = std::move(p);
    }
    double res = 0;
    for (const PcaResult& p : f.pca) res += p.residual_energy;
    f.error = energy > 0 ? std::sqrt(res / energy) : 0;
    f.members = std::move(members);
  }

  // Reassign on the sample: each sample texel (rows `rows` of M) to the cluster whose model
  // reconstructs it best (BestClusters, with the sketch's candidates unless it is empty), in
  // static blocks of kRows sample texels; returns the number moved.
  template <typename Mat>
  std::size_t ReassignSample(const Mat& M, const double* norms, const std::vector<std::size_t>& rows,
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

  // Seeds and Lloyd rounds on the rows `sample` of M (norms: of M's rows); returns the rounds.
  // assign: the sample texels' nearest centers.
  template <typename Mat>
  int Lloyd(const Mat& M, const double* norms, const std::vector<std::size_t>& sample, std::mt19937_64& rng,
            std::vector<std::int32_t>& assign) const {
    RowMatrixXf centers = SeedCenters(M, sample, rng);
    const std::size_t S = sample.size();
    std::vector<std::int32_t> next(S);
    assign.assign(S, -1);
    std::vector<double> dist(S);
    double objective = std::numeric_limits<double>::infinity();
    int rounds = 0;
    for (; rounds < kLloydRounds; ++rounds) {
      NearestCenters(M, norms, centers, sample.data(), S, next.data(), dist.data());
      const bool moved = next != assign;
      assign.swap(next);
      double obj = 0;
      for (double e : dist) obj += e;
      if (!moved || !(objective - obj > kLloydTolerance * obj)) break;
      objective = obj;
      UpdateMeans(M, sample, assign, dist, centers);
    }
    return rounds;
  }

  // Lloyd's update: each center the mean of its sample texels (double, in sample order, columns
  // split statically); an empty cluster takes the farthest sample texel of a cluster that can
  // spare one.
  template <typename Mat>
  void UpdateMeans(const Mat& M, const std::vector<std::size_t>& sample, std::vector<std::int32_t>& assign,
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

  // k-means++ seeds (D^2 sampling) on the sample.
  template <typename Mat>
  RowMatrixXf SeedCenters(const Mat& M, const std::vector<std::size_t>& sample, std::mt19937_64& rng) const {
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

  // A cluster's PCA as bytes: the model every rank needs, and the member scores for the codec.
  static std::vector<std::uint8_t> PackPca(const PcaResult& p) {
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
  static PcaResult UnpackPca(const std::vector<std::uint8_t>& bytes) {
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

  // Per-cluster PCA on the current assignment; empty clusters re-seeded from the worst texels. A
  // cluster whose members are those it had in `prev` keeps prev's PCA (the same rows in the same
  // order: its fit). warm (with o_.lpca_warm_start): per cluster, the model whose basis starts its
  // PCA (Pca's `start`; none where it has no components).
  void FitClusters(ClusterFit& f, bool have_residuals, const ClusterFit* prev, const std::vector<PcaResult>* warm) {
    std::vector<std::vector<std::size_t>> members = MembersFillingEmpty(f.assign, K_, have_residuals ? residual_.data() : nullptr);
    f.pca.assign(static_cast<std::size_t>(K_), PcaResult{});
    // Largest first (one cluster per thread, Eigen single-threaded inside the region); the
    // clusters that keep prev's PCA are left out.
    std::vector<int> order_k;
    for (int k = 0; k < K_; ++k) {
      const auto& m = members[static_cast<std::size_t>(k)];
      if (prev && !m.empty() && prev->members.size() == members.size() && prev->members[static_cast<std::size_t>(k)] == m)
        f.pca[static_cast<std::size_t>(k)] = prev->pca[static_cast<std::size_t>(k)];
      else
        order_k.push_back(k);
    }
    std::stable_sort(order_k.begin(), order_k.end(), [&](int a, int b) {
      return members[static_cast<std::size_t>(a)].size() > members[static_cast<std::size_t>(b)].size();
    });
    // The rank that fits each cluster: the least loaded so far (in texels), largest first.
    std::vector<int> owner(static_cast<std::size_t>(K_), 0);
    if (R_ > 1) {
      std::vector<std::size_t> load(static_cast<std::size_t>(R_), 0);
      for (int k : order_k) {
        const int r = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
        owner[static_cast<std::size_t>(k)] = r;
        load[static_cast<std::size_t>(r)] += members[static_cast<std::size_t>(k)].size();
      }
    }
    // Each rank fits its clusters (largest first) in waves of as many clusters as it has
    // threads (all of them in one process): per wave, the member rows held by other ranks are
    // gathered in (owner, cluster, sending rank) order, a fixed sequence of blocking transfers
    // (no deadlock), and the rank's own rows are copied when its cluster is fitted. Rows stay in
    // texel order. A rank so holds the rows of one wave's clusters at a time, not of all its
    // clusters.
    std::vector<std::vector<int>> owned(static_cast<std::size_t>(R_));
    for (int k : order_k)
      if (!members[static_cast<std::size_t>(k)].empty()) owned[static_cast<std::size_t>(owner[static_cast<std::size_t>(k)])].push_back(k);
    std::size_t wave = 0;  // clusters per rank and wave
    for (const auto& list : owned) wave = std::max(wave, list.size());
    if (R_ > 1) wave = std::size_t(std::max(1, omp_get_max_threads()));
    std::size_t waves = 0;
    for (const auto& list : owned) waves = std::max(waves, wave ? (list.size() + wave - 1) / wave : 0);
    // Out of core: waves of consecutive clusters (largest first) whose rows fit budget_, each
    // gathered in one pass over the slots. wave_end[w]: one past wave w's last index in the list.
    std::vector<std::size_t> wave_end;
    for (std::size_t w = 0; w < waves; ++w) wave_end.push_back(std::min(owned[std::size_t(rank_)].size(), (w + 1) * wave));
    if (ooc_) {
      wave_end.clear();
      double bytes = 0;
      const auto& list = owned[0];
      for (std::size_t j = 0; j < list.size(); ++j) {
        const double b = 4.0 * double(members[std::size_t(list[j])].size()) * double(d_);
        if (b > budget_)
          ThrowBadInput("out-of-core LPCA: cluster {} has {} texels ({:.3g} GiB of rows), over the wave budget of {:.3g} "
                        "GiB (half the memory limit {:.3g} GiB); use more clusters (-k) or raise BTF_MAX_BYTES",
                        list[j], members[std::size_t(list[j])].size(), b / double(1ull << 30),
                        budget_ / double(1ull << 30), 2 * budget_ / double(1ull << 30));
        if (j > 0 && bytes + b > budget_) wave_end.push_back(j), bytes = 0;
        bytes += b;
      }
      if (!list.empty()) wave_end.push_back(list.size());
      waves = wave_end.size();
    }
    std::vector<RowMatrixXf> X(static_cast<std::size_t>(K_));
    for (std::size_t w = 0; w < waves; ++w) {
      if (ooc_) ReadClusterRows(members, owned[0], w ? wave_end[w - 1] : 0, wave_end[w], X);
      for (int o = 0; o < R_ && R_ > 1; ++o) {
        const auto& list = owned[static_cast<std::size_t>(o)];
        for (std::size_t j = w * wave; j < std::min(list.size(), (w + 1) * wave); ++j) {
          const int k = list[j];
          const auto& m = members[static_cast<std::size_t>(k)];
          if (rank_ != o && !OwnsAny(m)) continue;
          if (rank_ == o)
            X[static_cast<std::size_t>(k)].resize(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_));
          for (int r = 0; r < R_; ++r) {
            if (r == o) continue;
            const std::size_t lo = std::size_t(std::lower_bound(m.begin(), m.end(), TexelBegin(r)) - m.begin());
            const std::size_t hi = std::size_t(std::lower_bound(m.begin(), m.end(), TexelBegin(r + 1)) - m.begin());
            if (lo == hi) continue;
            if (rank_ == o) {
              dist::Recv(r, 2, X[static_cast<std::size_t>(k)].data() + lo * d_, (hi - lo) * d_ * sizeof(float));
            } else if (rank_ == r) {
              RowMatrixXf rows(static_cast<Eigen::Index>(hi - lo), static_cast<Eigen::Index>(d_));
              for (std::size_t i = lo; i < hi; ++i)
                A_.CopyRow(m[i] - t0_, rows.row(Eigen::Index(i - lo)).data());
              dist::Send(o, 2, rows.data(), std::size_t(rows.size()) * sizeof(float));
            }
          }
        }
      }
      // Each cluster's PCA is computed by one thread alone (Eigen single-threaded inside the
      // region) and the residuals are summed in cluster order: the result does not depend on
      // which thread or rank took which cluster.
      const auto& list = owned[static_cast<std::size_t>(rank_)];
      const std::size_t last = std::min(list.size(), wave_end[w]), first = std::min(last, w ? wave_end[w - 1] : 0);
#pragma omp parallel for schedule(dynamic, 1)
      for (std::ptrdiff_t kk = std::ptrdiff_t(first); kk < std::ptrdiff_t(last); ++kk) {
        omp_set_num_threads(1);  // Eigen sequential in this cluster's task
        const int k = list[static_cast<std::size_t>(kk)];
        const auto& m = members[static_cast<std::size_t>(k)];
        const PcaRequest q = MakeRequest(o_, std::uint64_t(k));
        if (R_ == 1 && !ooc_) {  // in core, one process: the rows come from A_ a block at a time
          const PcaRows rows{static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_),
                             [&](Eigen::Index first, Eigen::Index count, float* out) {
                               for (Eigen::Index i = 0; i < count; ++i)
                                 A_.CopyRow(m[std::size_t(first + i)], out + std::size_t(i) * d_);
                             }};
          f.pca[static_cast<std::size_t>(k)] = Pca(rows, q, WarmStart(warm, k));
          continue;
        }
        RowMatrixXf& x = X[static_cast<std::size_t>(k)];
        if (x.rows() == 0) x.resize(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_));
        for (std::size_t i = 0; i < m.size() && !ooc_; ++i)
          if (m[i] >= t0_ && m[i] < t1_) A_.CopyRow(m[i] - t0_, x.row(Eigen::Index(i)).data());
        f.pca[static_cast<std::size_t>(k)] = Pca(x, q, WarmStart(warm, k));
        x.resize(0, 0);
      }
    }
    if (R_ > 1)  // every rank gets every cluster's model (and scores, for the codec)
      for (int k : order_k) {
        if (members[static_cast<std::size_t>(k)].empty()) continue;
        const int o = owner[static_cast<std::size_t>(k)];
        auto bytes = dist::BroadcastBytes(o, rank_ == o ? PackPca(f.pca[static_cast<std::size_t>(k)])
                                                        : std::vector<std::uint8_t>());
        if (rank_ != o) f.pca[static_cast<std::size_t>(k)] = UnpackPca(bytes);
      }
    double res = 0;
    for (const PcaResult& p : f.pca) res += p.residual_energy;
    f.error = total_ > 0 ? std::sqrt(res / total_) : 0;
    f.members = std::move(members);
  }

  // The basis that starts cluster k's PCA (FitClusters' `warm`), or none.
  const RowMatrixXf* WarmStart(const std::vector<PcaResult>* warm, int k) const {
    if (!o_.lpca_warm_start || !warm) return nullptr;
    const PcaResult& p = (*warm)[static_cast<std::size_t>(k)];
    return p.components() > 0 ? &p.basis : nullptr;
  }

  // Out of core: X[k] = the member rows (texel order) of clusters list[first, last), one pass.
  void ReadClusterRows(const std::vector<std::vector<std::size_t>>& members, const std::vector<int>& list,
                       std::size_t first, std::size_t last, std::vector<RowMatrixXf>& X) const {
    std::vector<std::size_t> texels;
    std::vector<float*> rows;
    for (std::size_t j = first; j < last; ++j) {
      const auto& m = members[static_cast<std::size_t>(list[j])];
      RowMatrixXf& x = X[static_cast<std::size_t>(list[j])];
      x.resize(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_));
      for (std::size_t i = 0; i < m.size(); ++i) texels.push_back(m[i]), rows.push_back(x.row(Eigen::Index(i)).data());
    }
    ReadRows(texels, rows);
  }

  // Whether this rank holds any of these (sorted) texels.
  bool OwnsAny(const std::vector<std::size_t>& texels) const {
    const auto it = std::lower_bound(texels.begin(), texels.end(), t0_);
    return it != texels.end() && *it < t1_;
  }

  // Reassigns each texel to the cluster that reconstructs it best (the lowest index on ties; a
  // texel keeps its cluster if none is fitted); returns the number moved. Each texel's residual
  // is computed (SubspaceResidual, from its stored row) under every cluster, or with
  // o_.lpca_prune under the candidates of the sketch's bounds (lpca_reassign.h; the sketch is
  // built at the first reassignment, from its models, with each texel's sketch coordinates),
  // which always hold the best: the same assignment either way.
  std::size_t Reassign(const std::vector<PcaResult>& pca, std::vector<std::int32_t>& assign) {
    const bool build = o_.lpca_prune && sketch_.e.empty();
    if (build) sketch_ = Sketch(pca, d_, N_);
    if (!sketch_.bounds.empty()) sketch_.bounds.SetClusters(pca);
    const std::vector<int> fitted = Fitted(pca);
    std::vector<std::uint8_t> changed(N_, 0);
    std::vector<std::uint32_t> compared(N_, 0);
    ForChunks([&] { A_.Visit([&](const auto& M) { ForBlocks(local(), [&](std::size_t b, std::size_t count) {
      const std::size_t t = t0_ + b;  // the block's first texel
      std::vector<std::vector<int>> candidates;
      if (!sketch_.bounds.empty()) {
        if (build) {
          RowMatrixXf X;
          A_.Rows(b, count, X);
          sketch_.Project(X, t);
        }
        sketch_.Candidates(t, count, norms_.data() + t, candidates);
      }
      BestClusters(M, [&](std::size_t i) { return Eigen::Index(b + i); }, count, pca, fitted,
                   sketch_.bounds.empty() ? nullptr : &candidates, assign.data() + t, residual_.data() + t, changed.data() + t,
                   compared.data() + t);
    }); }); });
    // Mean clusters compared per texel (this rank's texels; the sum of integers is exact).
    std::uint64_t pairs = std::accumulate(compared.begin(), compared.end(), std::uint64_t(0));
    if (R_ > 1) {
      std::uint64_t all = 0;
      for (std::uint64_t v : dist::AllGatherConcat(std::vector<std::uint64_t>{pairs})) all += v;
      pairs = all;
    }
    sum_.lpca_compared.push_back(N_ ? double(pairs) / double(N_) : 0.0);
    std::uint64_t moved = std::accumulate(changed.begin(), changed.end(), std::uint64_t(0));
    if (R_ > 1) {  // share this rank's texels' assignments and residuals
      const std::vector<std::int32_t> a =
          dist::AllGatherConcat(std::vector<std::int32_t>(assign.begin() + std::ptrdiff_t(t0_), assign.begin() + std::ptrdiff_t(t1_)));
      const std::vector<double> r = dist::AllGatherConcat(
          std::vector<double>(residual_.begin() + std::ptrdiff_t(t0_), residual_.begin() + std::ptrdiff_t(t1_)));
      BTF_CHECK(a.size() == N_ && r.size() == N_);
      assign = a;
      residual_ = r;
      moved = 0;
      for (std::uint64_t m : dist::AllGatherConcat(std::vector<std::uint64_t>{std::accumulate(
               changed.begin(), changed.end(), std::uint64_t(0))}))
        moved += m;
    }
    return static_cast<std::size_t>(moved);
  }

  // PCA/reassignment rounds until nothing moves, the error stops improving or max_iterations.
  void Iterate(ClusterFit& fit) {
    for (int it = 0; it < o_.max_iterations; ++it) {
      rep_.Progress(std::size_t(it), std::size_t(o_.max_iterations), "lpca");
      ClusterFit next{{}, fit.assign, 0, {}};
      const std::size_t moved = Reassign(fit.pca, next.assign);
      if (moved == 0) break;
      FitClusters(next, true, &fit, &fit.pca);
      sum_.iteration_errors.push_back(next.error);
      sum_.iteration_changes.push_back(static_cast<int>(moved));
      rep_.Info("lpca: iteration {}: {} texels reassigned, relative error {:.5f}", it + 1, moved, next.error);
      const bool better = next.error < fit.error;
      const bool enough = fit.error - next.error >= o_.min_improvement * fit.error;
      if (better) fit = std::move(next);
      if (!enough) break;
    }
  }

  // Codec arrays; the stride is the largest component count any cluster kept.
  void StoreModel(const ClusterFit& fit, Codec& codec) {
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

  const SlotSource& in_;
  const CompressOptions& o_;
  const Transform& tr_;
  CompressSummary& sum_;
  const Reporter& rep_;
  const std::size_t N_, d_;
  const int R_, rank_;          // ranks, this rank
  std::size_t t0_, t1_;         // this rank's texels [t0_, t1_) (out of core: the chunk in A_)
  bool ooc_ = false;            // out of core: A_ holds one chunk of chunk_ texels at a time
  double budget_ = 0;           // out of core: bytes of one chunk or one wave of cluster rows
  std::size_t chunk_ = 0;
  std::vector<double> chunk_norms_;  // squared norms of A_'s rows
  int K_ = 0;
  TexelMatrix A_;               // this rank's texels' rows
  Eigen::VectorXd norms_;       // every texel's squared norm
  double total_ = 0;
  double residual_energy_ = 0;
  std::vector<double> residual_;  // every texel's squared residual under its cluster (after Reassign)
  // The reassignment's sketch (o_.lpca_prune): built at the first reassignment, with every
  // texel's row (on each rank only its own texels' are set).
  Sketch sketch_;
};

// ---------------------------------------------------------------------------------------------
// LPCA with factorised Eigen-ABRDFs (lpca_tensor.h): the LPCA above, then FactoriseLpca. With
// --error (and no log transform) the codec's measured error is held to the target: quantisation
// adds error the prediction leaves out, so while the measured error is above the target the
// prediction's target is lowered by the gap (at most kTensorRounds factorisations).
void CompressLpcaTensor(const SlotSource& in, const CompressOptions& o, const Transform& tr, Codec& codec,
                        CompressSummary& sum, const Reporter& rep) {
  constexpr int kTensorRounds = 4;
  CompressOptions lo = o;
  lo.method = CodecMethod::kLpca;
  lo.target_error = 0, lo.retained_energy = 0, lo.max_bytes = 0;
  Codec stage = CodecBuilder::Make(CodecMethod::kLpca, in.views(), in.lights(), in.height(), in.width(), in.channels(),
                                   in.info(), codec.transform(), codec.log_epsilon());
  LpcaCompressor lc(in, lo, tr, sum, rep);
  lc.Run(stage, false);
  const double total = lc.total_energy(), residual = lc.residual_energy();
  sum.lpca_stage_error = total > 0 ? std::sqrt(residual / total) : 0;
  sum.quant_bits = o.quant_bits;
  TensorRequest q;
  q.bits = o.quant_bits, q.target_error = o.target_error, q.max_bytes = o.max_bytes, q.growth = o.tensor_growth;
  LpcaTensorModel& m = CodecBuilder::lpca_tensor(codec);
  ErrorStats e;
  bool all_kept = false;
  for (int round = 0; round < kTensorRounds; ++round) {
    Timer t;
    sum.predicted_error = FactoriseLpca(stage.lpca(), in.views().size(), in.lights().size(), in.channels(), total,
                                        residual, q, m);
    sum.times.Add("factorise", t.Seconds());
    t.Restart();
    e = MeasureErrors(in, codec);
    sum.times.Add("evaluate", t.Seconds());
    const double measured = e.RelativeL2().value_or(0.0);
    rep.Info("lpca-tensor: {} terms, predicted relative error {:.6g}, measured {:.6g}", m.terms(), sum.predicted_error,
             measured);
    if (!(o.target_error > 0) || tr.log || measured <= o.target_error || all_kept) break;
    const double gap = std::max(0.0, measured * measured - sum.predicted_error * sum.predicted_error);
    const double t2 = o.target_error * o.target_error - gap;
    // At or below the LPCA stage's error: every term (a tiny positive target keeps them all).
    all_kept = !(t2 > residual / total);
    q.target_error = all_kept ? 1e-150 : std::sqrt(t2);
  }
  if (o.target_error > 0 && !tr.log && e.RelativeL2().value_or(0.0) > o.target_error) {
    sum.warnings.push_back(fmt::format("lpca-tensor: relative error {:.6g} above --error {} (the LPCA stage alone has "
                                       "{:.6g}; raise --components or --clusters)",
                                       e.RelativeL2().value_or(0.0), o.target_error, sum.lpca_stage_error));
    rep.Warn("{}", sum.warnings.back());
  }
  sum.tensor_terms = static_cast<int>(m.terms());
  FillErrors(e, sum);
}

// --bytes for pca-view, lpca, fmf, dfmf: the largest c <= options.components whose codec cannot
// exceed the budget (sizes as Codec::StoredBytes counts them, at the unclamped c; clamping and
// dropped components only make a codec smaller).
int ComponentsWithin(const CompressOptions& o, const SlotSource& in) {
  const double V = in.views().size(), L = in.lights().size(), C = in.channels(),
               T = double(in.height()) * in.width(), D = T * C, bpv = o.storage == CodecStorage::kHalf ? 2 : 4;
  auto bytes = [&](double c) {
    switch (o.method) {
      case CodecMethod::kPcaView: c = std::min(c, std::max(L - 1, 0.0)); return V * (D + c * (D + L)) * bpv;
      case CodecMethod::kLpca: {
        const double K = std::min<double>(o.clusters, T);
        return (K * (c + 1) * V * L * C + T * c) * bpv + (T + K) * 4;
      }
      default: {
        const double M = o.method == CodecMethod::kDfmf ? 3 : 1, rows = V * L * C / M;
        c = std::min({c, rows, T});
        return M * c * (rows + T + 1) * 4;
      }
    }
  };
  const double B = double(o.max_bytes);
  if (bytes(1) > B)
    ThrowUsage("--bytes {} is below the smallest {} codec of this input ({:.0f} bytes at 1 component)", o.max_bytes,
               MethodName(o.method), bytes(1));
  int c = o.components;
  while (c > 1 && bytes(c) > B) --c;
  return c;
}

// What the full (scene-less) input would take with the same component counts (mean per
// slot/cluster), for the summary of a scene-reduced compression.
std::uint64_t FullCodecBytes(const CompressSummary& sum, const Codec& codec) {
  double cbar = 0;
  for (int c : sum.slot_components) cbar += c;
  cbar /= std::max<std::size_t>(sum.slot_components.size(), 1);
  const double Vf = sum.input_views, Lf = sum.input_lights, T = double(sum.input_height) * sum.input_width,
               Cf = sum.input_channels;
  double values = 0;
  if (codec.method() == CodecMethod::kLpcaTensor) {
    const LpcaTensorModel& m = codec.lpca_tensor();
    const double qb = m.bits / 8.0;
    return static_cast<std::uint64_t>(double(m.terms()) * ((Vf + Lf * Cf) * qb + 16) + T * (m.components * qb + 4) +
                                      double(m.clusters) * (1 + m.components) * 12);
  }
  if (codec.method() == CodecMethod::kPcaView) {
    values = Vf * (T * Cf * (1 + cbar) + Lf * cbar);
  } else if (IsFullMatrixFactorisation(codec.method())) {
    const double matrices = double(sum.slot_components.size()), rows = Vf * Lf * Cf / matrices;
    values = matrices * cbar * (rows + T + 1);
  } else {
    const double K = codec.lpca().clusters, c = codec.lpca().components;
    values = K * (c + 1) * Vf * Lf * Cf + T * (c + 1) + K;
  }
  return static_cast<std::uint64_t>(values * 4);
}

// Compress, and with `out` also the codec file (CompressToFile).
CompressSummary CompressAndWrite(const CompressOptions& options, const SlotSource& input_full, Codec* codec_out,
                                 AtomicOutput* out, const std::string& creator, const Reporter& rep) {
  options.Check();
  BTF_CHECK(codec_out != nullptr);
  CompressOptions o = options;
  CompressSummary sum;
  sum.input = input_full.name();
  std::unique_ptr<SlotSource> scene_input;
  if (o.scene) {
    scene_input = std::make_unique<SceneSlotSource>(input_full, *o.scene);
    if (o.scene->max_relative_error > 0 && o.target_error == 0 && o.retained_energy == 0)
      o.target_error = o.scene->max_relative_error;
    sum.scene_used = true;
    sum.input_views = input_full.views().size();
    sum.input_lights = input_full.lights().size();
    sum.input_height = input_full.height();
    sum.input_width = input_full.width();
    sum.input_channels = input_full.channels();
    rep.Info("scene keeps {} of {} views, {} of {} lights, {} x {} texels, {} channels", scene_input->views().size(),
             sum.input_views, scene_input->lights().size(), sum.input_lights, scene_input->width(),
             scene_input->height(), scene_input->channels());
  }
  const SlotSource& in = scene_input ? *scene_input : input_full;
  if (o.max_bytes > 0 && o.method != CodecMethod::kLpcaTensor) {
    const int c = ComponentsWithin(o, in);
    if (c < o.components) rep.Info("--bytes {}: {} components (of at most {})", o.max_bytes, c, o.components);
    o.components = c;
  }
  const Transform tr{o.log_transform, o.log_epsilon};
  Codec codec = CodecBuilder::Make(o.method, in.views(), in.lights(), in.height(), in.width(), in.channels(), in.info(),
                                   o.log_transform ? ValueTransform::kLog : ValueTransform::kNone,
                                   o.log_transform ? o.log_epsilon : 0.0);
  CodecBuilder::storage(codec) = o.storage;
  sum.method = MethodName(o.method);
  sum.storage = o.method == CodecMethod::kLpcaTensor ? fmt::format("uint{}", o.quant_bits) : StorageName(o.storage);
  sum.views = in.views().size();
  sum.lights = in.lights().size();
  sum.height = in.height();
  sum.width = in.width();
  sum.channels = in.channels();
  std::optional<CodecFileWriter> writer;
  if (out && o.method == CodecMethod::kPcaView && !dist::Distributed()) writer.emplace(*out, codec, creator);
  std::uint64_t streamed_bytes = 0;
  if (o.method == CodecMethod::kPcaView) {
    streamed_bytes = CompressPcaView(in, o, tr, codec, sum, rep, writer ? &*writer : nullptr);
  } else if (o.method == CodecMethod::kLpcaTensor) {
    CompressLpcaTensor(in, o, tr, codec, sum, rep);
  } else if (IsFullMatrixFactorisation(o.method)) {
    CompressFmf(in, o, [&](int v, float* x, std::size_t n) { tr.Apply(in, v, x, n); }, codec, sum, rep);
    Timer t;
    FillErrors(MeasureErrors(in, codec), sum);
    sum.times.Add("evaluate", t.Seconds());
  } else {
    LpcaCompressor(in, o, tr, sum, rep).Run(codec);
  }
  sum.components = 0;
  for (int c : sum.slot_components) sum.components = std::max(sum.components, c);
  sum.codec_bytes = streamed_bytes + codec.StoredBytes();
  sum.raw_float32_bytes = codec.RawBytes(4);
  sum.raw_half_bytes = codec.RawBytes(2);
  sum.ratio_float32 = sum.codec_bytes ? double(sum.raw_float32_bytes) / double(sum.codec_bytes) : 0;
  sum.ratio_half = sum.codec_bytes ? double(sum.raw_half_bytes) / double(sum.codec_bytes) : 0;
  if (sum.scene_used) {
    sum.full_codec_bytes = FullCodecBytes(sum, codec);
    sum.bytes_saved = sum.full_codec_bytes > sum.codec_bytes ? sum.full_codec_bytes - sum.codec_bytes : 0;
  }
  nlohmann::json prov;
  prov["options"] = o.ToJson();
  if (o.scene) prov["scene"] = o.scene->ToJson();
  prov["summary"] = sum.ToJson();
  CodecBuilder::provenance(codec) = prov;
  if (out) {  // timed in the returned summary only: the file holds the summary before it is written
    Timer t;
    if (writer) {
      writer->Finish(codec, codec.num_views());
    } else {
      WriteCodec(*out, codec, creator);
    }
    sum.times.Add("write", t.Seconds());
  }
  *codec_out = std::move(codec);
  return sum;
}

}  // namespace

CompressSummary Compress(const CompressOptions& options, const SlotSource& input, Codec* codec, const Reporter& rep) {
  return CompressAndWrite(options, input, codec, nullptr, {}, rep);
}

CompressSummary CompressToFile(const CompressOptions& options, const SlotSource& input, AtomicOutput* out,
                               const std::string& creator, const Reporter& rep) {
  Codec codec;
  return CompressAndWrite(options, input, &codec, out, creator, rep);
}

}  // namespace btf
