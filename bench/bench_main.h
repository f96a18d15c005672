#pragma once
// BENCHMARK_MAIN, with Eigen's blocking fixed as in every libbtf program (libbtf/core/eigen_setup.h),
// and the yardstick the kernel benchmarks state their rate against. Included once by each
// benchmark program (it defines main), before its benchmarks.
#include <omp.h>

#include <chrono>

#include <Eigen/Core>
#include <benchmark/benchmark.h>

#include "libbtf/core/eigen_setup.h"

namespace btf::bench {

// The machine's yardstick: Eigen's GEMM c = a b of 1024 x 1024 Scalar matrices, each product timed
// on its own (the benchmark's loop), 2 n^3 flops a product. threads > 0: OpenMP threads for the
// products (the previous count is restored afterwards); 0: as set. Returns GFLOP/s and sets the
// state's "GFLOPs" counter.
template <typename Scalar>
double EigenGemmRate(benchmark::State& st, int threads = 0) {
  using M = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  const int n = 1024;
  M a = M::Random(n, n), b = M::Random(n, n), c(n, n);
  const int before = omp_get_max_threads();
  if (threads > 0) omp_set_num_threads(threads);
  double secs = 0;
  long reps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    c.noalias() = a * b;
    benchmark::DoNotOptimize(c.data());
    secs += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++reps;
  }
  if (threads > 0) omp_set_num_threads(before);
  const double gflops = 2.0 * n * n * double(n) * double(reps) / secs / 1e9;
  st.counters["GFLOPs"] = gflops;
  return gflops;
}

}  // namespace btf::bench

int main(int argc, char** argv) {
  btf::FixEigenBlocking();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
