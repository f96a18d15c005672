// btf-compress benchmarks (docs/performance.md): compression time per method,
// decode throughput, the dominant kernel's rate as a fraction of Eigen GEMM measured in the same
// run, and ratios against straightforward implementations (full SVD per slot; plain Lloyd
// k-means then full-SVD PCA per cluster).
//
// Size: 81 x 81 directions, RGB, BTF_BENCH_RES x BTF_BENCH_RES texels (default 64; 256 is the
// Bonn size, 5 GB in float32, needs about 12 GB of memory). The data is synthetic: per view slot
// rank 12 in light plus 1 % noise, and 8 texel materials, so both codecs have structure to find.
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <Eigen/SVD>
#include <chrono>
#include <cstring>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <sstream>

#include <omp.h>
#if defined(__x86_64__)
#include <immintrin.h>
#endif
#include <unistd.h>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/compress/gram_kernel.h"
#include "libbtf/compress/lpca_reassign.h"
#include "libbtf/compress/pca.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/half.h"
#include "bench/bench_main.h"
#include "bench/synthetic_btf.h"

namespace {

using btf::RowMatrixXf;

int Resolution() {
  const char* e = std::getenv("BTF_BENCH_RES");
  return e ? std::max(4, std::atoi(e)) : 64;
}

const btf::Dataset& Data() {
  static std::unique_ptr<btf::Dataset> d;
  if (d) return *d;
  const int n = Resolution();
  const btf::Sampling s = btf::Sampling::Bonn81();
  d = std::make_unique<btf::Dataset>(s, s, n, n, 3);
#pragma omp parallel for schedule(dynamic)
  for (int v = 0; v < 81; ++v) btf::bench::SyntheticViewSlot(s, n, v, d->image(v, 0).data());
  return *d;
}

void SetSizeCounters(benchmark::State& st) {
  const auto& d = Data();
  st.counters["texels"] = double(d.num_texels());
  st.counters["GB_float32"] = double(d.size()) * 4 / 1e9;
}

// Measured Eigen GEMM rate (float and double, 1024^3), the yardstick for kernel efficiency.
double& GemmRate(bool dbl) {
  static double rate[2] = {0, 0};
  return rate[dbl];
}

template <typename Scalar>
void BM_EigenGemm(benchmark::State& st) {
  GemmRate(sizeof(Scalar) == 8) = btf::bench::EigenGemmRate<Scalar>(st);
}
BENCHMARK_TEMPLATE(BM_EigenGemm, float)->Unit(benchmark::kMillisecond)->MinTime(2.0)->UseRealTime();
BENCHMARK_TEMPLATE(BM_EigenGemm, double)->Unit(benchmark::kMillisecond)->MinTime(2.0)->UseRealTime();

// The machine's double FMA peak on one core with the widest instruction set the per-view PCA
// kernels use (gram_kernel.h: AVX-512 where the CPU has it, else AVX2): independent FMA chains,
// no loads (24 x 8 or 12 x 4 doubles per step; the AVX2 loop takes twice the steps). Eigen's GEMM above is built for x86-64-v3 (AVX2), so on an AVX-512 CPU this peak, not
// the GEMM rate, is the yardstick for those kernels.
double& FmaPeakPerCore() {
  static double rate = 0;
  return rate;
}

#if defined(__x86_64__)
// 24 independent chains x = a x + b of `iters` FMAs each; returns one value so nothing is dropped.
__attribute__((target("avx512f"))) double Chains512(long iters) {
  const __m512d a = _mm512_set1_pd(1.0000001), b = _mm512_set1_pd(0.9999999);
  __m512d x[24];
  for (auto& v : x) v = _mm512_set1_pd(0.5);
  for (long it = 0; it < iters; ++it)
#pragma GCC unroll 24
    for (int k = 0; k < 24; ++k) x[k] = _mm512_fmadd_pd(a, x[k], b);
  for (int k = 1; k < 24; ++k) x[0] = _mm512_add_pd(x[0], x[k]);
  alignas(64) double lanes[8];  // not _mm512_reduce_add_pd: GCC 12 warns inside it (-Wuninitialized)
  _mm512_store_pd(lanes, x[0]);
  return lanes[0] + lanes[1] + lanes[2] + lanes[3] + lanes[4] + lanes[5] + lanes[6] + lanes[7];
}
__attribute__((target("avx2,fma"))) double Chains256(long iters) {
  const __m256d a = _mm256_set1_pd(1.0000001), b = _mm256_set1_pd(0.9999999);
  __m256d x[12];  // 16 registers: 12 chains (the FMA latency of 4 cycles x 2 ports needs 8)
  for (auto& v : x) v = _mm256_set1_pd(0.5);
  for (long it = 0; it < 2 * iters; ++it)
#pragma GCC unroll 12
    for (int k = 0; k < 12; ++k) x[k] = _mm256_fmadd_pd(a, x[k], b);
  for (int k = 1; k < 12; ++k) x[0] = _mm256_add_pd(x[0], x[k]);
  double out[4];
  _mm256_storeu_pd(out, x[0]);
  return out[0] + out[1] + out[2] + out[3];
}
#endif

void BM_FmaPeak(benchmark::State& st) {
#if defined(__x86_64__)
  const btf::KernelIsa isa = btf::BestKernelIsa();
  const int lanes = isa == btf::KernelIsa::kAvx512 ? 8 : 4;
  if (isa == btf::KernelIsa::kGeneric) {
    st.SkipWithError("no AVX2/AVX-512 on this CPU");
    return;
  }
  const long iters = 1 << 22;
  double secs = 0, sink = 0;
  int reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    sink += lanes == 8 ? Chains512(iters) : Chains256(iters);
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  benchmark::DoNotOptimize(sink);
  const double fmas = lanes == 8 ? 24.0 * 8 * double(iters) : 12.0 * 4 * 2 * double(iters);  // per call
  FmaPeakPerCore() = 2.0 * fmas * reps / secs / 1e9;
  st.SetLabel(btf::KernelIsaName(isa));
  st.counters["GFLOPs_per_core"] = FmaPeakPerCore();
#else
  st.SkipWithError("x86-64 only");
#endif
}
BENCHMARK(BM_FmaPeak)->Unit(benchmark::kMillisecond)->MinTime(1.0)->UseRealTime();

// Per-view PCA's Gram kernel (LaneGram, gram_kernel.h) on one thread: an 81-row tile of 256
// columns (L2-resident, as WidePca hands it) added 768 times (one Bonn-size slot), against the
// straightforward Eigen rank update of the lower triangle that WidePca used before. Arg: 0 the
// straightforward one, 1 LaneGram. Flops: n^2 w per tile (the lower triangle's multiply-adds x 2).
double g_eigen_gram_seconds = 0;
void BM_PcaViewGram(benchmark::State& st) {
  using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Index n = 81, w = btf::kWideTile, tiles = 768;
  const RowMatrixXd T = RowMatrixXd::Random(n, w);
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
  double secs = 0, sink = 0;
  int reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    if (st.range(0) == 0) {
      Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, n);
      for (Eigen::Index t = 0; t < tiles; ++t) G.selfadjointView<Eigen::Lower>().rankUpdate(T);
      sink += G(n - 1, 0);
    } else {
      btf::LaneGram g(n);
      for (Eigen::Index t = 0; t < tiles; ++t) g.Add(T.data(), w, w);
      sink += g.Reduce()(n - 1, 0);
    }
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  omp_set_num_threads(before);
  benchmark::DoNotOptimize(sink);
  const double gflops = double(n) * n * w * tiles * reps / secs / 1e9;
  st.SetLabel(st.range(0) == 0 ? "Eigen rankUpdate (before)" : std::string("LaneGram ") + btf::KernelIsaName(btf::BestKernelIsa()));
  st.counters["GFLOPs"] = gflops;
  if (GemmRate(true) > 0) st.counters["fraction_of_double_gemm_per_core"] = 2 * gflops / GemmRate(true);
  if (FmaPeakPerCore() > 0) st.counters["fraction_of_fma_peak"] = gflops / FmaPeakPerCore();
  if (st.range(0) == 0) g_eigen_gram_seconds = secs / reps;
  else if (g_eigen_gram_seconds > 0) st.counters["eigen_s_over_lanegram_s"] = g_eigen_gram_seconds / (secs / reps);
}
BENCHMARK(BM_PcaViewGram)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->MinTime(1.0)->UseRealTime();

