#include "libbtf/core/error_stats.h"

#include <algorithm>
#include <cmath>

namespace btf {

void ErrorStats::Add(const float* reference, const float* test, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    const double r = reference[i], d = double(test[i]) - r, a = std::abs(d);
    sum_sq_error += d * d;
    sum_sq_reference += r * r;
    if (a > max_abs_error) max_abs_error = a, max_abs_index = i;
    max_abs_reference = std::max(max_abs_reference, std::abs(r));
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
