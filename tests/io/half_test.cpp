// The half conversions of libbtf/io/half.h, the only ones in libbtf (float16 dataset storage, the
// BDI writer, half codec rows and the renderer exports' HALF_FLOAT textures all use them), checked
// against references computed here independently: every half decoded from its fields, and floats
// rounded to the nearest half in exact double arithmetic (ties to even through std::nearbyint):
// all 65536 halves, every float around every rounding boundary (ties and their neighbours, the
// overflow edge), every NaN payload and a dense sample of all 2^32 bit patterns.
#include "libbtf/io/half.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

namespace btf {
namespace {

// The float a half's bits stand for, from its sign, exponent and mantissa fields (NaN: any NaN).
double ReferenceHalfToValue(std::uint16_t h) {
  const int e = (h >> 10) & 0x1f, m = h & 0x3ff;
  double v;
  if (e == 31)
    v = m ? std::numeric_limits<double>::quiet_NaN() : std::numeric_limits<double>::infinity();
  else if (e == 0)
    v = std::ldexp(double(m), -24);
  else
    v = std::ldexp(double(m | 0x400), e - 25);
  return (h & 0x8000) ? -v : v;
}

// The value a non-NaN float rounds to in half precision: |f| scaled so that one unit in the last
// place of a half of that magnitude is 1 (2^-24 below 2^-14: subnormals), rounded to nearest even,
// scaled back; beyond the largest half (65504) +-infinity. Exact: f has 24 significant bits.
double ReferenceRoundToHalf(float f) {
  const double a = std::fabs(double(f));
  double r = a;
  if (std::isfinite(a)) {
    int e;
    std::frexp(a, &e);  // a in [2^(e-1), 2^e)
    const int ulp = std::max(e - 1, -14) - 10;
    r = std::ldexp(std::nearbyint(std::ldexp(a, -ulp)), ulp);
  }
  if (r > 65504.0) r = std::numeric_limits<double>::infinity();
  return std::signbit(f) ? -r : r;
}

std::string Hex(std::uint32_t v) {
  char s[16];
  std::snprintf(s, sizeof s, "0x%x", v);
  return s;
}

// FloatToHalf(f) is the half nearest f (ties to even), the sign of zero kept; a NaN becomes the
// quiet NaN of its sign. Where the build has F16C, also its conversion (an independent rounding).
::testing::AssertionResult RoundsLikeReference(float f) {
  const std::uint16_t h = FloatToHalf(f);
  const std::uint32_t x = std::bit_cast<std::uint32_t>(f);
  if (std::isnan(f)) {
    if (h == (((x >> 16) & 0x8000u) | 0x7e00u)) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "NaN float bits " << Hex(x) << " -> half " << Hex(h);
  }
  const double want = ReferenceRoundToHalf(f), got = ReferenceHalfToValue(h);
  if (got != want || std::signbit(got) != std::signbit(want))
    return ::testing::AssertionFailure() << "float bits " << Hex(x) << " (" << f << ") -> half " << Hex(h) << " = "
                                         << got << ", nearest half " << want;
#ifdef __F16C__
  const std::uint16_t hw = _cvtss_sh(f, _MM_FROUND_TO_NEAREST_INT);
  if (h != hw) return ::testing::AssertionFailure() << "float bits " << Hex(x) << " -> half " << Hex(h) << ", F16C " << Hex(hw);
#endif
  return ::testing::AssertionSuccess();
}

TEST(Half, EveryHalfDecodesToTheValueOfItsFields) {
  for (std::uint32_t h = 0; h < 65536; ++h) {
    const float f = HalfToFloat(std::uint16_t(h));
    const std::uint32_t bits = std::bit_cast<std::uint32_t>(f);
    if ((h & 0x7c00u) == 0x7c00u && (h & 0x3ffu)) {  // NaN: sign and payload kept
      ASSERT_EQ(bits, (h & 0x8000u) << 16 | 0x7f800000u | (h & 0x3ffu) << 13) << h;
      continue;
    }
    const double want = ReferenceHalfToValue(std::uint16_t(h));
    ASSERT_TRUE(double(f) == want && std::signbit(f) == std::signbit(want)) << h << ": " << f << " vs " << want;
  }
}

TEST(Half, EveryHalfSurvivesTheRoundTripAndKnownPatternsDecode) {
  for (std::uint32_t h = 0; h < 65536; ++h) {
    const float f = HalfToFloat(std::uint16_t(h));
    if (std::isnan(f)) {
      EXPECT_TRUE(std::isnan(HalfToFloat(FloatToHalf(f))));
      continue;
    }
    ASSERT_EQ(FloatToHalf(f), h) << h;
  }
  EXPECT_EQ(HalfToFloat(0x3c00), 1.0f);
  EXPECT_EQ(HalfToFloat(0xc000), -2.0f);
  EXPECT_EQ(HalfToFloat(0x7bff), 65504.0f);
  EXPECT_EQ(HalfToFloat(0x0001), std::ldexp(1.0f, -24));  // smallest subnormal
  EXPECT_EQ(HalfToFloat(0x3555), 0.333251953125f);
  // Ties round to even: 1 + 2^-11 lies halfway between 1 and 1 + 2^-10.
  EXPECT_EQ(FloatToHalf(1.0f + std::ldexp(1.0f, -11)), 0x3c00);
  EXPECT_EQ(FloatToHalf(1.0f + 3 * std::ldexp(1.0f, -11)), 0x3c02);
  EXPECT_EQ(FloatToHalf(65519.0f), 0x7bff);
  EXPECT_EQ(FloatToHalf(65520.0f), 0x7c00);  // rounds past the largest half: infinity
  EXPECT_EQ(FloatToHalf(std::ldexp(1.0f, -25)), 0x0000);  // tie between 0 and the smallest subnormal
  EXPECT_EQ(FloatToHalf(std::ldexp(1.5f, -25)), 0x0001);
}

// The bulk conversions (F16C where built for it) give the scalar functions' bits: every half, and
// floats around every half's rounding boundaries (ties, just above and below, past 65504), in
// runs of any length (the vector body and the scalar tail).
TEST(Half, BulkConversionsEqualTheScalarOnes) {
  std::vector<std::uint16_t> halves;
  for (std::uint32_t h = 0; h < 65536; ++h)
    if (!std::isnan(HalfToFloat(std::uint16_t(h)))) halves.push_back(std::uint16_t(h));
  std::vector<float> floats(halves.size());
  HalvesToFloats(halves.data(), floats.data(), halves.size());
  for (std::size_t i = 0; i < halves.size(); ++i) ASSERT_EQ(floats[i], HalfToFloat(halves[i])) << halves[i];
  std::vector<float> probes;
  for (std::uint32_t h = 0; h < 0x7c00; ++h) {
    const float lo = HalfToFloat(std::uint16_t(h)), hi = h < 0x7bff ? HalfToFloat(std::uint16_t(h + 1)) : 65536.0f;
    const float mid = lo + (hi - lo) / 2;
    for (const float f : {mid, std::nextafter(mid, 0.0f), std::nextafter(mid, 1e9f)}) probes.push_back(f), probes.push_back(-f);
  }
  probes.push_back(1e6f), probes.push_back(-std::numeric_limits<float>::infinity());
  for (const std::size_t n : {probes.size(), std::size_t(7), std::size_t(13)}) {
    std::vector<std::uint16_t> out(n);
    FloatsToHalves(probes.data(), out.data(), n);
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(out[i], FloatToHalf(probes[i])) << probes[i];
    std::vector<float> rounded(probes.begin(), probes.begin() + std::ptrdiff_t(n));
    RoundToHalves(rounded.data(), n);
    for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(rounded[i], HalfToFloat(FloatToHalf(probes[i]))) << probes[i];
  }
}

// Every float at and next to the midpoint between two neighbouring halves (the ties, one and two
// ulps either side), of both signs, up to the overflow edge (65520, midway between 65504 and the
// next power of two: it and everything above become infinity), and the halves themselves.
TEST(Half, FloatsAroundEveryRoundingBoundaryRoundToTheNearestHalfTiesToEven) {
  int ties_down = 0, ties_up = 0;
  for (std::uint32_t h = 0; h < 0x7c00; ++h) {
    const float lo = HalfToFloat(std::uint16_t(h)), hi = h < 0x7bff ? HalfToFloat(std::uint16_t(h + 1)) : 65536.0f;
    const float mid = lo + (hi - lo) / 2;  // exact: 12 significant bits at most
    ASSERT_EQ(double(mid), (double(lo) + double(hi)) / 2);
    (FloatToHalf(mid) == h ? ties_down : ties_up)++;
    std::vector<float> probes = {lo, mid};
    float below = mid, above = mid;
    for (int k = 0; k < 2; ++k) {
      below = std::nextafter(below, 0.0f), above = std::nextafter(above, 1e9f);
      probes.push_back(below), probes.push_back(above);
    }
    for (const float f : probes) {
      ASSERT_TRUE(RoundsLikeReference(f));
      ASSERT_TRUE(RoundsLikeReference(-f));
    }
  }
  // Ties to even: half of the ties go down (to an even h), half up.
  EXPECT_EQ(ties_down, 0x7c00 / 2);
  EXPECT_EQ(ties_up, 0x7c00 / 2);
  for (const float f : {65519.99f, 65520.0f, 1e6f, std::numeric_limits<float>::max(), std::numeric_limits<float>::infinity()}) {
    ASSERT_TRUE(RoundsLikeReference(f));
    ASSERT_TRUE(RoundsLikeReference(-f));
  }
  EXPECT_EQ(FloatToHalf(65520.0f), 0x7c00);
  EXPECT_EQ(FloatToHalf(std::nextafter(65520.0f, 0.0f)), 0x7bff);
}

TEST(Half, EveryNanPayloadBecomesTheQuietNanOfItsSign) {
  for (std::uint32_t m = 1; m < 0x800000u; ++m) {
    ASSERT_TRUE(RoundsLikeReference(std::bit_cast<float>(0x7f800000u | m)));
    ASSERT_TRUE(RoundsLikeReference(std::bit_cast<float>(0xff800000u | m)));
  }
}

// Every 509th of the 2^32 float bit patterns (8.4 million: every exponent, sign and NaN, with
// varied low mantissa bits), and every 61st of the floats from 2^-38 to 2^-32, which round to zero
// (there a subnormal rounding that shifts the 24-bit mantissa by more than 31 bits is undefined).
TEST(Half, ADenseSampleOfAllFloatsRoundsToTheNearestHalf) {
  int zero = 0, subnormal = 0, normal = 0, infinite = 0, nan = 0;
  for (std::uint64_t x = 0; x < (std::uint64_t(1) << 32); x += 509) {
    const float f = std::bit_cast<float>(std::uint32_t(x));
    ASSERT_TRUE(RoundsLikeReference(f));
    const std::uint16_t h = FloatToHalf(f) & 0x7fffu;
    ++(h == 0 ? zero : h < 0x400 ? subnormal : h < 0x7c00 ? normal : h == 0x7c00 ? infinite : nan);
  }
  // The sample reaches every kind of result in proportion to the float patterns that give it.
  EXPECT_GT(subnormal, 100000);
  EXPECT_GT(normal, 500000);
  EXPECT_GT(zero, 1000000);
  EXPECT_GT(infinite, 1000000);
  EXPECT_GT(nan, 10000);
  for (std::uint32_t x = 0x2c800000u; x < 0x2f800000u; x += 61) {
    const float f = std::bit_cast<float>(x);
    ASSERT_TRUE(RoundsLikeReference(f));
    ASSERT_TRUE(RoundsLikeReference(-f));
    ASSERT_EQ(FloatToHalf(f), 0);
  }
}

}  // namespace
}  // namespace btf
