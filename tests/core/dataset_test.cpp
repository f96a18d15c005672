#include "libbtf/core/dataset.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <limits>
#include <string>

#include "libbtf/core/error.h"

namespace btf {
namespace {

// Sets an environment variable for one test and restores the old value.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old, had_ = true;
    setenv(name, value, 1);
  }
  ~ScopedEnv() { had_ ? setenv(name_, old_.c_str(), 1) : unsetenv(name_); }

 private:
  const char* name_;
  std::string old_;
  bool had_ = false;
};

void ExpectLimitError(double bytes, const std::string& fragment) {
  try {
    CheckAllocation(bytes, "thing");
    FAIL() << bytes << " bytes accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(AllocationLimit, DefaultIs16GiBAndTheMessageSaysHowToRaiseIt) {
  unsetenv("BTF_MAX_BYTES");
  EXPECT_EQ(MaxAllocationBytes(), 16ull << 30);
  EXPECT_NO_THROW(CheckAllocation(16.0 * (1ull << 30), "thing"));
  ExpectLimitError(17.0 * (1ull << 30), "raise it with BTF_MAX_BYTES=");
  ExpectLimitError(1e40, "thing needs");
  ExpectLimitError(std::numeric_limits<double>::quiet_NaN(), "thing");
}

TEST(AllocationLimit, EnvironmentRaisesOrLowersItAndIgnoresGarbage) {
  {
    ScopedEnv env("BTF_MAX_BYTES", "1000");
    EXPECT_NO_THROW(CheckAllocation(1000, "x"));
    ExpectLimitError(1001, "limit");
  }
  {
    ScopedEnv env("BTF_MAX_BYTES", "12abc");  // not a number: the default stays
    EXPECT_EQ(MaxAllocationBytes(), 16ull << 30);
  }
}

// Regression: the byte count of a shape whose integer product passes 2^64 used to wrap around
// (2^90 elements * 4 bytes is 0 mod 2^64) and slip through; it is computed in double now.
TEST(AllocationLimit, ShapesWhoseProductWrapsAroundAreRefused) {
  const Sampling one = Sampling::Single(Vec3(0, 0, 1));
  try {
    Dataset d(one, one, 1 << 30, 1 << 30, 1 << 30);
    FAIL() << "a 2^90-value dataset was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("BTF_MAX_BYTES"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace btf
