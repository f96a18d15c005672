// Irawan 2012 (Mitsuba 0.6 behavior): curvature, phase function, normalization, reciprocity,
// guards, stiff cases and hand-derived values.
#include "libbtf/synth/irawan2012.h"

#include <gtest/gtest.h>

#include <omp.h>

#include <cmath>
#include <fstream>
#include <random>

#include <Eigen/Geometry>

#include "libbtf/core/error.h"
#include "tests/test_util.h"

namespace btf {
namespace {

using irawan2012::Seeliger;
using irawan2012::SpineRadius;
using irawan2012::VonMises;

// Cheaper normalization for tests that do not check it (quadrature order 8: N_spec to ~1e-2, 100x
// faster than the default 16); tests of N_spec use the default.
const nlohmann::json kFast = {{"nspec_order", 8}};

// ---------------------------------------------------------------------------------------------
// Spine radius: the four branches of the reference (ellipse / circle / parabola / hyperbola,
// written from Mitsuba 0.6's irawan plugin) as an oracle for our closed form.
double BranchRadius(double u, double umax, double kappa, double w, double l) {
  const double rhat = 1 + kappa * (1 + 1 / std::tan(umax));
  const double C = 0.5 * l - 0.5 * w * std::sin(umax);
  if (rhat == 1) return C / std::sin(umax);
  if (rhat > 0) {
    const double tmax = std::atan(rhat * std::tan(umax));
    const double b = C / std::sin(tmax), a = b / rhat, t = std::atan(rhat * std::tan(u));
    return std::pow(b * b * std::cos(t) * std::cos(t) + a * a * std::sin(t) * std::sin(t), 1.5) / (a * b);
  }
  if (rhat < 0) {
    const double tmax = -std::atanh(rhat * std::tan(umax));
    const double b = C / std::sinh(tmax), a = b / rhat, t = -std::atanh(rhat * std::tan(u));
    return -std::pow(b * b * std::cosh(t) * std::cosh(t) + a * a * std::sinh(t) * std::sinh(t), 1.5) / (a * b);
  }
  const double a = C / (2 * std::tan(umax));
  return 2 * a * std::pow(1 + std::tan(u) * std::tan(u), 1.5);
}

TEST(Irawan2012Curvature, PresetValuesMatchTheReferenceTable) {
  // docs/btf-synth.md, "Irawan 2012" presets (6 significant digits printed:
  // relative tolerance 1e-5). (umax deg, kappa, w, l) -> R(0), R(umax).
  struct Row {
    const char* yarn;
    double umax, kappa, w, l, r0, rmax;
  };
  const Row rows[] = {
      {"denim warp", 12, 0, 1, 5, 11.5243, 11.5243},        {"denim weft", 38, 0, 1, 1, 0.312135, 0.312135},
      {"shantung warp", 50, -0.5, 2, 4, 1.04016, 3.86311},  {"shantung weft", 23, -0.3, 4, 4, 2.87068, 3.68055},
      {"charmeuse warp", 40, 2, 1, 9, 23.0402, 0.517512},   {"charmeuse weft", 60, 0, 1, 1, 0.0773503, 0.0773503},
      {"twill warp", 24, 0, 1, 6, 6.87578, 6.87578},        {"gabardine warp", 30, 0, 2, 6, 5.0, 5.0},
      {"gabardine weft", 30, 0, 3, 2, 0.5, 0.5},            {"polyester warp", 22, -0.7, 1, 1, 0.631138, 1.46014},
      {"polyester weft", 16, -0.7, 1, 1, 0.996977, 2.28241},
  };
  for (const Row& r : rows) {
    SCOPED_TRACE(r.yarn);
    const double umax = DegToRad(r.umax);
    EXPECT_NEAR(SpineRadius(0, umax, r.kappa, r.w, r.l), r.r0, 1e-5 * r.r0);
    EXPECT_NEAR(SpineRadius(umax, umax, r.kappa, r.w, r.l), r.rmax, 1e-5 * r.rmax);
    EXPECT_NEAR(SpineRadius(-umax, umax, r.kappa, r.w, r.l), r.rmax, 1e-5 * r.rmax);  // even in u
  }
  // Twill weft (w = 2, l = 1, umax = 36 deg): w sin(umax) = 1.176 >= l, no spine: 0.
  EXPECT_EQ(SpineRadius(0, DegToRad(36), 0, 2, 1), 0.0);
}

TEST(Irawan2012Curvature, ClosedFormEqualsBranchFormulas) {
  // 20000 random valid cases; the notes report 2.4e-11 as the worst relative difference; we allow
  // 1e-9 (the branch formulas lose digits near rhat = 0, which random draws rarely hit).
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> U(0, 1);
  double worst = 0;
  int n = 0;
  while (n < 20000) {
    const double umax = DegToRad(1 + 88 * U(rng));
    const double kappa = -0.98 + 4 * U(rng);
    const double w = 0.2 + 3 * U(rng), l = 0.2 + 8 * U(rng);
    if (w * std::sin(umax) >= l * 0.98) continue;
    const double u = umax * (2 * U(rng) - 1);
    const double a = SpineRadius(u, umax, kappa, w, l), b = BranchRadius(u, umax, kappa, w, l);
    ASSERT_TRUE(std::isfinite(a) && a > 0) << u << " " << umax << " " << kappa;
    worst = std::max(worst, std::abs(a - b) / std::abs(b));
    ++n;
  }
  EXPECT_LT(worst, 1e-9);
  // Exact branch points: circle (kappa = 0) and parabola (rhat = 0: kappa = -1 / (1 + cot umax)).
  const double umax = DegToRad(30);
  for (double u : {0.0, 0.2, umax}) {
    EXPECT_NEAR(SpineRadius(u, umax, 0, 1, 3), BranchRadius(u, umax, 0, 1, 3), 1e-12);
    const double kp = -1 / (1 + 1 / std::tan(umax));
    const double ref = BranchRadius(u, umax, kp, 1, 3);  // rhat rounds to ~0: parabola or a neighbor
    EXPECT_NEAR(SpineRadius(u, umax, kp, 1, 3), ref, 1e-9 * ref);
  }
}

TEST(Irawan2012Curvature, ContinuousThroughParabolaAndCircle) {
  // The closed form has no branch switch: stepping kappa by 1e-7 across rhat = 0 and rhat = 1
  // changes R by O(1e-7) relative (a branch jump would be O(1)).
  const double umax = DegToRad(30), u = DegToRad(20);
  const double k_parabola = -1 / (1 + 1 / std::tan(umax));
  for (double k0 : {k_parabola, 0.0}) {
    double prev = SpineRadius(u, umax, k0 - 5e-7, 1, 3);
    for (int i = -4; i <= 5; ++i) {
      const double r = SpineRadius(u, umax, k0 + i * 1e-7, 1, 3);
      EXPECT_NEAR(r, prev, 1e-6 * prev) << "kappa " << k0 + i * 1e-7;
      prev = r;
    }
  }
}

TEST(Irawan2012Curvature, StiffArguments) {
  // kappa -> -1 (hyperbola asymptote), umax -> 90 deg, umax -> 0: finite and > 0, or 0 where the
  // model has no spine; never NaN.
  for (double kappa : {-0.999999, -0.99, -0.9, 0.0, 5.0})
    for (double umax_deg : {1e-6, 0.01, 1.0, 45.0, 89.9, 90.0})
      for (double f : {0.0, 0.5, 1.0}) {
        const double umax = DegToRad(umax_deg);
        const double r = SpineRadius(f * umax, umax, kappa, 1, 2.5);
        EXPECT_TRUE(std::isfinite(r) && r >= 0) << kappa << " " << umax_deg << " " << f << " -> " << r;
      }
  EXPECT_EQ(SpineRadius(0.1, 0.0, 0.0, 1, 1), 0.0);   // umax = 0: no spine
  EXPECT_EQ(SpineRadius(0.1, 0.5, -1.0, 1, 1), 0.0);  // kappa = -1: rejected at load, 0 here
}

// ---------------------------------------------------------------------------------------------
TEST(Irawan2012Phase, VonMisesIsNormalizedOnTheCircle) {
  // Composite Simpson, 20000 intervals: error < 1e-12 for these smooth periodic integrands (the
  // largest concentration, 1000, has width ~0.03 rad = 100 intervals). Tolerance 1e-9.
  for (double b : {-3.0, 0.0, 0.5, 4.0, 7.3, 40.0, 1000.0}) {
    const int n = 20000;
    const double h = 2 * kPi / n;
    double s = 0;
    for (int i = 0; i <= n; ++i) {
      const double w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
      s += w * VonMises(std::cos(i * h), b);
    }
    EXPECT_NEAR(s * h / 3, 1.0, 1e-9) << "beta " << b;
  }
  // Against the reference's Abramowitz-Stegun 9.8.2 I0 at beta = 4 (accurate to ~1e-7 relative).
  const double t = 3.75 / 4;
  const double i0 = std::exp(4.0) / std::sqrt(4.0) *
                    (0.39894228 + t * (0.01328592 + t * (0.00225319 + t * (-0.00157565 + t * (0.00916281 + t * (-0.02057706 + t * (0.02635537 + t * (-0.01647633 + t * 0.00392377))))))));
  EXPECT_NEAR(VonMises(0.3, 4.0), std::exp(4.0 * 0.3) / (2 * kPi * i0), 2e-7 * VonMises(0.3, 4.0));
  // No overflow for a huge concentration: the peak is ~sqrt(b / 2 pi).
  EXPECT_NEAR(VonMises(1.0, 1e6), std::sqrt(1e6 / (2 * kPi)), 1.0);
}

TEST(Irawan2012Phase, SeeligerAttenuation) {
  EXPECT_NEAR(Seeliger(1, 1), 1 / (8 * kPi), 1e-16);  // the maximum
  EXPECT_EQ(Seeliger(0, 1), 0.0);
  EXPECT_EQ(Seeliger(-0.5, 1), 0.0);
  EXPECT_EQ(Seeliger(0.3, 0.7), Seeliger(0.7, 0.3));
  EXPECT_NEAR(Seeliger(0.3, 0.7), 0.21 / 1.0 / (4 * kPi), 1e-16);
}

// ---------------------------------------------------------------------------------------------
// An independent transcription of Mitsuba 0.6's irawan eval, used as
// the oracle for BandValue: different structure (explicit cell arithmetic, rotation matrix,
// branch-formula radius), same equations. Noise off, repeat 1.
double ReferenceBand(const WeavePattern& p, const Vec2& uv, Vec3 wi, Vec3 wo) {
  const double W = p.tile_width, H = p.tile_height;
  const double X = uv.x() * W, Y = (1 - uv.y()) * H;
  const int cx = static_cast<int>(std::floor(X)) % p.tile_width, cy = static_cast<int>(std::floor(Y)) % p.tile_height;
  const WeaveYarn& yarn = p.yarns[static_cast<std::size_t>(p.pattern[static_cast<std::size_t>(cy * p.tile_width + cx)] - 1)];
  double x = X - yarn.center_u * W, y = -(Y - (1 - yarn.center_v) * H);
  if (yarn.type == WeaveYarn::Type::kWeft) {
    Eigen::Matrix3d rot;  // +90 deg about z
    rot << 0, -1, 0, 1, 0, 0, 0, 0, 1;
    wi = rot * wi;
    wo = rot * wo;
    const Vec3 q = rot * Vec3(x, y, 0);
    x = q.x();
    y = q.y();
  }
  const double w = yarn.width, l = yarn.length, umax = yarn.umax, psi = yarn.psi, kappa = yarn.kappa;
  const double alpha = p.AlphaOf(yarn), beta = p.BetaOf(yarn), ss = p.SsOf(yarn);
  if (w * std::sin(umax) >= l) return 0;
  const double u = 2 * y / l * umax, v = kPi * x / w;
  const Vec3 h = (wi + wo).normalized();
  const double two_cos_d = (wi + wo).norm();
  const double fc = alpha + std::exp(-beta * wi.dot(wo)) / (2 * kPi * std::cyl_bessel_i(0.0, std::abs(beta)));
  const double a = w / 2;
  if (psi == 0) {
    const double us = std::atan(h.y() / h.z());
    if (std::abs(us) >= umax) return 0;
    const double ums = (1 - ss) * umax;
    const double R = BranchRadius(std::min(std::abs(us), ums), ums, kappa, w, l);
    const Vec3 t(0, std::cos(us), -std::sin(us));
    const double G = a * (R + a * std::cos(v)) / (two_cos_d * std::abs(t.cross(h).x()));
    const Vec3 n = Vec3(std::sin(v), std::sin(us) * std::cos(v), std::cos(us) * std::cos(v)).normalized();
    double A = Seeliger(n.dot(wi), n.dot(wo));
    if (ss > 0) {
      double s = std::clamp((std::abs(us) - ums) / (ss * umax), 0.0, 1.0);
      A *= 1 - s * s * (3 - 2 * s);
    }
    const double dy = l * p.h_width;
    const double ys = std::clamp(us * l / (2 * umax), -(l - dy) / 2, (l - dy) / 2);
    return std::abs(ys - y) < dy / 2 ? G * fc * A * kPi * l / dy : 0;
  }
  const double B = h.y() * std::sin(u) + h.z() * std::cos(u);
  const double D = (h.y() * std::cos(u) - h.z() * std::sin(u)) / (std::sqrt(h.x() * h.x() + B * B) * std::tan(psi));
  if (!(std::abs(D) < 1)) return 0;
  const double vs = std::atan2(-B, h.x()) + std::acos(D);
  if (!(std::abs(vs) < kPi / 2)) return 0;
  const Vec3 n = Vec3(std::sin(vs), std::sin(u) * std::cos(vs), std::cos(u) * std::cos(vs)).normalized();
  const Vec3 t(-std::cos(vs) * std::sin(psi), std::cos(u) * std::cos(psi) + std::sin(u) * std::sin(vs) * std::sin(psi),
               -std::sin(u) * std::cos(psi) + std::cos(u) * std::sin(vs) * std::sin(psi));
  EXPECT_NEAR(t.dot(h), 0, 1e-9);  // the root really is a highlight
  const double A = Seeliger(n.dot(wi), n.dot(wo));
  if (A == 0) return 0;
  const double R = BranchRadius(std::abs(u), umax, kappa, w, l);
  const double G = a * (R + a * std::cos(vs)) / (two_cos_d * n.dot(h) * std::abs(std::sin(psi)));
  const double dx = w * p.h_width;
  const double xs = std::clamp(vs * w / kPi, -(w - dx) / 2, (w - dx) / 2);
  return std::abs(xs - x) < dx / 2 ? G * fc * A * 2 * w * umax / dx : 0;
}

Vec3 RandomUpper(std::mt19937_64& rng, double max_theta = DegToRad(85)) {
  std::uniform_real_distribution<double> U(0, 1);
  return DirectionFromAngles(max_theta * std::sqrt(U(rng)), 2 * kPi * U(rng));
}

TEST(Irawan2012Model, MatchesIndependentTranscriptionOfTheReference) {
  // 3000 random (uv, wi, wo) per preset, all 12 presets. Relative tolerance 1e-9 (double vs
  // double; only the radius formula and evaluation order differ). Points within 1e-9 of a band
  // edge are skipped (the comparison flips there by rounding).
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> U(0, 1);
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const auto model = MakeIrawan2012(name, kFast);
    const WeavePattern& p = model->pattern();
    int nonzero = 0;
    for (int k = 0; k < 3000; ++k) {
      const Vec2 uv(U(rng), U(rng));
      const Vec3 wi = RandomUpper(rng), wo = RandomUpper(rng);
      const double ours = model->BandValue(uv, wi, wo);
      const double ref = ReferenceBand(p, uv, wi, wo);
      const double near_edge = std::abs(ReferenceBand(p, uv + Vec2(1e-9, 1e-9), wi, wo) - ref) +
                               std::abs(ReferenceBand(p, uv - Vec2(1e-9, 1e-9), wi, wo) - ref);
      if (near_edge > 1e-6 * std::abs(ref)) continue;
      EXPECT_NEAR(ours, ref, 1e-9 * std::abs(ref) + 1e-300) << "uv " << uv.transpose() << " wi " << wi.transpose()
                                                            << " wo " << wo.transpose();
      nonzero += ref > 0;
    }
    // Except the all-disabled velvet, a real share of random queries lands in a highlight band.
    if (name != "velvet") {
      EXPECT_GT(nonzero, 30);
    }
  }
}

TEST(Irawan2012Model, HandDerivedValueAtNormalIncidence) {
  // polyester_lining, uv at the center of warp yarn 1 (cell column 0, row 1 from the top:
  // uv = (0.25, 0.25)), wi = wo = +z. By hand (the band formula of docs/btf-synth.md):
  //   h = z, u* = 0, v = 0, n = z; umax_s = (1 - 0.5) * 22 deg = 11 deg;
  //   rhat = 1 - 0.7 (1 + cot 11 deg) = -3.301274..., q = -rhat^2;
  //   R(0) = C sqrt(cot^2 11 + q), C = 0.5 - 0.5 sin 11 deg;
  //   G = a (R + a) / (2 * 1), a = 0.5;   fc = 0.015 + e^{-4} / (2 pi I0(4));
  //   A = 1/(8 pi);  band: dy = 0.5, y* = 0 = y: value = G fc A pi l / dy.
  //   g = value * (warpArea + weftArea) / warpArea = 2 value.
  const double us = DegToRad(11);
  const double rhat = 1 - 0.7 * (1 + 1 / std::tan(us));
  const double C = 0.5 - 0.5 * std::sin(us);
  const double R = C * std::sqrt(1 / (std::tan(us) * std::tan(us)) - rhat * rhat);
  const double G = 0.5 * (R + 0.5) / 2;
  const double I0_4 = 11.301921952136330;  // I0(4), tables
  const double fc = 0.015 + std::exp(-4.0) / (2 * kPi * I0_4);
  const double value = G * fc / (8 * kPi) * kPi * 1 / 0.5;
  const auto model = MakeIrawan2012("polyester_lining", kFast);
  EXPECT_EQ(model->YarnIndexAt(Vec2(0.25, 0.25)), 1);
  EXPECT_NEAR(model->BandValue(Vec2(0.25, 0.25), Vec3(0, 0, 1), Vec3(0, 0, 1)), value, 1e-12 * value);
  EXPECT_NEAR(model->SpecularIntegrand(Vec2(0.25, 0.25), Vec3(0, 0, 1), Vec3(0, 0, 1)), 2 * value, 1e-12 * value);
  // The weft yarn 3 sits at uv = (0.25, 0.75); at normal incidence the rotation does not matter
  // and only umax differs (16 deg -> umax_s = 8 deg, which also enters C = l/2 - (w/2) sin umax_s,
  // as Mitsuba passes the smoothed umax to its radius function).
  const double us3 = DegToRad(8);
  const double rhat3 = 1 - 0.7 * (1 + 1 / std::tan(us3));
  const double R3 = (0.5 - 0.5 * std::sin(us3)) * std::sqrt(1 / (std::tan(us3) * std::tan(us3)) - rhat3 * rhat3);
  const double value3 = 0.5 * (R3 + 0.5) / 2 * fc / (8 * kPi) * kPi / 0.5;
  EXPECT_EQ(model->YarnIndexAt(Vec2(0.25, 0.75)), 3);
  EXPECT_NEAR(model->BandValue(Vec2(0.25, 0.75), Vec3(0, 0, 1), Vec3(0, 0, 1)), value3, 1e-12 * value3);
  // Eval = kd/pi + ks * N_spec * g (no cosine factor; Mitsuba's eval would multiply by cos theta_o).
  double rgb[3];
  model->EvalRgb(Vec2(0.25, 0.25), Vec3(0, 0, 1), Vec3(0, 0, 1), rgb);
  EXPECT_NEAR(rgb[0], 0.5 / kPi + 0.3 * model->specular_normalization() * 2 * value, 1e-12);
}

TEST(Irawan2012Model, WeftRotationMapsWarpHighlightGeometry) {
  // A square plain weave whose warp and weft yarns are identical: rotating the directions by
  // +90 deg about z and moving uv from a warp cell to the matching weft cell must give the same
  // band value (the weft frame is the warp frame turned by 90 deg).
  const char* text = R"(weave { name = "sym", tileWidth = 2, tileHeight = 2, alpha = 0.01, beta = 2, ss = 0,
    hWidth = 0.5, warpArea = 1, weftArea = 1, pattern { 3, 2, 1, 4 },
    yarn { type = warp, psi = 25, umax = 30, kappa = 0.3, width = 1, length = 1, centerU = 0.25, centerV = 0.25 },
    yarn { type = warp, psi = 25, umax = 30, kappa = 0.3, width = 1, length = 1, centerU = 0.75, centerV = 0.75 },
    yarn { type = weft, psi = 25, umax = 30, kappa = 0.3, width = 1, length = 1, centerU = 0.25, centerV = 0.75 },
    yarn { type = weft, psi = 25, umax = 30, kappa = 0.3, width = 1, length = 1, centerU = 0.75, centerV = 0.25 } })";
  Irawan2012Options o;
  o.nspec_order = 8;
  Irawan2012Model m("sym", ParseWeavePattern(text, "sym"), o);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> U(-0.49, 0.49);
  int nonzero = 0;
  for (int k = 0; k < 2000; ++k) {
    const Vec3 wi = RandomUpper(rng), wo = RandomUpper(rng);
    const double dx = U(rng) / 2, dy = U(rng) / 2;  // offset inside the cell (tile units)
    // Warp yarn 1: center (0.25, 0.25), local (x, y) = (dx, dy) * 2 cells.
    const double warp = m.BandValue(Vec2(0.25 + dx, 0.25 + dy), wi, wo);
    // Weft yarn 3 center (0.25, 0.75): the weft-local point (x', y') = (-y, x) equals the warp-local
    // (dx, dy) when (x, y) = (dy, -dx); directions turned by -90 deg so that rotating back gives wi.
    const Vec3 wi_r(wi.y(), -wi.x(), wi.z()), wo_r(wo.y(), -wo.x(), wo.z());
    const double weft = m.BandValue(Vec2(0.25 + dy, 0.75 - dx), wi_r, wo_r);
    EXPECT_NEAR(warp, weft, 1e-9 * warp + 1e-300);
    nonzero += warp > 0;
  }
  EXPECT_GT(nonzero, 20);
}

