#include "libbtf/stability/stability.h"

#include <gtest/gtest.h>

#include "libbtf/core/error.h"

namespace btf {
namespace {

// The whole suite (about 5-10 s on 2 cores): every case must pass. Each case states its own
// criterion and tolerance (docs/btf-eval.md, "stability").
TEST(EvalStability, EveryCasePasses) {
  const StabilitySummary s = RunStability();
  EXPECT_EQ(s.cases.size(), StabilityCaseNames().size());
  for (const auto& c : s.cases) EXPECT_TRUE(c.passed) << c.name << ": " << c.figure << " (criterion: " << c.criterion << ")";
  EXPECT_EQ(s.failed, 0);
  EXPECT_EQ(s.passed, int(s.cases.size()));
  // The JSON carries the same verdicts.
  const auto j = s.ToJson();
  EXPECT_EQ(j["failed"], 0);
  EXPECT_EQ(j["cases"].size(), s.cases.size());
}

TEST(EvalStability, OnlySelectsByPrefixAndRejectsUnknown) {
  StabilityOptions o;
  o.only = {"input/"};
  const StabilitySummary s = RunStability(o);
  ASSERT_EQ(s.cases.size(), 2u);  // input/NaN and input/Inf
  for (const auto& c : s.cases) EXPECT_EQ(c.name.rfind("input/", 0), 0u);
  o.only = {"no-such-case"};
  EXPECT_THROW(RunStability(o), Error);
}

}  // namespace
}  // namespace btf