std::unique_ptr<btf::Codec>& PcaCodec() {
  static std::unique_ptr<btf::Codec> c;
  return c;
}
std::unique_ptr<btf::Codec>& LpcaCodec() {
  static std::unique_ptr<btf::Codec> c;
  return c;
}
double g_pca_view_seconds_per_slot = 0;

void BM_PcaView(benchmark::State& st) {
  const auto& d = Data();
  btf::CompressOptions o;
  o.components = 16;
  o.storage = st.range(0) ? btf::CodecStorage::kHalf : btf::CodecStorage::kFloat;
  btf::CompressSummary s;
  const auto source = btf::MemorySource(d);
  btf::Codec half;  // the decode benchmarks below use the float codec
  for (auto _ : st) {
    if (st.range(0) == 0) PcaCodec() = std::make_unique<btf::Codec>();
    s = btf::Compress(o, *source, st.range(0) == 0 ? PcaCodec().get() : &half);
  }
  SetSizeCounters(st);
  st.SetLabel(s.storage);
  double decompose = 0;
  for (const auto& [name, sec] : s.times.phases())
    if (name == "read+decompose") decompose = sec;
  // Kernels per slot (WidePca): Gram, lower triangle (double, L^2 D / 2 multiply-adds), basis
  // rows (double, L c D), reconstruction for the errors (float, L c D): L^2 D + 4 L c D flops.
  const double L = 81, D = double(d.image_size()), c = 16;
  const double flops = 81 * (2 * L * L * D / 2 + 4 * L * c * D);
  st.counters["decompose_s"] = decompose;
  st.counters["kernel_GFLOPs"] = flops / decompose / 1e9;
  if (GemmRate(true) > 0) st.counters["fraction_of_double_gemm"] = flops / decompose / 1e9 / GemmRate(true);
  if (FmaPeakPerCore() > 0) st.counters["fraction_of_fma_peak"] = flops / decompose / 1e9 / (2 * FmaPeakPerCore());
  st.counters["relative_error"] = s.relative_error;
  st.counters["codec_MB"] = double(s.codec_bytes) / 1e6;
  st.counters["ratio_vs_float32"] = s.ratio_float32;
  st.counters["ratio_vs_half"] = s.ratio_half;
  if (st.range(0) == 0) g_pca_view_seconds_per_slot = s.times.Total() / 81;
  st.counters["seconds_per_slot"] = s.times.Total() / 81;
}
BENCHMARK(BM_PcaView)->Arg(0)->Arg(1)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// One view slot on one thread: the fused WidePca (Gram, basis, reconstruction handed to a sink
// that sums squared errors, as the compressor does) against the generic Pca path the compressor
// used before (centred copy, blocked Gram, basis re-orthonormalised by Householder QR, scores by
// projection) plus a separate decode for the errors. Arg: 0 WidePca, 1 generic Pca.
double g_wide_slot_seconds = 0;
void BM_PcaViewSlotKernel(benchmark::State& st) {
  const auto& d = Data();
  const auto slot = d.view_slot(40);
  const Eigen::Index L = 81, D = static_cast<Eigen::Index>(d.image_size());
  btf::PcaRequest q;
  q.max_components = 16;
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
  double err = 0, secs = 0;
  int reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    if (st.range(0) == 0) {
      btf::WidePca(slot.data(), L, D, q, false, [&](Eigen::Index c0, const Eigen::Ref<const RowMatrixXf>& rec) {
        const Eigen::Map<const RowMatrixXf, 0, Eigen::OuterStride<>> x(slot.data() + c0, L, rec.cols(),
                                                                          Eigen::OuterStride<>(D));
        err += (rec - x).cast<double>().squaredNorm();
      });
    } else {
      const Eigen::Map<const RowMatrixXf> X(slot.data(), L, D);
      const btf::PcaResult r = btf::Pca(X, q);
      const RowMatrixXf rec = (r.scores * r.basis).rowwise() + r.mean.transpose();
      err += (rec - X).cast<double>().squaredNorm();
    }
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  omp_set_num_threads(before);
  benchmark::DoNotOptimize(err);
  const double c = 16, flops = double(L) * L * D + 4.0 * L * c * D;
  st.SetLabel(st.range(0) == 0 ? "WidePca (fused)" : "generic Pca + decode (the straightforward path)");
  st.counters["slot_s"] = secs / reps;
  st.counters["GFLOPs"] = flops * reps / secs / 1e9;
  // One thread against the 2-thread GEMM rate: x 2 gives the fraction of one core's rate.
  if (GemmRate(true) > 0) st.counters["fraction_of_double_gemm_per_core"] = 2 * flops * reps / secs / 1e9 / GemmRate(true);
  if (FmaPeakPerCore() > 0) st.counters["fraction_of_fma_peak"] = flops * reps / secs / 1e9 / FmaPeakPerCore();
  if (st.range(0) == 0) g_wide_slot_seconds = secs / reps;
  else if (g_wide_slot_seconds > 0) st.counters["generic_s_over_wide_s"] = secs / reps / g_wide_slot_seconds;
}
BENCHMARK(BM_PcaViewSlotKernel)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->MinTime(2.0)->UseRealTime();