TEST(Irawan2012Model, Reciprocity) {
  // f(wi, wo) = f(wo, wi) for every preset: every factor is symmetric (h, wi.wo, Seeliger).
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(0, 1);
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const auto model = MakeIrawan2012(name, kFast);
    for (int k = 0; k < 2000; ++k) {
      const Vec2 uv(U(rng), U(rng));
      const Vec3 wi = RandomUpper(rng, DegToRad(89.9)), wo = RandomUpper(rng, DegToRad(89.9));
      double a[3], b[3];
      model->EvalRgb(uv, wi, wo, a);
      model->EvalRgb(uv, wo, wi, b);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 1e-12 * a[c]);
    }
  }
}

// Independent estimate of the specular albedo (1/pi) int int int f_spec cos_i cos_o with k_s = 1:
// wi, wo uniform in solid angle (not the cosine sampling N_spec uses), uv uniform, mt19937_64.
std::pair<double, double> SpecularAlbedo(const Irawan2012Model& m, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  auto uniform_dir = [&] {
    const double z = U(rng), phi = 2 * kPi * U(rng), r = std::sqrt(std::max(0.0, 1 - z * z));
    return Vec3(r * std::cos(phi), r * std::sin(phi), z);
  };
  double s = 0, s2 = 0;
  for (int k = 0; k < n; ++k) {
    const Vec3 wi = uniform_dir(), wo = uniform_dir();
    const Vec2 uv(U(rng), U(rng));
    // pdf of (wi, wo) = 1 / (2 pi)^2; albedo integrand / pi.
    const double x = m.SpecularIntegrand(uv, wi, wo) * m.specular_normalization() * wi.z() * wo.z() *
                     (4 * kPi * kPi) / kPi;
    s += x;
    s2 += x * x;
  }
  const double mean = s / n;
  return {mean, std::sqrt(std::max(0.0, s2 / n - mean * mean) / n)};
}

