// ErrorStats::Add sums in 8 lanes (vectorised): its sums must equal a plain serial double loop to
// rounding, and its maxima and the index of the worst value exactly.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "libbtf/core/error_stats.h"

namespace btf {
namespace {

TEST(ErrorStats, LanesMatchASerialLoop) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-2, 2);
  for (std::size_t n : {0u, 1u, 7u, 8u, 9u, 256u, 1001u}) {
    std::vector<float> ref(n), test(n);
    for (std::size_t i = 0; i < n; ++i) ref[i] = u(rng), test[i] = ref[i] + 0.01f * u(rng);
    if (n > 5) test[5] = ref[5] + 3;  // the worst value, away from the lane boundaries' ends
    ErrorStats e;
    e.Add(ref.data(), test.data(), n);
    double se = 0, sr = 0, me = 0, mr = 0;
    std::size_t arg = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double d = double(test[i]) - ref[i];
      se += d * d, sr += double(ref[i]) * ref[i];
      if (std::abs(d) > me) me = std::abs(d), arg = i;
      mr = std::max(mr, std::abs(double(ref[i])));
    }
    // Reordered double sums of n <= 1001 terms: relative difference below n * 2^-53.
    EXPECT_NEAR(e.sum_sq_error, se, 1e-13 * se) << n;
    EXPECT_NEAR(e.sum_sq_reference, sr, 1e-13 * sr) << n;
    EXPECT_EQ(e.max_abs_error, me) << n;
    EXPECT_EQ(e.max_abs_reference, mr) << n;
    EXPECT_EQ(e.max_abs_index, arg) << n;
    EXPECT_EQ(e.count, n);
  }
}

TEST(ErrorStats, FirstIndexOnTiesAndNaNPropagatesToTheSums) {
  const std::vector<float> ref(20, 1.0f);
  std::vector<float> test(20, 1.0f);
  test[11] = test[3] = 0.5f;  // tied worst values: the first one is reported
  ErrorStats e;
  e.Add(ref.data(), test.data(), test.size());
  EXPECT_EQ(e.max_abs_index, 3u);
  EXPECT_EQ(e.max_abs_error, 0.5);
  test[17] = std::numeric_limits<float>::quiet_NaN();
  ErrorStats f;
  f.Add(ref.data(), test.data(), test.size());
  EXPECT_TRUE(std::isnan(f.sum_sq_error));  // callers check finiteness; a NaN is never hidden
  EXPECT_FALSE(f.RelativeL2().has_value() && std::isfinite(*f.RelativeL2()));
}

}  // namespace
}  // namespace btf