// Straightforward reference: full SVD (BDCSVD) of every centered slot, first 16 components. Run on
// the first `slots` view slots only (it is slow); the ratio is per slot.
void BM_PcaViewFullSvdReference(benchmark::State& st) {
  const auto& d = Data();
  const int slots = static_cast<int>(st.range(0));
  double err = 0;
  for (auto _ : st) {
    for (int v = 0; v < slots; ++v) {
      const auto s = d.view_slot(v);
      const Eigen::Map<const RowMatrixXf> X(s.data(), 81, static_cast<Eigen::Index>(d.image_size()));
      const btf::PcaResult r = btf::PcaFullSvd(X, 16);
      err += r.residual_energy;
    }
  }
  benchmark::DoNotOptimize(err);
  st.counters["slots"] = slots;
  st.counters["seconds_per_slot"] = benchmark::Counter(double(slots), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  if (g_pca_view_seconds_per_slot > 0)
    st.counters["reference_slot_s_over_pca_view_slot_s"] =
        benchmark::Counter(double(slots) * g_pca_view_seconds_per_slot, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_PcaViewFullSvdReference)->Arg(4)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

double g_lpca_seconds = 0;

void BM_Lpca(benchmark::State& st) {
  const auto& d = Data();
  btf::CompressOptions o;
  o.method = btf::CodecMethod::kLpca;
  o.clusters = 32;
  o.components = 8;
  o.lpca.max_iterations = static_cast<int>(st.range(0));
  o.lpca.gram_limit = static_cast<int>(st.range(1));
  o.lpca.warm_start = st.range(2) != 0;
  o.lpca.prune = st.range(3) != 0;
  o.lpca.subspace = static_cast<int>(st.range(4));
  btf::CompressSummary s;
  const auto source = btf::MemorySource(d);
  for (auto _ : st) {
    LpcaCodec() = std::make_unique<btf::Codec>();
    s = btf::Compress(o, *source, LpcaCodec().get());
  }
  SetSizeCounters(st);
  const btf::CompressOptions defaults;
  const bool is_default = o.lpca.gram_limit == defaults.lpca.gram_limit && o.lpca.warm_start == defaults.lpca.warm_start &&
                          o.lpca.prune == defaults.lpca.prune && o.lpca.subspace == defaults.lpca.subspace;
  st.SetLabel("gram_limit " + std::to_string(o.lpca.gram_limit) + (o.lpca.warm_start ? ", warm start" : ", cold start") +
              (o.lpca.prune ? ", pruned" : ", every cluster") + ", subspace " + std::to_string(o.lpca.subspace) +
              (is_default ? " (default)" : " (before)"));
  // Clusters whose residual a texel's reassignment computed, mean over the reassignments.
  double compared = 0;
  for (double c : s.lpca_compared) compared += c / double(s.lpca_compared.size());
  st.counters["clusters_compared"] = compared;
  for (const auto& [name, sec] : s.times.phases()) st.counters[name + "_s"] = sec;
  st.counters["rounds"] = double(s.iteration_errors.size());
  st.counters["relative_error"] = s.relative_error;
  st.counters["codec_MB"] = double(s.codec_bytes) / 1e6;
  st.counters["ratio_vs_float32"] = s.ratio_float32;
  st.counters["ratio_vs_half"] = s.ratio_half;
  // Reassignment GEMM: N x d x K (c + 1) multiply-adds per round; its share is reported by the
  // kernel benchmark below.
  if (is_default) g_lpca_seconds = s.times.Total();
}
// Args: max_iterations, gram_limit, warm start (CompressOptions::lpca_warm_start), pruned
// reassignment (CompressOptions::lpca_prune), the sample rounds' subspace (lpca_subspace; 0: the
// full dimension). Before (every randomized cluster fit from a Gaussian sketch; every cluster
// compared in each reassignment; sample rounds in the full dimension) first, then the default,
// whose codec the decode benchmarks use.
BENCHMARK(BM_Lpca)
    ->Args({20, 256, 0, 1, 128})
    ->Args({20, 256, 1, 0, 128})
    ->Args({20, 256, 1, 1, 0})
    ->Args({20, 256, 1, 1, 128})
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

// One cluster's PCA (n texels' ABRDFs, 81 x 81 x 3 values; c = 8 as BM_Lpca) on one thread, by
// one path: Arg 1: n, Arg 2: 0 Gram (double), 1 randomized (18 test vectors, 2 power iterations),
// 2 randomized warm-started (LPCA's refits, CompressOptions::lpca_warm_start) from the basis of a
// neighbouring cluster: the n texels half a step further along the image (other texels of the
// same materials), fitted by path 1 outside the timing. relative_residual: the residual energy
// over the centred energy (an approximate path shows as a larger value).
void BM_ClusterPca(benchmark::State& st) {
  const auto& d = Data();
  const Eigen::Index n = std::min<Eigen::Index>(st.range(0), static_cast<Eigen::Index>(d.num_texels()));
  const Eigen::Index dim = static_cast<Eigen::Index>(d.abrdf_size());
  // Texels spread over the image (several materials), starting at `offset` of a step.
  auto rows = [&](double offset) {
    RowMatrixXf X(n, dim);
    for (Eigen::Index i = 0; i < n; ++i) {
      const std::size_t t = std::size_t((double(i) + offset) * double(d.num_texels()) / double(n));
      const auto a = d.Abrdf(static_cast<int>(t / d.width()), static_cast<int>(t % d.width()));
      X.row(i) = Eigen::Map<const Eigen::RowVectorXf>(a.data(), dim);
    }
    return X;
  };
  const RowMatrixXf X = rows(0);
  btf::PcaRequest q;
  q.max_components = 8;
  q.gram_limit = st.range(1) ? 1 : static_cast<int>(n);
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
  const btf::PcaResult start = st.range(1) == 2 ? btf::Pca(rows(0.5), q) : btf::PcaResult{};
  btf::PcaResult r;
  for (auto _ : st) r = btf::Pca(X, q, st.range(1) == 2 ? &start.basis : nullptr);
  omp_set_num_threads(before);
  st.SetLabel(!r.randomized ? "Gram" : st.range(1) == 2 ? "randomized, warm" : "randomized");
  st.counters["relative_residual"] = r.residual_energy / r.centered_energy;
}
BENCHMARK(BM_ClusterPca)
    ->ArgsProduct({{64, 128, 256, 512}, {0, 1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->MinTime(0.5)
    ->UseRealTime();

// The third codec (lpca-tensor) on the same data: lpca-tensor k = 32 at LPCA's c = 8 with its default
// rate-distortion rule and 8-bit codes, so the three codecs' ratio and error stand side by side.
void BM_LpcaTensor(benchmark::State& st) {
  const auto& d = Data();
  btf::CompressOptions o;
  o.method = btf::CodecMethod::kLpcaTensor;
  o.clusters = 32;
  o.components = 8;
  o.tensor.quant_bits = 8;
  btf::CompressSummary s;
  const auto source = btf::MemorySource(d);
  for (auto _ : st) {
    btf::Codec codec;
    s = btf::Compress(o, *source, &codec);
  }
  SetSizeCounters(st);
  for (const auto& [name, sec] : s.times.phases()) st.counters[name + "_s"] = sec;
  st.counters["relative_error"] = s.relative_error;
  st.counters["codec_MB"] = double(s.codec_bytes) / 1e6;
  st.counters["ratio_vs_float32"] = s.ratio_float32;
  st.counters["ratio_vs_half"] = s.ratio_half;
}
BENCHMARK(BM_LpcaTensor)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// The LPCA reassignment kernel alone (SubspaceResiduals: 256 half texel rows against 32 clusters
// of c = 8, every pair, in batches of 16 rows per cluster, about what a 256-texel block gives each
// cluster at Bonn size with 2 candidates per texel; batches split over all threads), as a flop
// rate (2 d (c + 1) per pair: the squared differences and the c projections) and as a fraction of
// the float GEMM rate of the same run.
void BM_LpcaReassignKernel(benchmark::State& st) {
  const auto& d = Data();
  constexpr int kBatch = 16;
  const int n = 256, K = 32, c = 8;
  const std::size_t dim = d.abrdf_size();
  const RowMatrixXf A = RowMatrixXf::Random(n, Eigen::Index(dim)), B = RowMatrixXf::Random(K * (c + 1), Eigen::Index(dim));
  std::vector<std::uint16_t> rows(std::size_t(n) * dim);
  btf::FloatsToHalves(A.data(), rows.data(), rows.size());
  std::vector<double> r(std::size_t(n) * K);
  double secs = 0;
  int reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static)
    for (int g = 0; g < n / kBatch; ++g) {
      const std::uint16_t* batch[kBatch];
      for (int i = 0; i < kBatch; ++i) batch[i] = rows.data() + std::size_t(g * kBatch + i) * dim;
      for (int k = 0; k < K; ++k)
        btf::SubspaceResiduals(batch, kBatch, B.row(k * (c + 1)).data(), B.row(k * (c + 1) + 1).data(), c, dim,
                               r.data() + std::size_t(k * n + g * kBatch));
    }
    benchmark::DoNotOptimize(r.data());
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  const double g = 2.0 * double(n) * double(dim) * K * (c + 1) * reps / secs / 1e9;
  st.counters["GFLOPs"] = g;
  if (GemmRate(false) > 0) st.counters["fraction_of_float_gemm"] = g / GemmRate(false);
}
BENCHMARK(BM_LpcaReassignKernel)->Unit(benchmark::kMillisecond)->MinTime(1.0)->UseRealTime();

// Straightforward reference: plain Lloyd k-means on the ABRDFs (explicit distance loops, random
// initial centers, at most 10 rounds) then a full SVD per cluster (8 components).
void BM_LpcaLloydReference(benchmark::State& st) {
  const auto& d = Data();
  const std::size_t N = d.num_texels(), dim = d.abrdf_size();
  const int K = 32, C = 8;
  RowMatrixXf A(static_cast<Eigen::Index>(N), static_cast<Eigen::Index>(dim));
  for (int y = 0; y < d.height(); ++y)
    for (int x = 0; x < d.width(); ++x) {
      const auto a = d.Abrdf(y, x);
      A.row(Eigen::Index(y) * d.width() + x) = Eigen::Map<const Eigen::RowVectorXf>(a.data(), static_cast<Eigen::Index>(dim));
    }
  double residual = 0, energy = A.cast<double>().squaredNorm();
  int rounds = 0;
  for (auto _ : st) {
    std::mt19937_64 rng(1);
    RowMatrixXf centers(K, static_cast<Eigen::Index>(dim));
    for (int k = 0; k < K; ++k) centers.row(k) = A.row(static_cast<Eigen::Index>(rng() % N));
    std::vector<int> assign(N, -1);
    for (rounds = 0; rounds < 10; ++rounds) {
      bool changed = false;
#pragma omp parallel for reduction(|| : changed)
      for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(N); ++i) {
        float best = std::numeric_limits<float>::max();
        int arg = 0;
        for (int k = 0; k < K; ++k) {
          float s = 0;
          for (std::size_t j = 0; j < dim; ++j) {
            const float e = A(i, Eigen::Index(j)) - centers(k, Eigen::Index(j));
            s += e * e;
          }
          if (s < best) best = s, arg = k;
        }
        if (assign[i] != arg) changed = true, assign[i] = arg;
      }
      centers.setZero();
      std::vector<int> count(K, 0);
      for (std::size_t i = 0; i < N; ++i) centers.row(assign[i]) += A.row(Eigen::Index(i)), ++count[assign[i]];
      for (int k = 0; k < K; ++k)
        if (count[k]) centers.row(k) /= float(count[k]);
      if (!changed) break;
    }
    residual = 0;
    for (int k = 0; k < K; ++k) {
      std::vector<Eigen::Index> m;
      for (std::size_t i = 0; i < N; ++i)
        if (assign[i] == k) m.push_back(Eigen::Index(i));
      if (m.empty()) continue;
      RowMatrixXf X(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(dim));
      for (std::size_t i = 0; i < m.size(); ++i) X.row(Eigen::Index(i)) = A.row(m[i]);
      residual += btf::PcaFullSvd(X, C).residual_energy;
    }
  }
  st.counters["rounds"] = rounds;
  st.counters["relative_error"] = std::sqrt(residual / energy);
  if (g_lpca_seconds > 0)
    st.counters["reference_s_over_lpca_s"] =
        benchmark::Counter(g_lpca_seconds, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_LpcaLloydReference)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// Args: codec (0 pca-view, 1 lpca), threads (0 = all). values_per_s counts L x H x W x C decoded
// values per second (the "texel-values"); with 1 thread it is the per-core rate.
// Decodes one view slot per iteration, cycling through the views, on `threads` threads (0 =
// all); returns the values decoded per iteration.
std::size_t DecodeSlots(benchmark::State& st, const btf::Codec& c, std::int64_t threads) {
  std::vector<float> out(c.image_size() * c.num_lights());
  const int before = omp_get_max_threads();
  if (threads > 0) omp_set_num_threads(static_cast<int>(threads));
  int v = 0;
  for (auto _ : st) {
    c.DecodeViewSlot(v, out.data());
    v = (v + 1) % c.num_views();
    benchmark::DoNotOptimize(out.data());
  }
  omp_set_num_threads(before);
  return out.size();
}

// The codec of Arg 0 (0 pca-view, 1 lpca), made by BM_PcaView/0 or BM_Lpca; where a
// --benchmark_filter left those out, none: the benchmark is skipped with a message saying so.
const btf::Codec* DecodedCodec(benchmark::State& st) {
  const auto& codec = st.range(0) == 0 ? PcaCodec() : LpcaCodec();
  if (!codec)
    st.SkipWithError(st.range(0) == 0 ? "no codec: include BM_PcaView/0 in --benchmark_filter"
                                      : "no codec: include a BM_Lpca in --benchmark_filter");
  return codec.get();
}

void BM_DecodeViewSlot(benchmark::State& st) {
  const btf::Codec* codec = DecodedCodec(st);
  if (!codec) return;
  const btf::Codec& c = *codec;
  const std::size_t values = DecodeSlots(st, c, st.range(1));
  st.SetLabel(std::string(st.range(0) == 0 ? "pca-view" : "lpca") + (st.range(1) == 1 ? ", 1 thread" : ", all threads"));
  // One slot = L images = L x H x W texel values.
  st.counters["images_per_s"] = benchmark::Counter(double(st.iterations()) * c.num_lights(), benchmark::Counter::kIsRate);
  st.counters["texels_per_s"] = benchmark::Counter(double(st.iterations()) * c.num_lights() * c.height() * c.width(),
                                                   benchmark::Counter::kIsRate);
  st.counters["values_per_s"] = benchmark::Counter(double(st.iterations()) * double(values), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_DecodeViewSlot)
    ->Args({0, 1})
    ->Args({1, 1})
    ->Args({0, 0})
    ->Args({1, 0})
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0)
    ->UseRealTime();

void BM_DecodeValue(benchmark::State& st) {
  const btf::Codec* codec = DecodedCodec(st);
  if (!codec) return;
  const btf::Codec& c = *codec;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  float out[3];
  for (auto _ : st) {
    const btf::Vec3 wi = btf::HemisphereFromSquare(btf::Vec2(u(rng), u(rng)));
    const btf::Vec3 wo = btf::HemisphereFromSquare(btf::Vec2(u(rng), u(rng)));
    c.Value(btf::Vec2(u(rng), u(rng)), wi, wo, out);
    benchmark::DoNotOptimize(out);
  }
  st.SetLabel(st.range(0) == 0 ? "pca-view" : "lpca");
  st.counters["values_per_s"] = benchmark::Counter(double(st.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_DecodeValue)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond)->MinTime(1.0)->UseRealTime();

// Reading every view slot of a dataset file through DatasetReader (docs/btf-compress.md,
// "Reading"): Arg 0 H5Dread (HDF5's filter pipeline, zlib on one thread), Arg 1 the raw chunk
// path (libbtf/io/raw_chunks.h: checksum, inflate and unshuffle on all threads), same file, same
// run. The file is BTF_BENCH_READ_FILE, or else the benchmarks' synthetic BTF (bench/
// synthetic_btf.h, as bench_synthetic_input writes it) at BTF_BENCH_RES, written to a temporary
// file first. The file is read once before either is timed, so both find it in the page cache.
// GB_per_s: float32 values delivered (4 V L H W C bytes) per wall second.
class ReadBenchFile {
 public:
  ReadBenchFile() {
    if (const char* e = std::getenv("BTF_BENCH_READ_FILE")) {
      path_ = e;
    } else {
      const int n = Resolution();
      const btf::Sampling s = btf::Sampling::Bonn81();
      path_ = std::filesystem::temp_directory_path() / ("btf_bench_read_" + std::to_string(getpid()) + ".h5");
      temporary_ = true;
      btf::DatasetWriter w(path_, s, s, n, n, 3, btf::DatasetInfo{});
      std::vector<float> slot(std::size_t(s.size()) * n * n * 3);
      for (int v = 0; v < s.size(); ++v) {
        btf::bench::SyntheticViewSlot(s, n, v, slot.data());
        w.WriteViewSlot(v, slot.data());
      }
      w.Commit();
    }
    std::ifstream in(path_, std::ios::binary);
    std::vector<char> buf(1 << 20);
    while (in.read(buf.data(), std::streamsize(buf.size())) || in.gcount() > 0) {
    }
  }
  ~ReadBenchFile() {
    std::error_code ec;
    if (temporary_) std::filesystem::remove(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  bool temporary_ = false;
};

void BM_ReadViewSlots(benchmark::State& st) {
  static const ReadBenchFile file;
  btf::DatasetReadOptions o;
  o.raw_chunks = st.range(0) == 1;
  const btf::DatasetReader r(file.path(), o);
  const auto& h = r.header();
  std::vector<float> slot(std::size_t(h.num_lights) * h.height * h.width * h.channels);
  const auto start = std::chrono::steady_clock::now();
  for (auto _ : st) {
    for (int v = 0; v < h.num_views; ++v) r.ReadViewSlot(v, slot.data());
    benchmark::DoNotOptimize(slot.data());
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double bytes = 4.0 * double(slot.size()) * h.num_views;
  st.SetLabel(std::string(o.raw_chunks ? "raw chunks, " + std::to_string(omp_get_max_threads()) + " threads" : "H5Dread") +
              ", " + h.storage + ", " + std::to_string(h.num_views) + " x " + std::to_string(h.num_lights) + " x " +
              std::to_string(h.height) + "^2 x " + std::to_string(h.channels));
  st.counters["float_GB"] = bytes * 1e-9;
  st.counters["GB_per_s"] = bytes * double(st.iterations()) / seconds * 1e-9;
}
BENCHMARK(BM_ReadViewSlots)->Arg(0)->Arg(1)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();

// Decoding of codec files named by BTF_BENCH_CODECS (comma-separated paths; none: not run): one
// view slot per iteration, cycling through the views, on 1 thread and on all; values_per_s as in
// BM_DecodeViewSlot. Compares codecs of one dataset (docs/btf-compress.md, "lpca-tensor").
const bool g_codec_files_registered = [] {
  const char* e = std::getenv("BTF_BENCH_CODECS");
  if (!e) return false;
  std::stringstream list(e);
  std::string path;
  while (std::getline(list, path, ',')) {
    if (path.empty()) continue;
    benchmark::RegisterBenchmark(("BM_DecodeCodecFile/" + path).c_str(),
                                 [path](benchmark::State& st) {
                                   static std::map<std::string, btf::Codec> cache;
                                   if (!cache.count(path)) cache[path] = btf::ReadCodec(path);
                                   const btf::Codec& c = cache[path];
                                   const std::size_t values = DecodeSlots(st, c, st.range(0));
                                   st.SetLabel(btf::MethodName(c.method()) + (st.range(0) == 1 ? ", 1 thread" : ", all threads"));
                                   st.counters["values_per_s"] = benchmark::Counter(
                                       double(st.iterations()) * double(values), benchmark::Counter::kIsRate);
                                 })
        ->Arg(1)
        ->Arg(0)
        ->Unit(benchmark::kMillisecond)
        ->MinTime(2.0)
        ->UseRealTime();
  }
  return true;
}();

}  // namespace