TEST(Irawan2012Model, SpecularLobeAlbedoEqualsKs) {
  // N_spec makes the cosine-weighted, uv-averaged bihemispherical albedo of the specular lobe
  // equal k_s (= 1 here). Checked with an independent black-box estimator (400k samples of the
  // model's own integrand): tolerance 4 standard errors of that estimate plus 4 times N_spec's own
  // error estimate. (This checks the quadrature's formulation at the percent level; the tests
  // below check it pointwise and its convergence.)
  // Six presets covering staple and filament yarns, smoothing, every spine branch, a guard-disabled
  // yarn type (twill) and per-yarn alpha/beta/ss (crepe).
  for (const char* name : {"cotton_denim", "polyester_lining", "silk_charmeuse", "silk_shantung", "cotton_twill",
                           "silk_crepe_de_chine"}) {
    SCOPED_TRACE(name);
    const auto model = MakeIrawan2012(name);
    ASSERT_GT(model->specular_normalization(), 0);
    EXPECT_EQ(model->options().nspec_order, 16);
    EXPECT_LT(model->specular_normalization_rel_error(), 1e-4);
    const auto [albedo, se] = SpecularAlbedo(*model, 400000, 99);
    EXPECT_LT(se, 0.03) << "estimator too weak to test anything";
    EXPECT_NEAR(albedo, 1.0, 4 * se + 4 * model->specular_normalization_rel_error()) << "se " << se;
  }
}

