// Irawan 2006 ellipse model: the analytic ellipse-window area (case-free method vs the report's
// five cases vs the reference table), the small-angle segment series, and the stiff cases.
#include "libbtf/synth/irawan2006.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "libbtf/core/error.h"
#include "tests/synth/five_cases_oracle.h"

namespace btf {
namespace {

EllipseSegment TwillWarp() {
  return Irawan2006Preset("twill").segments[0];
}
EllipseSegment TwillWeft() {
  return Irawan2006Preset("twill").segments[1];
}

TEST(Irawan2006, CircularSegmentSeriesIsAccurateForTinyAngles) {
  // Reference in long double from the same series to many terms / direct formula where stable.
  for (double t : {1e-8, 1e-6, 1e-4, 1e-3, 1e-2, 0.049, 0.051, 0.5, 3.0, 6.0}) {
    long double ref;
    const long double lt = t;
    if (t < 0.1) {  // series to theta^15: truncation < 1e-30 relative here
      long double term = lt * lt * lt / 6, sum = 0;
      for (int k = 0; k < 7; ++k) {
        sum += term;
        term *= -lt * lt / ((2 * k + 4) * (2 * k + 5));
      }
      ref = sum / 2;
    } else {
      ref = (lt - std::sin(lt)) / 2;
    }
    // 1e-13 relative: double rounding of a handful of operations.
    EXPECT_NEAR(CircularSegmentArea(t) / static_cast<double>(ref), 1.0, 1e-13) << "theta " << t;
  }
  EXPECT_GT(CircularSegmentArea(1e-4), 0);  // the naive (t - sin t)/2 in float gives 0 here
  EXPECT_NEAR(CircularSegmentArea(2 * kPi), kPi, 1e-15);
  EXPECT_EQ(CircularSegmentArea(0), 0);
}

TEST(Irawan2006, EllipseAreaMatchesReferenceTable) {
  // S = A_E / A_R from clipping a 2e5-gon (accurate to 1e-6), printed with
  // 6 decimals. Tolerance 2e-6 = table accuracy + rounding.
  struct Row {
    double hx, hy, warp, weft;
  };
  const Row rows[] = {{0, 0, 0.470649, 0.684694},      {0, 0.2, 0.346777, 0.616671},
                      {0.2, 0.3, 0.245120, 0.395743},  {0.5, 0.5, 0.024212, 0.009564},
                      {-0.3, 0.6, 0.013988, 0.120088}, {0.6, -0.1, 0.269755, 0}};
  const EllipseSegment warp = TwillWarp(), weft = TwillWeft();
  for (const Row& r : rows) {
    EXPECT_NEAR(EllipseWindowArea(warp, r.hx, r.hy) / 6.0, r.warp, 2e-6) << r.hx << "," << r.hy;
    EXPECT_NEAR(EllipseWindowArea(weft, r.hx, r.hy) / 2.0, r.weft, 2e-6) << r.hx << "," << r.hy;
    EXPECT_NEAR(test::FiveCaseWindowArea(warp, r.hx, r.hy) / 6.0, r.warp, 2e-6) << r.hx << "," << r.hy;
    EXPECT_NEAR(test::FiveCaseWindowArea(weft, r.hx, r.hy) / 2.0, r.weft, 2e-6) << r.hx << "," << r.hy;
  }
  // h = 0: pi alpha beta / window area exactly.
  EXPECT_NEAR(EllipseWindowArea(warp, 0, 0) / 6, kPi * 3 * 3 * std::sqrt(1 - 0.995 * 0.995) / 6, 1e-14);
  // Twill tile average at h = 0 from the table's first row: (4 x 6 x 0.470649 + 4 x 2 x 0.684694) / 32.
  const Irawan2006Model m(Irawan2006Preset("twill"));
  EXPECT_NEAR(m.HighlightFraction(Vec3::UnitZ(), Vec3::UnitZ()), 0.524160, 2e-6);
}

TEST(Irawan2006, CaseFreeMatchesFiveCasesOnRandomConfigurations) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(0, 1);
  int seen[6] = {0, 0, 0, 0, 0, 0};
  double max_diff = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    // Random ellipse that fits its window when centered (the five cases' assumption), random shift.
    EllipseSegment s;
    s.sx = 0.5 + 3 * U(rng);
    s.sy = 0.5 + 3 * U(rng);
    s.eta = 0.999 * U(rng);
    s.phi = 2 * kPi * U(rng);
    const double beta_ratio = std::sqrt(1 - s.eta * s.eta);
    const double c = std::cos(s.phi), sn = std::sin(s.phi);
    const double ex = 2 * std::sqrt(c * c + beta_ratio * beta_ratio * sn * sn);  // extents per unit alpha
    const double ey = 2 * std::sqrt(sn * sn + beta_ratio * beta_ratio * c * c);
    s.alpha = (0.2 + 0.79 * U(rng)) * std::min(s.sx / ex, s.sy / ey);
    s.kx = 3 * U(rng);
    s.ky = 3 * U(rng);
    const double hx = 2 * U(rng) - 1, hy = 2 * U(rng) - 1;
    int which = 0;
    const double beta = s.alpha * beta_ratio;
    // Five-case area directly, to learn which case it was.
    const double cx = 0.5 * s.sx * (s.kx * hx + 1), cy = 0.5 * s.sy * (s.ky * hy + 1);
    auto to_disk = [&](double x, double y) {
      return Vec2((c * (x - cx) + sn * (y - cy)) / s.alpha, (-sn * (x - cx) + c * (y - cy)) / beta);
    };
    const double five =
        test::DiskQuadAreaFiveCases({to_disk(0, 0), to_disk(s.sx, 0), to_disk(s.sx, s.sy), to_disk(0, s.sy)}, &which);
    ASSERT_TRUE(std::isfinite(five)) << "configuration outside the five cases at trial " << trial;
    ++seen[which];
    const double free = EllipseWindowArea(s, hx, hy) / (s.alpha * beta);
    // Both are exact formulas in double: agreement to 1e-11 of the disk area (pi).
    max_diff = std::max(max_diff, std::abs(free - five));
    ASSERT_NEAR(free, five, 1e-11 * kPi) << "trial " << trial << " case " << which;
  }
  for (int k = 1; k <= 5; ++k) EXPECT_GT(seen[k], 50) << "case " << k << " not exercised";
  RecordProperty("max_abs_diff", std::to_string(max_diff));
}

