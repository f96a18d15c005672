#pragma once
// Error sums between a reference and a test signal: the one definition of RMSE, relative L2 error
// and PSNR that compression summaries and btf-eval report (docs/btf-eval.md, "Metrics").
//
// Sums are accumulated in double, serially within one Add() call; callers add blocks (images,
// view slots) in a fixed order and Merge() them in that order, so results do not depend on the
// number of threads.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

namespace btf {

struct ErrorStats {
  double sum_sq_error = 0;      // sum (test - ref)^2
  double sum_sq_reference = 0;  // sum ref^2
  double max_abs_error = 0;     // max |test - ref|
  double max_abs_reference = 0; // max |ref|
  std::uint64_t count = 0;      // values added
  std::size_t max_abs_index = 0;  // index of max_abs_error within the Add() call that set it

  void Add(const float* reference, const float* test, std::size_t n);
  void Merge(const ErrorStats& other);

  double Mse() const { return count ? sum_sq_error / double(count) : 0.0; }
  double Rmse() const;
  // ||test - ref|| / ||ref||; 0 when both are all zero, empty when only the reference is.
  std::optional<double> RelativeL2() const;
  // 10 log10(peak^2 / MSE) in dB; empty when MSE = 0 (identical) or peak <= 0.
  std::optional<double> PsnrDb(double peak) const;
  // A warning when a few values dominate the reference, so that the relative error and PSNR
  // describe them, not the rest: at least 10^4 values and the largest |value| holds over 1 % of
  // the energy (max |ref|^2 > 0.01 sum ref^2; e.g. one 1e30 outlier). Empty otherwise.
  std::string PeakDominance() const;
};

}  // namespace btf