TEST(Irawan2012Model, NormalizationIsDeterministicAndRecorded) {
  const auto a = MakeIrawan2012("silk_shantung", kFast);
  const auto b = MakeIrawan2012("silk_shantung", kFast);
  EXPECT_EQ(a->specular_normalization(), b->specular_normalization());
  // The same bits on one thread as on several (values summed in a fixed order).
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = MakeIrawan2012("silk_shantung", kFast);
  omp_set_num_threads(std::max(2, threads));
  const auto many = MakeIrawan2012("silk_shantung", kFast);
  omp_set_num_threads(threads);
  EXPECT_EQ(one->specular_normalization(), many->specular_normalization());
  EXPECT_EQ(one->SpecularMean(9), many->SpecularMean(9));
  EXPECT_EQ(a->specular_normalization(), 1 / (kPi * a->SpecularMean(8)));
  const auto d = a->Describe();
  EXPECT_EQ(d["specular_normalization"]["value"].get<double>(), a->specular_normalization());
  EXPECT_EQ(d["specular_normalization"]["order"].get<int>(), 8);
  EXPECT_EQ(d["specular_normalization"]["error_estimate_order"].get<int>(), 6);
  EXPECT_EQ(d["specular_normalization"]["relative_error_estimate"].get<double>(), a->specular_normalization_rel_error());
  EXPECT_GT(d["specular_normalization"]["outer_nodes"].get<long long>(), 100);
  EXPECT_EQ(d["noise"].get<bool>(), false);
}

// ---------------------------------------------------------------------------------------------
// N_spec quadrature (docs/btf-synth.md, "Normalization N_spec"). The quadrature integrates, per
// yarn segment, over the highlight point (u, v) and a direction pair written in the fibre frame
// there: wi = sin(theta) t + cos(theta) (cos(phi_i) n + sin(phi_i) b), wo likewise with -theta and
// phi_o, h = (wi + wo) / |wi + wo| at angle a = (phi_i + phi_o) / 2 from n towards b. The three
// tests below check that reformulation against the model itself, pointwise: (1) at every point of
// the quadrature's domain the model's band value is the integrand the quadrature uses, (2) every
// highlight the model produces lies in that domain, (3) the Jacobian that cancels the model's
// geometry factor G. The convergence tests after them check the quadrature.

using irawan2012::FibreFrame;
using irawan2012::MakeFibreFrame;

Vec3 PairDirection(const FibreFrame& f, double theta, double phi) {
  return std::sin(theta) * f.t + std::cos(theta) * (std::cos(phi) * f.n + std::sin(phi) * f.b);
}