TEST(Irawan2006, TinyCapsKeepRelativeAccuracy) {
  // A window edge cutting a tiny cap off the unit disk: area ~ theta^3/12.
  for (double d : {1 - 1e-6, 1 - 1e-9}) {
    const double theta = 2 * std::acos(d);
    const std::array<Vec2, 4> quad{Vec2(d, -3), Vec2(5, -3), Vec2(5, 3), Vec2(d, 3)};
    const double five = test::DiskQuadAreaFiveCases(quad);
    EXPECT_NEAR(five / CircularSegmentArea(theta), 1, 1e-6);  // acos(d) itself limits this
    // The case-free sum cancels O(1) terms: absolute accuracy ~1e-15 is what it promises.
    EXPECT_NEAR(DiskPolygonArea({quad.begin(), quad.end()}), five, 1e-14);
  }
}

TEST(Irawan2006, StiffCasesStayFiniteAndContinuous) {
  const double grazing = DegToRad(89.9);
  std::vector<std::unique_ptr<SvbrdfModel>> models;
  for (const char* p : {"twill", "plain", "sateen"}) models.push_back(MakeIrawan2006Model(p));
  models.push_back(MakeIrawan2006Model("twill", {{"warp", {{"eta", 0.9999}}}, {"weft", {{"eta", 0.9999}}}}));
  models.push_back(MakeIrawan2006Model("twill", {{"fresnel", "none"}}));
  std::vector<Vec3> dirs;
  for (double t : {0.0, 0.3, 1.0, 1.3, DegToRad(80), DegToRad(89), grazing})
    for (double p : {0.0, 0.7, kPi / 2, 2.0, kPi, -2.5, -kPi / 2}) dirs.push_back(DirectionFromAngles(t, p));
  dirs.push_back(Vec3(0, 0, 1e-30).normalized());
  dirs.push_back(Vec3(1, 0, 1e-12).normalized());
  dirs.push_back(Vec3(-1, 0, 1e-12).normalized());
  const std::vector<Vec2> uvs{Vec2(0, 0), Vec2(0.999999, 0.5), Vec2(0.25, 0.75), Vec2(1, 1), Vec2(-3.2, 7.9)};
  for (const auto& m : models) {
    for (const Vec3& wi : dirs)
      for (const Vec3& wo : dirs) {
        float f[3];
        m->EvalBrdf(wi, wo, f);
        for (float x : f) ASSERT_TRUE(std::isfinite(x) && x >= 0) << m->name();
        for (const Vec2& uv : uvs) {
          m->Eval(uv, wi, wo, f);
          for (float x : f) ASSERT_TRUE(std::isfinite(x) && x >= 0) << m->name();
        }
      }
    // Below the horizon: 0.
    float f[3];
    m->Eval(Vec2(0.3, 0.3), Vec3(0, 0.5, -0.8).normalized(), Vec3::UnitZ(), f);
    EXPECT_EQ(f[0], 0);
    m->EvalBrdf(Vec3::UnitZ(), Vec3(1, 0, -1e-9).normalized(), f);
    EXPECT_EQ(f[1], 0);
  }
  // Continuity of the analytic BRDF along paths that sweep highlights across window edges,
  // retro-reflection included: consecutive steps of 1e-6 rad may change f by at most 1e-3
  // relative (the area is Lipschitz in the center; a jump would be a case flip or a wrong sign).
  for (const auto& m : models) {
    for (double phi_o : {0.0, 1.0, kPi / 2, 2.5}) {
      float prev[3];
      bool first = true;
      for (double t = -1.4; t <= 1.4; t += 0.0131) {  // coarse scan: finiteness
        const Vec3 wo = DirectionFromAngles(std::abs(t), t < 0 ? phi_o + kPi : phi_o);
        float f[3];
        m->EvalBrdf(Vec3(0.2, 0.1, 1).normalized(), wo, f);
        ASSERT_TRUE(std::isfinite(f[0]));
      }
      for (double t = 0.5; t <= 0.5 + 2000e-6; t += 1e-6) {  // fine scan across a window edge region
        const Vec3 wo = DirectionFromAngles(t, phi_o);
        const Vec3 wi = DirectionFromAngles(t, phi_o);  // retro-reflection wi = wo
        float f[3];
        m->EvalBrdf(wi, wo, f);
        if (!first) {
          for (int c = 0; c < 3; ++c) ASSERT_NEAR(f[c], prev[c], 1e-3 * std::abs(prev[c]) + 1e-7) << m->name();
        }
        std::copy(f, f + 3, prev);
        first = false;
      }
    }
  }
}

