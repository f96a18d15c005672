// The neural codec's core (libbtf/compress/neural_net.h):
//   BM_NeuralEigenGemm: Eigen's float GEMM at 1024^3 on one thread, the machine's yardstick
//     (bench_main.h, as in bench_compress);
//   BM_NeuralGemmShapes: the same products one training step makes (forward and backward of a
//     14-32-32-3 decoder over 16 blocks of 256 samples) as bare Eigen GEMMs: the best the step
//     can do with Eigen's kernels on these thin shapes;
//   BM_NeuralStep/threads: one training step (forward, backward, reduction, Adam) at batch 4096,
//     with its GFLOP/s as a fraction of both rates above (measured earlier in the same run) and
//     samples/s;
//   BM_NeuralDecode/hidden/threads: the codec's decoder (NeuralCodecModel::DecodeImages, what
//     Codec::DecodeViewSlot runs) over one view slot of 128 x 128 texels x 81 lights, RGB, latent 8,
//     two hidden layers of the given width: decoded values per second, and per core;
//   BM_NeuralFit/activation/encoding/steps: training on the synthetic lobes of
//     tests/compress/neural_lobes.h (64 texels x 256 direction pairs, batch 1024), one thread,
//     three seeds: the held-out RMSE (log domain; other direction pairs of the same texels) and
//     the seconds a training took (wall and CPU).
// Run: build/bin/bench_neural (--benchmark_filter=NeuralFit for the activation/encoding table).
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <string>

#include <Eigen/Core>
#include <benchmark/benchmark.h>

#include "bench/bench_main.h"
#include "libbtf/compress/neural_codec.h"
#include "libbtf/core/directions.h"
#include "libbtf/compress/neural_net.h"
#include "tests/compress/neural_lobes.h"

