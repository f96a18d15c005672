// btf-compress --method neural (neural_codec.h): one streaming pass over the view slots draws the
// training set (per view slot a seeded sample of (texel, light) pairs, values log-transformed),
// TrainNeural fits the latents and the decoder, the latents are quantised and the errors are
// measured on the codec as stored.
#include <algorithm>
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

// The training set: per view slot a sample of (texel, light) pairs, uniform with replacement,
// from a generator seeded by (seed, view) alone; targets are the transformed values.
NeuralSamples DrawSamples(const MethodContext& ctx) {
  const SlotSource& in = ctx.input;
  const int V = in.views().size(), L = in.lights().size(), C = in.channels();
  const std::int64_t T = std::int64_t(in.height()) * in.width(), N = ctx.options.neural.samples;
  CheckAllocation(4.0 * double(N) * (7 + C), "neural training samples");
  NeuralSamples s;
  s.texels = T;
  s.channels = C;
  s.texel.resize(std::size_t(N));
  s.wi.resize(3 * std::size_t(N));
  s.wo.resize(3 * std::size_t(N));
  s.target.resize(std::size_t(N) * C);
  std::vector<float> slot(in.slot_size());
  for (int v = 0; v < V; ++v) {
    ctx.reporter.Progress(std::size_t(v), std::size_t(V), "neural samples");
    in.ReadViewSlot(v, slot.data());
    ctx.transform.Apply(in.name(), v, slot.data(), slot.size());
    std::mt19937_64 rng(ctx.options.seed * 0x9E3779B97F4A7C15ull + std::uint64_t(v) * 0xD1B54A32D192ED03ull + 1);
    const auto below = [&](std::uint64_t n) { return std::uint64_t((unsigned __int128)rng() * n >> 64); };
    const Vec3 wo = in.views()[v].normalized();
    for (std::int64_t i = SlotBegin(N, v, V); i < SlotBegin(N, v + 1, V); ++i) {
      const std::uint64_t t = below(std::uint64_t(T));
      const int l = int(below(std::uint64_t(L)));
      const Vec3 wi = in.lights()[l].normalized();
      s.texel[std::size_t(i)] = std::int32_t(t);
      for (int k = 0; k < 3; ++k) {
        s.wi[3 * std::size_t(i) + k] = float(wi[k]);
        s.wo[3 * std::size_t(i) + k] = float(wo[k]);
      }
      const float* x = &slot[(std::size_t(l) * std::size_t(T) + t) * C];
      std::copy(x, x + C, &s.target[std::size_t(i) * C]);
    }
  }
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
  t.seed = o.seed;
  return t;
}

}  // namespace

std::uint64_t CompressNeural(const MethodContext& ctx, Codec& codec, CompressSummary& sum) {
  const CompressOptions& o = ctx.options;
  if (ctx.ranks.distributed()) ThrowUsage("the neural codec trains in one process (run it without MPI ranks)");
  if (o.target_error > 0 || o.retained_energy > 0)
    ThrowUsage("the neural codec takes --bytes or its own sizes, not an error or energy target (a scene's "
               "max_relative_error included)");
  Timer t;
  const NeuralSamples samples = DrawSamples(ctx);
  sum.times.Add("sample", t.Seconds());
  t.Restart();
  NeuralTrainSummary ts;
  const NeuralModel trained = TrainNeural(
      samples, TrainOptions(o),
      [&](std::int64_t step, std::int64_t total, double) {
        if (step % 16 == 0 || step == total) ctx.reporter.Progress(std::size_t(step), std::size_t(total), "neural training");
        return true;
      },
      &ts);
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