TEST(Irawan2006, ContinuityWhereHighlightsLeaveTheWindow) {
  // Scan h_y through the range where the warp ellipse center crosses its window's top edge
  // (k_y h_y = 1): the area must fall continuously to 0.
  const EllipseSegment warp = TwillWarp();
  double prev = EllipseWindowArea(warp, 0, 0.2);
  for (double hy = 0.2; hy < 0.7; hy += 1e-5) {
    const double a = EllipseWindowArea(warp, 0, hy);
    ASSERT_TRUE(std::isfinite(a) && a >= 0);
    // |dA/dc| <= chord length <= 2 alpha; dc = s_y k_y dhy / 2.
    ASSERT_LE(std::abs(a - prev), 2 * warp.alpha * 0.5 * warp.sy * warp.ky * 1e-5 * 1.01);
    prev = a;
  }
  EXPECT_EQ(EllipseWindowArea(warp, 0, 0.7), 0);
}

TEST(Irawan2006, BadPresetAndParametersAreUsageErrors) {
  try {
    MakeIrawan2006Model("denim");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
    EXPECT_NE(std::string(e.what()).find("denim"), std::string::npos);
  }
  EXPECT_THROW(MakeIrawan2006Model("twill", {{"warp", {{"eta", 1.0}}}}), Error);
  EXPECT_THROW(MakeIrawan2006Model("twill", {{"gloss", 1.0}}), Error);
  EXPECT_THROW(MakeIrawan2006Model("twill", {{"fresnel", "schlick"}}), Error);
}

TEST(Irawan2006, BrdfIsReciprocal) {
  // F(theta_d), G and S̄(h) are symmetric in wi, wo: exact reciprocity (float rounding only).
  const auto m = MakeIrawan2006Model("twill");
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(0, 1);
  for (int i = 0; i < 500; ++i) {
    const Vec3 a = DirectionFromAngles(1.5 * U(rng), 6.28 * U(rng));
    const Vec3 b = DirectionFromAngles(1.5 * U(rng), 6.28 * U(rng));
    float f1[3], f2[3];
    m->EvalBrdf(a, b, f1);
    m->EvalBrdf(b, a, f2);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(f1[c], f2[c], 1e-6 * f1[c]);
  }
}

}  // namespace
}  // namespace btf

namespace btf {
namespace {

TEST(Irawan2006, SinglePointEvalEqualsBatchEval) {
  // Eval (one point, no tables) and EvalBatch (per-pair tables) are two code paths of one
  // formula: they must agree exactly.
  for (const char* preset : {"twill", "plain", "sateen"}) {
    const auto m = MakeIrawan2006Model(preset);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> U(0, 1);
    for (int i = 0; i < 200; ++i) {
      const Vec3 wi = DirectionFromAngles(1.3 * U(rng), 6.28 * U(rng));
      const Vec3 wo = DirectionFromAngles(1.3 * U(rng), 6.28 * U(rng));
      std::vector<Vec2> uv(64);
      for (auto& p : uv) p = Vec2(U(rng), U(rng));
      std::vector<float> batch(64 * 3);
      m->EvalBatch(wi, wo, uv.data(), 64, batch.data());
      for (int k = 0; k < 64; ++k) {
        float f[3];
        m->Eval(uv[k], wi, wo, f);
        for (int c = 0; c < 3; ++c) ASSERT_EQ(f[c], batch[k * 3 + c]) << preset;
      }
    }
  }
}

}  // namespace
}  // namespace btf