namespace {

using btf::Activation;

double& EigenRate() {  // GFLOP/s, 1024^3 float
  static double rate = 0;
  return rate;
}
double& ShapesRate() {  // GFLOP/s, the step's GEMM shapes
  static double rate = 0;
  return rate;
}

// The defaults: 8 latent values, the half vector (6 direction inputs), SiLU.
constexpr int kBatch = 4096, kBlock = 256, kLatent = 8;
const int kInputs = kLatent + btf::DirectionEncoding{}.Width();
const std::vector<int> kHidden{32, 32};

// Multiply-adds x 2 of one training step: per sample, forward W_l a (in x out each), backward
// dW_l = delta a^T (the same) and delta_{l-1} = W_l^T delta_l for every layer (the first one's
// gives the latent gradient).
double StepFlops() {
  const int widths[] = {kInputs, kHidden[0], kHidden[1], 3};
  double per_sample = 0;
  for (int l = 0; l < 3; ++l) per_sample += 3.0 * 2 * widths[l] * widths[l + 1];
  return per_sample * kBatch;
}

// One thread from here on (the shapes below and the fits run on one; BM_NeuralStep and
// BM_NeuralDecode set their own count and return to one).
void BM_NeuralEigenGemm(benchmark::State& st) {
  omp_set_num_threads(1);
  EigenRate() = btf::bench::EigenGemmRate<float>(st);
}
BENCHMARK(BM_NeuralEigenGemm)->Unit(benchmark::kMillisecond)->MinTime(2.0)->UseRealTime();

void BM_NeuralGemmShapes(benchmark::State& st) {
  const int w[] = {kInputs, kHidden[0], kHidden[1], 3};
  std::vector<Eigen::MatrixXf> W, A, Z, D, G, B;
  for (int l = 0; l <= 3; ++l) A.push_back(Eigen::MatrixXf::Random(w[l], kBlock));
  for (int l = 0; l < 3; ++l) {
    W.push_back(Eigen::MatrixXf::Random(w[l + 1], w[l]));
    Z.emplace_back(w[l + 1], kBlock);
    D.push_back(Eigen::MatrixXf::Random(w[l + 1], kBlock));
    G.push_back(Eigen::MatrixXf::Zero(w[l + 1], w[l]));
    B.emplace_back(w[l], kBlock);
  }
  double secs = 0;
  long reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    for (int block = 0; block < kBatch / kBlock; ++block)
      for (int l = 0; l < 3; ++l) {
        Z[l].noalias() = W[l] * A[l];
        G[l].noalias() += D[l] * A[l].transpose();
        B[l].noalias() = W[l].transpose() * D[l];
      }
    benchmark::DoNotOptimize(B[0].data());
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  ShapesRate() = StepFlops() * reps / secs / 1e9;
  st.counters["GFLOPs"] = ShapesRate();
  st.counters["of_eigen_1024"] = EigenRate() > 0 ? ShapesRate() / EigenRate() : 0;
}
BENCHMARK(BM_NeuralGemmShapes)->Unit(benchmark::kMicrosecond)->MinTime(2.0)->UseRealTime();

void BM_NeuralStep(benchmark::State& st) {
  const int threads = int(st.range(0));
  // 256 texels x 256 direction pairs; one epoch is 16 steps.
  const btf::NeuralSamples s = btf::test::LobeSamples(256, 256, 1);
  btf::NeuralTrainOptions o;
  o.batch = kBatch;
  o.block = kBlock;
  o.latent = kLatent;
  o.hidden = kHidden;
  o.steps = 1 << 30;
  btf::NeuralTrainer trainer(s, o);
  omp_set_num_threads(threads);
  std::vector<btf::BlockGradient> blocks;
  double secs = 0;
  long reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    trainer.ComputeBlockGradients(0, trainer.blocks_per_step(), &blocks);
    benchmark::DoNotOptimize(trainer.ApplyStep(blocks));
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  omp_set_num_threads(1);
  const double gflops = StepFlops() * reps / secs / 1e9;
  st.counters["GFLOPs"] = gflops;
  st.counters["samples_per_s"] = double(kBatch) * reps / secs;
  // Per core: the yardsticks are single-threaded.
  st.counters["of_eigen_1024"] = EigenRate() > 0 ? gflops / threads / EigenRate() : 0;
  st.counters["of_same_shapes"] = ShapesRate() > 0 ? gflops / threads / ShapesRate() : 0;
}
BENCHMARK(BM_NeuralStep)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->MinTime(2.0)->UseRealTime();

void BM_NeuralDecode(benchmark::State& st) {
  const int hidden = int(st.range(0)), threads = int(st.range(1));
  constexpr int kTexels = 128 * 128, kLights = 81;
  btf::NeuralCodecModel m;
  m.latent = kLatent;
  m.latents = Eigen::MatrixXf::Random(kLatent, kTexels);
  btf::NeuralNetShape shape;
  shape.inputs = kLatent + m.encoding.Width();
  shape.hidden = {hidden, hidden};
  shape.outputs = 3;
  m.net = btf::NeuralNet(shape, 1);
  std::vector<float> wi, wo;
  const btf::Sampling bonn = btf::Sampling::Bonn81();
  for (int l = 0; l < kLights; ++l)
    for (int k = 0; k < 3; ++k) wi.push_back(float(bonn[l][k])), wo.push_back(float(bonn[7][k]));
  std::vector<float> out(std::size_t(kLights) * kTexels * 3);
  omp_set_num_threads(threads);
  double secs = 0;
  long reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    m.DecodeImages(kLights, wi.data(), wo.data(), out.data());
    benchmark::DoNotOptimize(out.data());
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  omp_set_num_threads(1);
  const double values = double(out.size()) * double(reps) / secs;
  st.counters["values_per_s"] = values;
  st.counters["values_per_s_per_core"] = values / threads;
}
BENCHMARK(BM_NeuralDecode)
    ->ArgsProduct({{16, 32}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0)
    ->UseRealTime();

// The process's CPU seconds: on a shared machine, the time a one-thread training took without
// the waits for the CPU that other processes cause.
double CpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

// encoding: 0 wi/wo x,y; 1 + half vector; 2 + Fourier features (2 octaves); 3 both. Seeds 1, 2
// and 3 (the initial weights and latents, the sample order): the mean and the worst held-out
// RMSE, and the mean training time.
void BM_NeuralFit(benchmark::State& st) {
  const auto act = Activation(st.range(0));
  const int encoding = int(st.range(1));
  const btf::NeuralSamples train = btf::test::LobeSamples(64, 256, 1), held = btf::test::LobeSamples(64, 256, 2);
  btf::NeuralTrainOptions o;
  o.batch = 1024;
  o.steps = st.range(2);
  o.activation = act;
  o.encoding.half_vector = encoding & 1;
  o.encoding.fourier = encoding & 2 ? 2 : 0;
  omp_set_num_threads(1);
  constexpr int kSeeds = 3;
  double rmse = 0, worst = 0, secs = 0, cpu = 0;
  for (auto _ : st) {
    for (int seed = 1; seed <= kSeeds; ++seed) {
      o.seed = std::uint64_t(seed);
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = CpuSeconds();
      const btf::NeuralModel m = btf::TrainNeural(train, o);
      secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / kSeeds;
      cpu += (CpuSeconds() - c0) / kSeeds;
      const double r = btf::test::LobeRmse(m, held);
      rmse += r / kSeeds;
      worst = std::max(worst, r);
    }
  }
  st.SetLabel(std::string(btf::ActivationName(act)) + (o.encoding.half_vector ? "+half" : "") +
              (o.encoding.fourier ? "+fourier2" : ""));
  st.counters["held_out_rmse"] = rmse;
  st.counters["worst_seed"] = worst;
  st.counters["train_s"] = secs;
  st.counters["train_cpu_s"] = cpu;
}
BENCHMARK(BM_NeuralFit)
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1, 2, 3}, {3000}})
    ->Args({0, 1, 6000})
    ->Args({3, 1, 6000})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

}  // namespace