// uv of the yarn-local point (x, y) of yarn `yarn` (tile 0, repeat 1), and the global directions
// of local ones; false if the point leaves the tile or lies in another yarn's cell.
bool LocalToUv(const Irawan2012Model& m, int yarn, double x, double y, Vec3* wi, Vec3* wo, Vec2* uv) {
  const WeavePattern& p = m.pattern();
  const WeaveYarn& yn = p.yarns[static_cast<std::size_t>(yarn)];
  const double W = p.tile_width, H = p.tile_height, cx = yn.center_u * W, cy = (1 - yn.center_v) * H;
  double X = cx + x, Y = cy - y;
  if (yn.type == WeaveYarn::Type::kWeft) {  // local (x, y) = (-y_l, x_l), directions turned by +90 deg
    X = cx + y;
    Y = cy + x;
    *wi = Vec3(wi->y(), -wi->x(), wi->z());
    *wo = Vec3(wo->y(), -wo->x(), wo->z());
  }
  if (X < 0 || X >= W || Y < 0 || Y >= H) return false;
  *uv = Vec2(X / W, 1 - Y / H);
  return m.YarnIndexAt(*uv) == yarn + 1;
}

TEST(Irawan2012Normalization, FibreFrameIsOrthonormal) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> U(-1.5, 1.5);
  for (int k = 0; k < 1000; ++k) {
    const FibreFrame f = MakeFibreFrame(U(rng), U(rng), U(rng));
    EXPECT_NEAR(f.n.norm(), 1, 1e-14);
    EXPECT_NEAR(f.t.norm(), 1, 1e-14);
    EXPECT_NEAR(f.b.norm(), 1, 1e-14);
    EXPECT_NEAR(f.n.dot(f.t), 0, 1e-14);
    EXPECT_NEAR(f.n.dot(f.b), 0, 1e-14);
    EXPECT_NEAR(f.t.dot(f.b), 0, 1e-14);
  }
  // Filament (psi = 0): n and t as in the model (n = (sin v, sin u cos v, cos u cos v), t = (0, cos u, -sin u)).
  const FibreFrame f = MakeFibreFrame(0.3, -0.7, 0);
  EXPECT_NEAR((f.n - Vec3(std::sin(-0.7), std::sin(0.3) * std::cos(-0.7), std::cos(0.3) * std::cos(-0.7))).norm(), 0, 1e-15);
  EXPECT_NEAR((f.t - Vec3(0, std::cos(0.3), -std::sin(0.3))).norm(), 0, 1e-15);
}

TEST(Irawan2012Normalization, ModelEqualsTheQuadratureIntegrandOnItsDomain) {
  // Random points of the domain: (u, v) on the yarn, theta, phi_i, phi_o in (-pi/2, pi/2), both
  // directions above the surface. The model, evaluated at the band center of that highlight, must
  // give  G fc A * (domain factor)  with G = (w/2) (R + (w/2) cos v) / (2 cos(theta_d) J), J =
  // cos(a + v) (filament) or cos(a) |sin psi| (staple): the factor the Jacobian (test below)
  // cancels. Staple points with v + atan(cos(psi) tan(a)) <= -pi/2 must give 0 (the reference's
  // v* comes out 2 pi too large there). Relative tolerance 1e-6 (cos(theta_d) from |wi + wo|).
  std::mt19937_64 rng(22);
  std::uniform_real_distribution<double> U(0, 1);
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const auto m = MakeIrawan2012(name, kFast);
    const WeavePattern& p = m->pattern();
    int tested = 0, cut = 0;
    for (std::size_t yi = 0; yi < p.yarns.size(); ++yi) {
      const WeaveYarn& y = p.yarns[yi];
      if (y.width * std::sin(y.umax) >= y.length) continue;  // guard: no highlight
      const double w = y.width, l = y.length, a = 0.5 * w, hw = p.h_width, ss = p.SsOf(y);
      const bool staple = y.psi != 0;
      for (int k = 0; k < 1500; ++k) {
        double u = y.umax * (2 * U(rng) - 1), v = kPi * (U(rng) - 0.5);
        double th = kPi * (U(rng) - 0.5), pi_ = kPi * (U(rng) - 0.5), po = kPi * (U(rng) - 0.5);
        if (staple && k >= 1400) {  // the cut is rare (0.1 % of denim's pairs): search it (v < 0, a < 0)
          for (int tries = 0; tries < 100000; ++tries) {
            u = y.umax * (2 * U(rng) - 1);
            v = -0.5 * kPi * U(rng);
            th = kPi * (U(rng) - 0.5);
            pi_ = -0.5 * kPi * U(rng);
            po = -0.5 * kPi * U(rng);
            const FibreFrame g = MakeFibreFrame(u, v, y.psi);
            if (PairDirection(g, th, pi_).z() > 1e-3 && PairDirection(g, -th, po).z() > 1e-3 &&
                v + std::atan(std::cos(y.psi) * std::tan(0.5 * (pi_ + po))) <= -kPi / 2)
              break;
          }
        }
        const FibreFrame f = MakeFibreFrame(u, v, y.psi);
        Vec3 wi = PairDirection(f, th, pi_), wo = PairDirection(f, -th, po);
        if (wi.z() < 1e-3 || wo.z() < 1e-3) continue;
        const double ah = 0.5 * (pi_ + po);
        const double cos_d = 0.5 * (wi + wo).norm();
        const double fc = p.AlphaOf(y) + VonMises(-wi.dot(wo), p.BetaOf(y));
        const double A = Seeliger(std::cos(th) * std::cos(pi_), std::cos(th) * std::cos(po));
        double x, yy, expected;
        if (!staple) {  // band along y, centered at y*(u); x from v
          const double ums = (1 - ss) * y.umax, dy = l * hw;
          const double R = BranchRadius(std::min(std::abs(u), ums), ums, y.kappa, w, l);
          double sm = 1;
          if (ss > 0) {
            const double s = std::clamp((std::abs(u) - ums) / (ss * y.umax), 0.0, 1.0);
            sm = 1 - s * s * (3 - 2 * s);
          }
          x = v * w / kPi;
          yy = std::clamp(u * 0.5 * l / y.umax, -0.5 * (l - dy), 0.5 * (l - dy));
          expected = a * (R + a * std::cos(v)) / (2 * cos_d * std::cos(ah + v)) * fc * A * sm * kPi * l / dy;
        } else {  // band along x, centered at x*(v); y from u
          const double dx = w * hw;
          const double R = BranchRadius(std::abs(u), y.umax, y.kappa, w, l);
          x = std::clamp(v * w / kPi, -0.5 * (w - dx), 0.5 * (w - dx));
          yy = u * 0.5 * l / y.umax;
          const bool accepted = v + std::atan(std::cos(y.psi) * std::tan(ah)) > -kPi / 2;
          expected = accepted ? a * (R + a * std::cos(v)) / (2 * cos_d * std::cos(ah) * std::abs(std::sin(y.psi))) * fc * A *
                                    2 * w * y.umax / dx
                              : 0.0;
        }
        Vec2 uv;
        if (!LocalToUv(*m, static_cast<int>(yi), x, yy, &wi, &wo, &uv)) continue;
        cut += staple && expected == 0;
        const double got = m->BandValue(uv, wi, wo);
        EXPECT_NEAR(got, expected, 1e-6 * expected + 1e-300)
            << "yarn " << yi + 1 << " u " << u << " v " << v << " theta " << th << " phi " << pi_ << " " << po;
        ++tested;
      }
    }
    if (name != "velvet") {
      EXPECT_GT(tested, 500);
    }
    if (name == "cotton_denim" || name == "wool_gabardine") {
      EXPECT_GT(cut, 50) << "the staple cut was not exercised";
    }
  }
}

