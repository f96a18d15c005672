// btf-synth speed: texel values per second of ground-truth BTF generation (Irawan 2006 twill)
// and photo rendering. A Bonn-size job (81 x 81 directions, 256 x 256 texels, 4 x 4 samples)
// is measured on a slice (one view, all 81 lights, 64 x 64 texels) and extrapolated.
//   naive     : Eval() per sample, one thread (the straightforward implementation)
//   batch_1t  : EvalBatch per texel row (per-pair work hoisted), one thread
//   batch     : EvalBatch, all cores (what btf-synth btf runs)
// Counters: texels/s (texel values per second), evals/s (model samples per second),
// bonn_s (extrapolated seconds for the full 81 x 81 x 256^2 job at 4 x 4 samples).
#include <benchmark/benchmark.h>
#include <omp.h>

#include "bench/bench_main.h"
#include "libbtf/synth/btf_generator.h"
#include "libbtf/synth/irawan2006.h"
#include "libbtf/synth/photo_synth.h"

namespace {

constexpr int kRes = 64, kSamples = 4;
constexpr double kBonnTexelValues = 81.0 * 81.0 * 256 * 256;

btf::BtfOptions SliceOptions() {
  btf::BtfOptions o;
  o.views = btf::Sampling::Bonn81().Subset({40});
  o.lights = btf::Sampling::Bonn81();
  o.resolution = kRes;
  o.samples = kSamples;
  return o;
}

void SetCounters(benchmark::State& state, double texel_values_per_iter) {
  const double evals = texel_values_per_iter * kSamples * kSamples;
  state.counters["texels/s"] = benchmark::Counter(texel_values_per_iter * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["evals/s"] = benchmark::Counter(evals * state.iterations(), benchmark::Counter::kIsRate);
  // time / (iterations * slice / bonn) = seconds for the whole Bonn-size job.
  state.counters["bonn_s"] = benchmark::Counter(texel_values_per_iter * state.iterations() / kBonnTexelValues,
                                                benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_BtfSlice_Naive(benchmark::State& state) {
  const auto model = btf::MakeIrawan2006Model("twill");
  const auto o = SliceOptions();
  std::vector<btf::Vec2> uv;
  for (int y = 0; y < kRes; ++y)
    for (int x = 0; x < kRes; ++x)
      for (int j = 0; j < kSamples; ++j)
        for (int i = 0; i < kSamples; ++i) uv.push_back(btf::TexelSampleUv(o, x, y, i, j));
  std::vector<float> out(static_cast<std::size_t>(o.lights.size()) * kRes * kRes * 3);
  for (auto _ : state) {
    for (int l = 0; l < o.lights.size(); ++l)
      for (int t = 0; t < kRes * kRes; ++t) {
        double acc[3] = {0, 0, 0};
        for (int s = 0; s < kSamples * kSamples; ++s) {
          float f[3];
          model->Eval(uv[static_cast<std::size_t>(t) * kSamples * kSamples + s], o.lights[l], o.views[0], f);
          for (int c = 0; c < 3; ++c) acc[c] += f[c];
        }
        for (int c = 0; c < 3; ++c) out[(static_cast<std::size_t>(l) * kRes * kRes + t) * 3 + c] = float(acc[c] / 16);
      }
    benchmark::DoNotOptimize(out.data());
  }
  SetCounters(state, double(o.lights.size()) * kRes * kRes);
}
BENCHMARK(BM_BtfSlice_Naive)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2);

void BM_BtfSlice_Batch(benchmark::State& state) {
  const int threads = static_cast<int>(state.range(0));
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads > 0 ? threads : saved);
  const auto model = btf::MakeIrawan2006Model("twill");
  const auto o = SliceOptions();
  std::vector<float> out(static_cast<std::size_t>(o.lights.size()) * kRes * kRes * 3);
  for (auto _ : state) {
    btf::GenerateViewSlot(*model, o, 0, out.data());
    benchmark::DoNotOptimize(out.data());
  }
  omp_set_num_threads(saved);
  SetCounters(state, double(o.lights.size()) * kRes * kRes);
}
// 1 = one thread, 0 = all cores.
BENCHMARK(BM_BtfSlice_Batch)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2);

void BM_Photo1280x960(benchmark::State& state) {
  const auto model = btf::MakeIrawan2006Model("twill");
  btf::PhotoOptions o;  // 1280 x 960, 3 x 3 samples per pixel
  const btf::Board board = btf::MakeBoard(o, model->tile_size_mm());
  const btf::Vec3 v = o.views[19], l = o.lights[9];
  const btf::CameraPose cam = btf::MakeCamera(o, board, v);
  for (auto _ : state) {
    auto img = btf::RenderPhoto(*model, board, o, cam, v, l);
    benchmark::DoNotOptimize(img.pixels.data());
  }
  state.counters["photos/s"] = benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Photo1280x960)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2);

}  // namespace

