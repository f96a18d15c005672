// Slow: the texel-mean convergence check for the presets the fast suite leaves out, and for
// twill at 4x the strata (tighter bound).
#include <gtest/gtest.h>

#include "tests/synth/generator_check.h"

namespace btf {
namespace {

TEST(BtfGeneratorSlow, PlainConverges) { test::ExpectTexelMeanConverges("plain", 16, 8); }     // 128 strata / 2 units
TEST(BtfGeneratorSlow, SateenConverges) { test::ExpectTexelMeanConverges("sateen", 20, 8); }  // 160 strata / 5 units
TEST(BtfGeneratorSlow, TwillConvergesAtHigherSampling) { test::ExpectTexelMeanConverges("twill", 32, 16); }

}  // namespace
}  // namespace btf