TEST(Irawan2012Normalization, EveryHighlightLiesInTheQuadratureDomain) {
  // Random (uv, wi, wo) where the model has a highlight, all presets: the highlight point (u, v)
  // (filament: u = atan(h_y / h_z), v = pi x / w; staple: u = 2 umax y / l, v = v* of the
  // reference) and the pair's (theta, phi_i, phi_o) in the fibre frame there must lie in the
  // quadrature's domain: h . t = 0, wo . t = -wi . t, |phi| < pi/2, |u| < umax (filament),
  // |v| < pi/2 and the staple cut (above). So the quadrature misses no part of the integrand.
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> U(0, 1);
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const auto m = MakeIrawan2012(name, kFast);
    const WeavePattern& p = m->pattern();
    int hits = 0;
    for (int k = 0; k < 20000; ++k) {
      const Vec2 uv(U(rng), U(rng));
      const Vec3 wi_g = RandomUpper(rng, DegToRad(89)), wo_g = RandomUpper(rng, DegToRad(89));
      if (!(m->BandValue(uv, wi_g, wo_g) > 0)) continue;
      ++hits;
      // Local point and directions (as the transcription ReferenceBand above).
      const double X = uv.x() * p.tile_width, Y = (1 - uv.y()) * p.tile_height;
      const WeaveYarn& y = p.yarns[static_cast<std::size_t>(m->YarnIndexAt(uv) - 1)];
      double x = X - y.center_u * p.tile_width, yl = -(Y - (1 - y.center_v) * p.tile_height);
      Vec3 wi = wi_g, wo = wo_g;
      if (y.type == WeaveYarn::Type::kWeft) {
        const double t = x;
        x = -yl;
        yl = t;
        wi = Vec3(-wi.y(), wi.x(), wi.z());
        wo = Vec3(-wo.y(), wo.x(), wo.z());
      }
      const Vec3 h = (wi + wo).normalized();
      double u, v;
      if (y.psi == 0) {
        u = std::atan(h.y() / h.z());
        v = kPi * x / y.width;
        EXPECT_LT(std::abs(u), y.umax);
      } else {
        u = 2 * y.umax * yl / y.length;
        const double B = h.y() * std::sin(u) + h.z() * std::cos(u);
        const double D = (h.y() * std::cos(u) - h.z() * std::sin(u)) / (std::hypot(h.x(), B) * std::tan(y.psi));
        v = std::atan2(-B, h.x()) + std::acos(D);
        EXPECT_LT(std::abs(v), kPi / 2);
      }
      const FibreFrame f = MakeFibreFrame(u, v, y.psi);
      EXPECT_NEAR(f.t.dot(h), 0, 1e-9);
      const double st = wi.dot(f.t);
      EXPECT_NEAR(wo.dot(f.t), -st, 1e-9);
      const double phi_i = std::atan2(wi.dot(f.b), wi.dot(f.n)), phi_o = std::atan2(wo.dot(f.b), wo.dot(f.n));
      EXPECT_LT(std::abs(phi_i), kPi / 2);
      EXPECT_LT(std::abs(phi_o), kPi / 2);
      EXPECT_NEAR((PairDirection(f, std::asin(st), phi_i) - wi).norm(), 0, 1e-9);
      EXPECT_NEAR((PairDirection(f, -std::asin(st), phi_o) - wo).norm(), 0, 1e-9);
      if (y.psi != 0 && v < 0) {
        EXPECT_GT(phi_i + phi_o, 2 * std::atan(1 / (std::tan(v) * std::cos(y.psi))));
      }
    }
    if (name != "velvet") {
      EXPECT_GT(hits, 100);
    }
  }
}

TEST(Irawan2012Normalization, JacobianOfTheDirectionParameterization) {
  // |d(wi, wo) / d(s, theta, phi_i, phi_o)| (solid angle x solid angle) by central differences,
  // against the closed form the quadrature uses: 2 cos(theta_d) J cos(theta) with s = u, J =
  // cos(a + v) at fixed v (filament) and s = v, J = cos(a) |sin psi| at fixed u (staple).
  // Differences with step 1e-5: relative accuracy ~1e-9; tolerance 1e-6.
  std::mt19937_64 rng(24);
  std::uniform_real_distribution<double> U(-1, 1);
  auto angles = [](const Vec3& w, double ref_phi) {
    double phi = std::atan2(w.y(), w.x());
    phi += 2 * kPi * std::round((ref_phi - phi) / (2 * kPi));  // no jump across the branch cut
    return std::array<double, 2>{std::acos(std::clamp(w.z(), -1.0, 1.0)), phi};
  };
  int tested = 0;
  for (int k = 0; k < 400; ++k) {
    const bool staple = k % 2;
    const double psi = staple ? 0.7 * U(rng) : 0.0;
    if (staple && std::abs(psi) < 0.1) continue;
    const double x0[5] = {0.6 * U(rng), 1.2 * U(rng), 1.2 * U(rng), 1.3 * U(rng), 1.3 * U(rng)};  // u, v, theta, phi_i, phi_o
    auto dirs = [&](const double* x) {
      const FibreFrame f = MakeFibreFrame(x[0], x[1], psi);
      return std::pair<Vec3, Vec3>{PairDirection(f, x[2], x[3]), PairDirection(f, -x[2], x[4])};
    };
    const auto [wi, wo] = dirs(x0);
    if (std::abs(wi.z()) > 0.98 || std::abs(wo.z()) > 0.98) continue;  // keep away from the poles of (theta, phi)
    const auto ai = angles(wi, 0), ao = angles(wo, 0);
    // Columns: s (u for the filament, v for the staple), theta, phi_i, phi_o.
    const int vars[4] = {staple ? 1 : 0, 2, 3, 4};
    Eigen::Matrix4d J;
    const double step = 1e-5;
    for (int c = 0; c < 4; ++c) {
      double xp[5], xm[5];
      std::copy(x0, x0 + 5, xp);
      std::copy(x0, x0 + 5, xm);
      xp[vars[c]] += step;
      xm[vars[c]] -= step;
      const auto [wip, wop] = dirs(xp);
      const auto [wim, wom] = dirs(xm);
      const auto aip = angles(wip, ai[1]), aop = angles(wop, ao[1]), aim = angles(wim, ai[1]), aom = angles(wom, ao[1]);
      J.col(c) << (aip[0] - aim[0]) / (2 * step), (aip[1] - aim[1]) / (2 * step), (aop[0] - aom[0]) / (2 * step),
          (aop[1] - aom[1]) / (2 * step);
    }
    const double numeric = std::abs(J.determinant()) * std::sin(ai[0]) * std::sin(ao[0]);
    const double a = 0.5 * (x0[3] + x0[4]), cos_d = 0.5 * (wi + wo).norm();
    const double jac = staple ? std::cos(a) * std::abs(std::sin(psi)) : std::cos(a + x0[1]);
    const double expected = 2 * cos_d * std::abs(jac) * std::cos(x0[2]);
    EXPECT_NEAR(numeric, expected, 1e-6 * expected) << "staple " << staple << " k " << k;
    ++tested;
  }
  EXPECT_GT(tested, 200);
}

