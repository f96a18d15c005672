#pragma once
// BENCHMARK_MAIN, with Eigen's blocking fixed as in every libbtf program (libbtf/core/eigen_setup.h).
// Included once by each benchmark program, after its benchmarks.
#include <benchmark/benchmark.h>

#include "libbtf/core/eigen_setup.h"

int main(int argc, char** argv) {
  btf::FixEigenBlocking();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
