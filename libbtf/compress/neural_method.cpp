// btf-compress --method neural (neural_codec.h): one streaming pass over the view slots draws the
// training set (per view slot a seeded sample of (texel, light) pairs, values log-transformed),
// NeuralTrainer fits the latents and the decoder, the latents are quantised and the errors are
// measured on the codec as stored. Over MPI ranks: each rank draws the samples of the view slots
// it owns and all of them gather the whole set; training is data-parallel over the blocks of
// each step (Train); the codec is bit-identical for any number of ranks and threads.
#include <algorithm>
#include <climits>
#include <random>

#include "libbtf/compress/method.h"
#include "libbtf/compress/neural_codec.h"
#include "libbtf/core/error.h"
#include "libbtf/core/timer.h"

namespace btf {

namespace {

// Samples of view slot v: [N v / V, N (v + 1) / V) of the N in all, so that every slot gets its
// share whatever N is.
std::int64_t SlotBegin(std::int64_t n, int v, int views) {
  return static_cast<std::int64_t>((static_cast<unsigned __int128>(n) * unsigned(v)) / unsigned(views));
}

// Appends view slot v's samples to s: its share of the N in all, (texel, light) pairs uniform
// with replacement from a generator seeded by (seed, view) alone; targets are the transformed
// values (slot: the slot's values, transformed).
void AppendSlotSamples(const MethodContext& ctx, int v, const std::vector<float>& slot, NeuralSamples& s) {
  const SlotSource& in = ctx.input;
  const int V = in.views().size(), L = in.lights().size(), C = in.channels();
  const std::int64_t T = std::int64_t(in.height()) * in.width(), N = ctx.options.neural.samples;
  const std::int64_t begin = SlotBegin(N, v, V), count = SlotBegin(N, v + 1, V) - begin;
  const std::size_t at = s.texel.size();
  s.texel.resize(at + std::size_t(count));
  s.wi.resize(3 * s.texel.size());
  s.wo.resize(3 * s.texel.size());
  s.target.resize(std::size_t(C) * s.texel.size());
  std::mt19937_64 rng(ctx.options.seed * 0x9E3779B97F4A7C15ull + std::uint64_t(v) * 0xD1B54A32D192ED03ull + 1);
  const auto below = [&](std::uint64_t n) { return std::uint64_t((unsigned __int128)rng() * n >> 64); };
  const Vec3 wo = in.views()[v].normalized();
  for (std::size_t i = at; i < s.texel.size(); ++i) {
    const std::uint64_t t = below(std::uint64_t(T));
    const int l = int(below(std::uint64_t(L)));
    const Vec3 wi = in.lights()[l].normalized();
    s.texel[i] = std::int32_t(t);
    for (int k = 0; k < 3; ++k) {
      s.wi[3 * i + k] = float(wi[k]);
      s.wo[3 * i + k] = float(wo[k]);
    }
    const float* x = &slot[(std::size_t(l) * std::size_t(T) + t) * C];
    std::copy(x, x + C, &s.target[i * C]);
  }
}

template <typename T>
void Append(std::vector<T>& to, const std::vector<T>& values) {
  to.insert(to.end(), values.begin(), values.end());
}

// The training set, in view order. Distributed, in rounds of one view slot per rank: in round i
// rank r draws slot i R + r (the slot it owns), and every rank appends the round's samples
// gathered in rank order, that is in view order. Every rank ends with the one process's set.
NeuralSamples DrawSamples(const MethodContext& ctx) {
  const SlotSource& in = ctx.input;
  const dist::Context& ranks = ctx.ranks;
  const int V = in.views().size(), C = in.channels(), R = ranks.size();
  const std::int64_t N = ctx.options.neural.samples;
  CheckAllocation(4.0 * double(N) * (7 + C), "neural training samples");
  // A round's gathered targets must fit one MPI message (below 2^31 bytes).
  if (R > 1 && 4.0 * std::max(C, 3) * double((N + V - 1) / V) * R >= double(INT_MAX))
    ThrowUsage("--neural-samples {} over {} view slots: too many samples a view slot to gather over {} ranks "
               "(fewer samples or ranks)", N, V, R);
  NeuralSamples s, mine;
  s.texels = mine.texels = std::int64_t(in.height()) * in.width();
  s.channels = mine.channels = C;
  s.texel.reserve(std::size_t(N));
  s.wi.reserve(3 * std::size_t(N));
  s.wo.reserve(3 * std::size_t(N));
  s.target.reserve(std::size_t(N) * C);
  std::vector<float> slot(in.slot_size());
  for (int first = 0; first < V; first += R) {
    const int v = first + ranks.rank();  // ranks.Owns(v)
    NeuralSamples& out = R > 1 ? mine : s;
    mine.texel.clear(), mine.wi.clear(), mine.wo.clear(), mine.target.clear();
    if (v < V) {
      ctx.reporter.Progress(std::size_t(v), std::size_t(V), "neural samples");
      in.ReadViewSlot(v, slot.data());
      CheckFiniteSlot(in, v, slot.data());  // names the file and the slot (the log keeps an Inf)
      ctx.transform.Apply(in.name(), v, slot.data(), slot.size());
      AppendSlotSamples(ctx, v, slot, out);
    }
    if (R > 1) {
      Append(s.texel, ranks.AllGatherConcat(mine.texel));
      Append(s.wi, ranks.AllGatherConcat(mine.wi));
      Append(s.wo, ranks.AllGatherConcat(mine.wo));
      Append(s.target, ranks.AllGatherConcat(mine.target));
    }
  }
  BTF_CHECK(s.size() == N);
  ctx.reporter.Progress(std::size_t(V), std::size_t(V), "neural samples");
  return s;
}

NeuralTrainOptions TrainOptions(const CompressOptions& o) {
  NeuralTrainOptions t;
  t.latent = o.neural.latent;
  t.hidden = o.neural.hidden;
  t.encoding.fourier = o.neural.fourier;
  t.batch = o.neural.batch;
  t.block = std::min(t.block, t.batch);  // 256 samples a gradient block, or the whole (smaller) batch
  t.steps = o.neural.steps;
  t.epochs = o.neural.epochs;
  t.learning_rate = t.latent_learning_rate = o.neural.learning_rate;
  t.linear_loss = o.neural.linear_loss;
  t.seed = o.seed;
  return t;
}

// Per block of a step: its decoder gradient, texels, latent gradients, squared error and value
// count (all ranks run the same binary: raw bytes).
void PackBlocks(const std::vector<BlockGradient>& blocks, dist::Packer& p) {
  for (const BlockGradient& b : blocks) {
    p.PutVector(b.parameters);
    p.PutVector(b.texels);
    p.PutVector(b.latents);
    p.Put(b.squared_error);
    p.Put(b.values);
  }
}

void UnpackBlocks(const std::vector<std::uint8_t>& bytes, std::vector<BlockGradient>& blocks) {
  dist::Unpacker u(bytes);
  for (BlockGradient& b : blocks) {
    b.parameters = u.GetVector<float>();
    b.texels = u.GetVector<std::int32_t>();
    b.latents = u.GetVector<float>();
    b.squared_error = u.Get<double>();
    b.values = u.Get<std::int64_t>();
  }
}

// Data-parallel training: every rank holds all samples and the whole model. Of each step's B
// blocks rank r computes [B r / R, B (r + 1) / R) (a split by rank alone, whatever the threads),
// the ranks gather every block in block order (rank order is block order) and each applies the
// step with all of them. A block's gradient does not depend on who computes it and the step sums
// the blocks in block order, so the replicas stay bit-identical and equal to the one process's.
NeuralModel Train(const MethodContext& ctx, const NeuralSamples& samples, NeuralTrainSummary& ts) {
  NeuralTrainer trainer(samples, TrainOptions(ctx.options));
  const dist::Context& ranks = ctx.ranks;
  const std::int64_t B = trainer.blocks_per_step(), R = ranks.size(), r = ranks.rank();
  const int first = int(B * r / R), count = int(B * (r + 1) / R) - first;
  std::vector<BlockGradient> mine, all(static_cast<std::size_t>(B));
  ts.steps = trainer.steps();
  for (std::int64_t k = 0; k < trainer.steps(); ++k) {
    if (R > 1) {
      trainer.ComputeBlockGradients(first, count, &mine);
      dist::Packer p;
      PackBlocks(mine, p);
      UnpackBlocks(ranks.AllGatherConcat(p.bytes), all);
    } else {
      trainer.ComputeBlockGradients(0, int(B), &all);
    }
    const double loss = trainer.ApplyStep(all);
    if (k == 0) ts.first_loss = loss;
    ts.last_loss = loss;
    const std::int64_t step = k + 1, total = trainer.steps();
    if (step % 16 == 0 || step == total) ctx.reporter.Progress(std::size_t(step), std::size_t(total), "neural training");
  }
  return std::move(trainer.model());
}

}  // namespace

std::uint64_t CompressNeural(const MethodContext& ctx, Codec& codec, CompressSummary& sum) {
  const CompressOptions& o = ctx.options;
  if (o.target_error > 0 || o.retained_energy > 0)
    ThrowUsage("the neural codec takes --bytes or its own sizes, not an error or energy target (a scene's "
               "max_relative_error included)");
  Timer t;
  const NeuralSamples samples = DrawSamples(ctx);
  sum.times.Add("sample", t.Seconds());
  t.Restart();
  NeuralTrainSummary ts;
  const NeuralModel trained = Train(ctx, samples, ts);
  sum.times.Add("train", t.Seconds());
  NeuralCodecModel& m = CodecBuilder::neural(codec);
  m = NeuralCodecModel::FromTrained(trained, ParseLatentStorage(o.neural.latent_storage));
  sum.slot_components = {m.latent};
  sum.neural_samples = samples.size();
  sum.neural_steps = ts.steps;
  sum.neural_first_loss = ts.first_loss;
  sum.neural_last_loss = ts.last_loss;
  sum.neural_hidden = m.net.shape().hidden;
  sum.neural_parameters = m.net.parameter_count();
  ctx.reporter.Info("neural: {} samples, {} steps, loss {:.4g} -> {:.4g} (log domain)", samples.size(), ts.steps,
                    ts.first_loss, ts.last_loss);
  t.Restart();
  FillErrors(MeasureErrors(ctx.input, codec, ctx.ranks), sum);
  sum.times.Add("evaluate", t.Seconds());
  return 0;
}

}  // namespace btf
