// Per-view PCA (Sattler et al. 2003, section 4.1): per view slot, the light images are the
// observations; eigen-normtextures over texels, weights per light.
#include <atomic>
#include <exception>
#include <mutex>

#include <omp.h>

#include "libbtf/compress/method.h"
#include "libbtf/core/error.h"
#include "libbtf/core/timer.h"

namespace btf {

namespace {

// Decomposes one view slot into `slot` (WidePca: two tiled passes over the slot, no copy of it
// unless the log transform needs one); returns the errors of its reconstruction, measured on the
// tiles as WidePca reconstructs them.
ErrorStats CompressViewSlot(const MethodContext& ctx, int v, const float* raw, PcaViewSlot& slot, int* dropped) {
  const SlotSource& in = ctx.input;
  const ValueMap& tr = ctx.transform;
  const int L = in.lights().size();
  const std::size_t D = in.image_size(), n = in.slot_size();
  std::vector<float> transformed;
  if (tr.log()) {  // the log's domain check would misname a NaN: check finiteness first
    CheckFiniteSlot(in, v, raw);
    transformed.assign(raw, raw + n);
    tr.Apply(in.name(), v, transformed.data(), n);
  }
  ErrorStats e;
  std::vector<float> row;
  auto sink = [&](Eigen::Index c0, const Eigen::Ref<const RowMatrixXf>& rec) {
    row.resize(static_cast<std::size_t>(rec.cols()));
    for (Eigen::Index l = 0; l < rec.rows(); ++l) {
      const float* x = rec.row(l).data();  // row-major: the row is contiguous
      if (tr.log()) {
        for (Eigen::Index j = 0; j < rec.cols(); ++j) row[static_cast<std::size_t>(j)] = tr.Inverse(x[j]);
        x = row.data();
      }
      e.Add(raw + std::size_t(l) * D + std::size_t(c0), x, static_cast<std::size_t>(rec.cols()));
    }
  };
  WidePcaResult r = WidePca(tr.log() ? transformed.data() : raw, L, static_cast<Eigen::Index>(D),
                            MakeRequest(ctx.options, std::uint64_t(v)), ctx.options.storage == CodecStorage::kHalf, sink);
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

// The slots this rank decomposes, one slot per thread at a time (coarse-grained parallelism: no
// barrier per small GEMM, robust when the cores are shared), taken in turn from a shared
// counter; each thread reads its slot itself, one thread at a time (HDF5 is never called
// concurrently), so one thread reads and inflates while the other decomposes, on the same cores
// and without a reader thread of its own; a source that holds its slots in memory is read where
// it is (no copy). A slot's result does not depend on the thread that computes it. The first
// thread (the caller's) reports progress after each of its slots.
//
// With a writer (one process only), each slot goes to the file as soon as it and the slots
// before it are done, in view order, and its arrays are freed: at most one slot per thread waits
// in memory, and the kernel writes the codec back while the decomposition goes on.
class SlotRun {
 public:
  SlotRun(const MethodContext& ctx, std::vector<PcaViewSlot>& slots)
      : errors(slots.size()), dropped(slots.size(), 0), ctx_(ctx), slots_(slots), V_(int(slots.size())),
        finished_(slots.size(), 0) {
    for (int v = 0; v < V_; ++v)
      if (ctx.ranks.Owns(v)) mine_.push_back(v);
    BTF_CHECK(!ctx.writer || mine_.size() == std::size_t(V_));
  }

  // Returns the values written through the writer.
  std::uint64_t Run() {
    const int M = static_cast<int>(mine_.size());
    const int P = std::max(1, std::min(omp_get_max_threads(), M));
    failures_.assign(std::size_t(M), nullptr);
#pragma omp parallel num_threads(P)
    {
      omp_set_num_threads(1);  // Eigen and the reader's inflate sequential in this thread
      std::vector<float> buffer;
      for (int i = next_++; i < M && !stop_; i = next_++) {
        try {
          Slot(mine_[std::size_t(i)], buffer);
        } catch (...) {
          failures_[std::size_t(i)] = std::current_exception();
          stop_ = true;
        }
        const int finished = ++done_;
        if (omp_get_thread_num() == 0 && !stop_) try {
            ctx_.reporter.Progress(std::size_t(finished), std::size_t(M), "pca-view");
          } catch (...) {
            cancelled_ = std::current_exception();
            stop_ = true;
          }
      }
    }
    for (const auto& f : failures_)  // the first failed slot in order, whichever thread saw it first
      if (f) std::rethrow_exception(f);
    if (cancelled_) std::rethrow_exception(cancelled_);
    ctx_.reporter.Progress(std::size_t(M), std::size_t(M), "pca-view");
    return written_values_;
  }

  std::vector<ErrorStats> errors;  // per slot
  std::vector<int> dropped;        // per slot: components with ~0 eigenvalue

 private:
  void Slot(int v, std::vector<float>& buffer) {
    const float* raw = ctx_.input.ViewSlotData(v);
    if (!raw) {
      buffer.resize(ctx_.input.slot_size());
      const std::lock_guard<std::mutex> lock(reading_);
      ctx_.input.ReadViewSlot(v, buffer.data());
      raw = buffer.data();
    }
    const std::size_t u = static_cast<std::size_t>(v);
    errors[u] = CompressViewSlot(ctx_, v, raw, slots_[u], &dropped[u]);
    if (!ctx_.writer) return;
    const std::lock_guard<std::mutex> lock(reading_);  // HDF5 is never called concurrently
    finished_[u] = 1;
    for (; written_ < V_ && finished_[static_cast<std::size_t>(written_)]; ++written_) {
      PcaViewSlot& s = slots_[static_cast<std::size_t>(written_)];
      ctx_.writer->WritePcaViewSlot(written_, s);
      written_values_ += s.mean.size() + s.basis.size() + s.weights.size();
      s = PcaViewSlot{s.components, {}, {}, {}, {}};
    }
  }

  const MethodContext& ctx_;
  std::vector<PcaViewSlot>& slots_;
  const int V_;
  std::vector<int> mine_;
  std::mutex reading_;
  std::atomic<int> next_{0}, done_{0};
  std::atomic<bool> stop_{false};
  std::vector<std::exception_ptr> failures_;
  std::exception_ptr cancelled_;
  std::vector<char> finished_;
  int written_ = 0;
  std::uint64_t written_values_ = 0;
};

// Distributed: rank 0 receives the other ranks' slots in view order; they keep none.
void GatherSlots(const MethodContext& ctx, std::vector<PcaViewSlot>& slots, SlotRun& run) {
  const dist::Context& ranks = ctx.ranks;
  for (int v = 0; v < static_cast<int>(slots.size()); ++v) {
    const int owner = ranks.Owner(v);
    if (owner == 0) continue;
    const std::size_t i = static_cast<std::size_t>(v);
    if (ranks.rank() == owner) {
      ranks.SendBytes(0, v, PackSlot(slots[i], run.errors[i], run.dropped[i]));
      slots[i] = PcaViewSlot{};
    } else if (ranks.rank() == 0) {
      UnpackSlot(ranks.RecvBytes(owner, v), slots[i], run.errors[i], run.dropped[i]);
    }
  }
}

}  // namespace

// Distributed (docs/scaling.md): each rank decomposes and reads only the view slots it owns
// (round robin); rank 0 receives the others' slots in view order. A slot's decomposition does
// not depend on which rank computes it, and the errors are merged in slot order, so rank 0's
// codec and summary are those of the single-process run. The other ranks end with only their
// own slots. Returns the bytes of the slots written through the writer (the codec keeps only
// their component counts).
std::uint64_t CompressPcaView(const MethodContext& ctx, Codec& codec, CompressSummary& sum) {
  const CompressOptions& o = ctx.options;
  const int V = ctx.input.views().size(), L = ctx.input.lights().size();
  auto& slots = CodecBuilder::slots(codec);
  slots.resize(static_cast<std::size_t>(V));
  if (o.components > L - 1)
    ctx.Warn(sum, fmt::format("components {} clamped to {} per view slot (lights - 1: {} light images span at most {} "
                              "centred directions)",
                              o.components, std::max(L - 1, 0), L, std::max(L - 1, 0)));
  Timer t;
  SlotRun run(ctx, slots);
  const std::uint64_t written_values = run.Run();
  sum.times.Add("read+decompose", t.Seconds());
  if (ctx.ranks.distributed()) {
    t.Restart();
    GatherSlots(ctx, slots, run);
    sum.times.Add("gather", t.Seconds());
  }
  ErrorStats err;
  int dropped = 0;
  for (int v = 0; v < V; ++v) {  // merged in slot order: sums independent of thread and rank counts
    err.Merge(run.errors[static_cast<std::size_t>(v)]);
    dropped += run.dropped[static_cast<std::size_t>(v)];
    sum.slot_components.push_back(slots[static_cast<std::size_t>(v)].components);
  }
  if (dropped > 0) {
    sum.warnings.push_back(fmt::format("{} components with ~0 eigenvalue dropped (rank-deficient or constant slots)", dropped));
    ctx.reporter.Info("{}", sum.warnings.back());
  }
  FillErrors(err, sum);
  return written_values * (o.storage == CodecStorage::kHalf ? 2 : 4);
}

}  // namespace btf
