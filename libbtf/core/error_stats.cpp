#include "libbtf/core/error_stats.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Core>
#include <fmt/format.h>

namespace btf {

void ErrorStats::Add(const float* reference, const float* test, std::size_t n) {
  // kLanes independent partial sums and maxima (AVX packets), folded in lane order: the result
  // depends only on the values and n, never on who calls.
  constexpr int kLanes = 8;
  using Lanes = Eigen::Array<double, kLanes, 1>;
  using Floats = Eigen::Map<const Eigen::Array<float, kLanes, 1>, Eigen::Unaligned>;
  Lanes se = Lanes::Zero(), sr = Lanes::Zero(), me = Lanes::Zero(), mr = Lanes::Zero();
  const std::size_t body = n - n % kLanes;
  for (std::size_t i = 0; i < body; i += kLanes) {
    const Lanes r = Floats(reference + i).cast<double>(), d = Floats(test + i).cast<double>() - r;
    se += d * d;
    sr += r * r;
    me = me.max(d.abs());
    mr = mr.max(r.abs());
  }
  for (std::size_t i = body; i < n; ++i) {
    const double r = reference[i], d = double(test[i]) - r;
    const auto k = static_cast<Eigen::Index>(i - body);
    se[k] += d * d;
    sr[k] += r * r;
    me[k] = std::max(me[k], std::abs(d));
    mr[k] = std::max(mr[k], std::abs(r));
  }
  double block_max = 0;
  for (int k = 0; k < kLanes; ++k) {
    sum_sq_error += se[k];
    sum_sq_reference += sr[k];
    block_max = std::max(block_max, me[k]);
    max_abs_reference = std::max(max_abs_reference, mr[k]);
  }
  if (block_max > max_abs_error) {  // the first value that attains it
    for (std::size_t i = 0; i < n; ++i)
      if (std::abs(double(test[i]) - double(reference[i])) == block_max) {
        max_abs_error = block_max, max_abs_index = i;
        break;
      }
  }
  count += n;
}

void ErrorStats::Merge(const ErrorStats& o) {
  sum_sq_error += o.sum_sq_error;
  sum_sq_reference += o.sum_sq_reference;
  if (o.max_abs_error > max_abs_error) max_abs_error = o.max_abs_error, max_abs_index = o.max_abs_index;
  max_abs_reference = std::max(max_abs_reference, o.max_abs_reference);
  count += o.count;
}

std::string ErrorStats::PeakDominance() const {
  const double peak_sq = max_abs_reference * max_abs_reference;
  if (count < 10000 || !(peak_sq > 0.01 * sum_sq_reference)) return {};
  return fmt::format("the reference's largest |value| {:.4g} holds {:.3g} % of its energy (its RMS is {:.4g}): the "
                     "relative error and PSNR describe that value, not the rest (an outlier in the input?); compare "
                     "with --metric rmse or remove it",
                     max_abs_reference, 100 * peak_sq / sum_sq_reference, std::sqrt(sum_sq_reference / double(count)));
}

double ErrorStats::Rmse() const { return std::sqrt(Mse()); }

std::optional<double> ErrorStats::RelativeL2() const {
  if (sum_sq_reference > 0) return std::sqrt(sum_sq_error / sum_sq_reference);
  if (sum_sq_error == 0) return 0.0;
  return std::nullopt;
}

std::optional<double> ErrorStats::PsnrDb(double peak) const {
  const double mse = Mse();
  if (!(mse > 0) || !(peak > 0)) return std::nullopt;
  return 10 * std::log10(peak * peak / mse);
}

}  // namespace btf