TEST(Irawan2012Normalization, ErrorEstimateBelow1e4ForEveryPreset) {
  // Every preset at the default order 16: the error estimate |N(16) - N(12)| / N(16) is below
  // 1e-4 (the issue's target; the actual error is ~1e-6 or less, see the slow test against
  // order 32), and it is not vacuous (> 0).
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const auto m = MakeIrawan2012(name);
    if (name == "velvet") {
      EXPECT_EQ(m->specular_normalization(), 0.0);
      continue;
    }
    EXPECT_GT(m->specular_normalization(), 0);
    EXPECT_GT(m->specular_normalization_rel_error(), 0);
    EXPECT_LT(m->specular_normalization_rel_error(), 1e-4);
  }
}

TEST(Irawan2012Normalization, ConvergedAtTheDefaultOrder) {
  // Fast version of the slow test's check: three presets that exercise the three hard parts (staple
  // cut and many segments: cotton_denim; hyperbolic spine near its asymptote with smoothing:
  // polyester_lining; beta = 40, a very peaked phase function: silk_shot). N(16) against N(20),
  // a different set of nodes everywhere: |difference| / N <= 1e-5 (observed <= 5e-7), and the
  // error estimate covers the difference.
  for (const char* name : {"cotton_denim", "polyester_lining", "silk_shot"}) {
    SCOPED_TRACE(name);
    const auto m = MakeIrawan2012(name);
    const double n20 = 1 / (kPi * m->SpecularMean(20));
    const double diff = std::abs(m->specular_normalization() / n20 - 1);
    EXPECT_LT(diff, 1e-5);
    EXPECT_GE(m->specular_normalization_rel_error(), diff);
  }
}

TEST(Irawan2012Normalization, OptionsCheck) {
  Irawan2012Options o;
  o.Check();  // the documented defaults are valid
  EXPECT_EQ(o.nspec_order, 16);
  for (int bad : {3, 65}) {
    o.nspec_order = bad;
    EXPECT_THROW(o.Check(), Error);
  }
  o = Irawan2012Options{};
  o.repeat_u = 0;
  EXPECT_THROW(o.Check(), Error);
  o = Irawan2012Options{};
  o.tile_mm = -1;
  EXPECT_THROW(o.Check(), Error);
  // The model constructor checks them too.
  o = Irawan2012Options{};
  o.nspec_order = 2;
  EXPECT_THROW(Irawan2012Model("x", WeavePreset("polyester_lining"), o), Error);
}

TEST(Irawan2012Model, GuardDisablesTwillWeftAndVelvet) {
  // Cotton twill weft: w sin(umax) = 2 sin 36 deg = 1.176 >= l = 1 -> specular 0 (reference).
  const auto twill = MakeIrawan2012("cotton_twill", kFast);
  EXPECT_EQ(twill->disabled_yarns(), (std::vector<int>{7, 8, 9, 10}));
  const auto d = twill->Describe();
  ASSERT_EQ(d["disabled_yarns"].size(), 4u);
  EXPECT_EQ(d["disabled_yarns"][0]["type"], "weft");
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> U(0, 1);
  int warp_hits = 0, weft_cells = 0;
  for (int k = 0; k < 20000; ++k) {
    const Vec2 uv(U(rng), U(rng));
    const Vec3 wi = RandomUpper(rng), wo = RandomUpper(rng);
    const int yarn = twill->YarnIndexAt(uv);
    const double g = twill->BandValue(uv, wi, wo);
    if (yarn >= 7) {
      ++weft_cells;
      EXPECT_EQ(g, 0.0);
    } else {
      warp_hits += g > 0;
    }
  }
  EXPECT_GT(weft_cells, 3000);  // a quarter of the tile
  EXPECT_GT(warp_hits, 100);    // the warp is not disabled
  // Velvet (umax = 90 deg, w = l = 1): sin 90 = 1 >= 1: both yarns disabled, N_spec = 0, the BRDF
  // is the diffuse kd / pi everywhere.
  const auto velvet = MakeIrawan2012("velvet", kFast);
  EXPECT_EQ(velvet->disabled_yarns(), (std::vector<int>{1, 2, 3, 4}));
  EXPECT_EQ(velvet->specular_normalization(), 0.0);
  for (int k = 0; k < 1000; ++k) {
    const Vec2 uv(U(rng), U(rng));
    double rgb[3];
    velvet->EvalRgb(uv, RandomUpper(rng), RandomUpper(rng), rgb);
    EXPECT_NEAR(rgb[0], 0.05 * 0.03 / kPi, 1e-15);
    EXPECT_NEAR(rgb[2], 0.0, 1e-15);
  }
  // Every other preset keeps all its yarns.
  for (const char* name : {"cotton_denim", "polyester_lining", "silk_charmeuse", "silk_shantung", "wool_gabardine"})
    EXPECT_TRUE(MakeIrawan2012(name, kFast)->disabled_yarns().empty()) << name;
}

TEST(Irawan2012Model, StiffCasesStayFiniteAndNonNegative) {
  // theta up to 89.9 deg on both sides, retro-reflection (wi = wo), exact mirror pairs, all
  // presets, 16 x 16 uv grid including the tile edges. Also below-horizon inputs return 0.
  std::vector<Vec3> dirs;
  for (double t : {0.0, 30.0, 60.0, 80.0, 89.0, 89.9})
    for (double p : {0.0, 45.0, 90.0, 135.0, 180.0, 270.0, 333.0}) dirs.push_back(DirectionFromAngles(DegToRad(t), DegToRad(p)));
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const auto model = MakeIrawan2012(name, nlohmann::json{{"nspec_order", 6}, {"noise", true}});
    for (int iu = 0; iu <= 16; ++iu)
      for (int iv = 0; iv <= 16; ++iv) {
        const Vec2 uv(iu / 16.0, iv / 16.0);
        for (const Vec3& wi : dirs) {
          for (const Vec3& wo : {wi, Vec3(-wi.x(), -wi.y(), wi.z()), dirs[static_cast<std::size_t>(iu + iv) % dirs.size()]}) {
            float f[3];
            model->Eval(uv, wi, wo, f);
            for (float x : f) ASSERT_TRUE(std::isfinite(x) && x >= 0) << uv.transpose() << " | " << wi.transpose() << " | " << wo.transpose();
          }
        }
      }
    float f[3];
    model->Eval(Vec2(0.3, 0.3), Vec3(0, 0.5, -0.8), Vec3(0, 0, 1), f);
    EXPECT_EQ(f[0], 0.0f);
    model->Eval(Vec2(0.3, 0.3), Vec3(0, 0, 0), Vec3(0, 0, 1), f);
    EXPECT_EQ(f[0], 0.0f);
    model->Eval(Vec2(NAN, 1e300), Vec3(0, 0, 1), Vec3(0, 0, 1), f);
    EXPECT_TRUE(std::isfinite(f[0]));
  }
}

TEST(Irawan2012Model, ExtremeYarnParameters) {
  // kappa just above -1, umax at 0 and 90 deg (w = 1 < l = 2, so the guard lets 90 through), for
  // filament and staple yarns: finite everywhere.
  for (const char* psi : {"0", "30"})
    for (const char* umax : {"0", "0.001", "45", "90"})
      for (const char* kappa : {"-0.999999", "-0.99", "0", "3"}) {
        if (std::string(psi) != "0" && std::string(umax) == "0") continue;  // rejected (tested in the parser)
        const std::string text = fmt::format(
            R"(weave {{ name = "x", tileWidth = 1, tileHeight = 1, alpha = 0.01, beta = 4, ss = 0.3, hWidth = 0.5,
               warpArea = 1, weftArea = 0, pattern {{ 1 }},
               yarn {{ type = warp, psi = {}, umax = {}, kappa = {}, width = 1, length = 2, centerU = 0.5, centerV = 0.5,
                      kd = {{0.1, 0.1, 0.1}}, ks = {{0.5, 0.5, 0.5}} }} }})",
            psi, umax, kappa);
        SCOPED_TRACE(text);
        Irawan2012Options o;
        o.nspec_order = 8;
        Irawan2012Model m("x", ParseWeavePattern(text, "x"), o);
        EXPECT_TRUE(std::isfinite(m.specular_normalization()));
        std::mt19937_64 rng(1);
        std::uniform_real_distribution<double> U(0, 1);
        for (int k = 0; k < 3000; ++k) {
          double rgb[3];
          m.EvalRgb(Vec2(U(rng), U(rng)), RandomUpper(rng, DegToRad(89.9)), RandomUpper(rng, DegToRad(89.9)), rgb);
          ASSERT_TRUE(std::isfinite(rgb[0]) && rgb[0] >= 0);
        }
      }
}

TEST(Irawan2012Model, ParameterOverrides) {
  const auto base = MakeIrawan2012("cotton_denim", kFast);
  // repeat_u = 2, repeat_v = 3: the value at uv equals the repeat-1 value at the folded position
  // (u' = frac(2u), 1 - v' = frac(3 (1 - v)) because rows run from the top).
  const auto rep = MakeIrawan2012("cotton_denim", {{"repeat_u", 2}, {"repeat_v", 3}, {"nspec_order", 8}});
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> U(0, 1);
  for (int k = 0; k < 500; ++k) {
    const Vec2 uv(U(rng), U(rng));
    const Vec3 wi = RandomUpper(rng), wo = RandomUpper(rng);
    const double fu = 2 * uv.x() - std::floor(2 * uv.x());
    const double fy = 3 * (1 - uv.y()) - std::floor(3 * (1 - uv.y()));
    const double a = rep->BandValue(uv, wi, wo), b = base->BandValue(Vec2(fu, 1 - fy), wi, wo);
    EXPECT_NEAR(a, b, 1e-9 * b + 1e-12);
  }
  // Color overrides: kd everywhere, then ks of the weft only.
  const auto col = MakeIrawan2012("cotton_denim", {{"kd", {0.2, 0.3, 0.4}}, {"weft_ks", 0.0}, {"nspec_order", 8}});
  for (const auto& y : col->pattern().yarns) {
    EXPECT_DOUBLE_EQ(y.kd[2], 0.4);
    EXPECT_DOUBLE_EQ(y.ks[0], y.type == WeaveYarn::Type::kWeft ? 0.0 : 0.08);
  }
  // Bad overrides name the field.
  for (const auto& [params, field] : std::vector<std::pair<nlohmann::json, std::string>>{
           {{{"repeat_u", 0}}, "repeat_u"}, {{{"kd", "red"}}, "kd"}, {{{"noise", 1}}, "noise"},
           {{{"colour", 1}}, "colour"}, {{{"nspec_order", 3}}, "nspec_order"}, {{{"nspec_order", 8.5}}, "nspec_order"},
           {{{"nspec_samples", 65536}}, "nspec_samples"},  // the former Monte Carlo count: now unknown
           {{{"warp_ks", {1, 2}}}, "warp_ks"}}) {
    try {
      MakeIrawan2012("cotton_denim", params);
      ADD_FAILURE() << params.dump();
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kUsage);
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  }
}

TEST(Irawan2012Model, PresetMayBeAWvFile) {
  const auto dir = test::TempDir();
  const auto path = dir / "lining.wv";
  std::ofstream(path) << FormatWeavePattern(WeavePreset("polyester_lining"));
  const auto file = MakeIrawan2012(path.string(), kFast);
  const auto preset = MakeIrawan2012("polyester_lining", kFast);
  EXPECT_EQ(file->name(), "irawan2012/file:lining");
  const Vec3 wi = DirectionFromAngles(0.4, 0.3), wo = DirectionFromAngles(0.5, 2.0);
  for (double u : {0.1, 0.3, 0.6, 0.9})
    EXPECT_DOUBLE_EQ(file->BandValue(Vec2(u, 0.4), wi, wo), preset->BandValue(Vec2(u, 0.4), wi, wo));
  // Through the generic factory as well.
  EXPECT_EQ(MakeIrawan2012Model("silk_charmeuse", kFast)->name(), "irawan2012/silk_charmeuse");
}

TEST(Irawan2012Model, NoiseIsDeterministicAndVariesTheHighlight) {
  // With noise on: the same values from two instances, different values from noise off at some
  // points, and the albedo normalization still holds (N_spec includes the variation).
  const auto off = MakeIrawan2012("silk_shantung", kFast);  // period 500 -> umax noise
  const auto on1 = MakeIrawan2012("silk_shantung", {{"noise", true}, {"nspec_order", 8}});
  const auto on2 = MakeIrawan2012("silk_shantung", {{"noise", true}, {"nspec_order", 8}});
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> U(0, 1);
  int differ = 0;
  for (int k = 0; k < 4000; ++k) {
    const Vec2 uv(U(rng) * 0.999, U(rng));
    const Vec3 wi = RandomUpper(rng), wo = RandomUpper(rng);
    const double a = on1->BandValue(uv, wi, wo);
    EXPECT_EQ(a, on2->BandValue(uv, wi, wo));
    differ += std::abs(a - off->BandValue(uv, wi, wo)) > 1e-9 * a;
  }
  EXPECT_GT(differ, 20);
  const auto denim = MakeIrawan2012("cotton_denim", {{"noise", true}});  // fineness 3 -> intensity variation
  const auto [albedo, se] = SpecularAlbedo(*denim, 400000, 5);
  EXPECT_NEAR(albedo, 1.0, 4 * se + 4 * denim->specular_normalization_rel_error());
}

}  // namespace
}  // namespace btf
