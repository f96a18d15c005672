// Sadeghi 2013 microcylinder model: pieces, hand-derived value, reciprocity, stiff cases, albedo.
#include "libbtf/synth/sadeghi2013.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <tuple>

#include "libbtf/core/error.h"

namespace btf {
namespace {

using sadeghi2013::FresnelDielectric;
using sadeghi2013::SampleTangentCurve;
using sadeghi2013::UnitGaussian;

TEST(Sadeghi2013Pieces, Fresnel) {
  // Normal incidence ((eta - 1) / (eta + 1))^2, grazing 1, and a tabulated value: glass eta = 1.5
  // at 45 deg: Rs = 0.0920, Rp = 0.00847 -> 0.05023 (4 digits).
  EXPECT_NEAR(FresnelDielectric(1, 1.5), 0.04, 1e-15);
  EXPECT_NEAR(FresnelDielectric(0, 1.5), 1.0, 1e-15);
  EXPECT_NEAR(FresnelDielectric(std::cos(kPi / 4), 1.5), 0.05023, 5e-5);
}

TEST(Sadeghi2013Pieces, UnitGaussianHasUnitArea) {
  // Trapezoid over +-10 sigma with 20000 steps: error far below 1e-9.
  for (double w : {DegToRad(2.5), DegToRad(30)}) {
    const int n = 20000;
    const double a = -10 * w, h = 20 * w / n;
    double s = 0;
    for (int i = 0; i <= n; ++i) s += (i == 0 || i == n ? 0.5 : 1.0) * UnitGaussian(w, a + i * h);
    EXPECT_NEAR(s * h, 1.0, 1e-9);
  }
}

TEST(Sadeghi2013Pieces, TangentCurveSampling) {
  // Charmeuse front flat thread: the length-weighted mean tilt of the piecewise-linear curve is
  // sum(len * (a0 + a1) / 2) / sum(len) = 0 by symmetry; the mean |tilt| is
  // (1.33*32 + 0.66*25 + 2*9 + 2*0 + 2*9 + 0.66*25 + 1.33*32) / 9.98 deg. The midpoint rule is
  // exact for the mean of a linear piece; |tilt| is linear on each piece too (no sign change inside).
  const std::vector<double> off = {-32, -32, -18, 0, 0, 18, 32, 32};
  std::vector<double> off_rad;
  for (double o : off) off_rad.push_back(DegToRad(o));
  const std::vector<double> len = {1.33, 0.66, 2, 2, 2, 0.66, 1.33};
  const auto s = SampleTangentCurve(off_rad, len, DegToRad(0.5));
  double wsum = 0, mean = 0, mean_abs = 0;
  for (const auto& t : s) {
    wsum += t.weight;
    mean += t.weight * t.angle;
    mean_abs += t.weight * std::abs(t.angle);
  }
  EXPECT_NEAR(wsum, 1.0, 1e-12);
  EXPECT_NEAR(mean, 0.0, 1e-12);
  const double expect = (1.33 * 32 + 0.66 * 25 + 2 * 9 + 2 * 9 + 0.66 * 25 + 1.33 * 32) / 9.98;
  EXPECT_NEAR(RadToDeg(mean_abs), expect, 1e-9);
  // A zero-length piece is a jump (velvet dir 2: -90..-55, then 55..90): no tilt inside (-55, 55).
  const auto v = SampleTangentCurve({DegToRad(-90), DegToRad(-55), DegToRad(55), DegToRad(90)}, {0.5, 0, 0.5}, DegToRad(0.5));
  for (const auto& t : v) EXPECT_GE(std::abs(t.angle), DegToRad(55) - 1e-12);
  // A constant curve is one sample.
  EXPECT_EQ(SampleTangentCurve({0.0, 0.0}, {1.0}, 0.01).size(), 1u);
}

TEST(Sadeghi2013Model, HandDerivedValueForOneUntiltedThread) {
  // One thread along +y, tilt 0, coverage 1, wi = (0, sin 30, cos 30), wo = its mirror image
  // (0, -sin 30, cos 30). By hand (paper Eqs. 2-4, 7-15):
  //   theta_i = 30, theta_o = -30 -> theta_h = 0, theta_d = 30 deg; both azimuths 0 -> phi_d = 0;
  //   Fr = F(cos 30, eta); surface = Fr * 1 * g(gamma_s, 0) / cos^2 30;
  //   volume = (1 - Fr)^2 ((1 - kd) g(gamma_v, 0) + kd) / (2 cos 30) / cos^2 30;
  //   M = 1 (both azimuth cosines 1); P(t) is the same for the single tangent, so P / Q = 1:
  //   f = surface + volume * A.
  SadeghiParams p;
  p.name = "one thread";
  p.eta = 1.5;
  SadeghiThread t;
  t.label = "t";
  t.along_v = true;
  t.albedo = {0.2, 0.4, 0.8};
  t.kd = 0.3;
  t.gamma_s = DegToRad(5);
  t.gamma_v = DegToRad(10);
  t.coverage = 1;
  t.offsets = {0.0};
  p.threads = {t};
  Sadeghi2013Model m("one", p);
  const double c30 = std::cos(kPi / 6), s30 = 0.5;
  const double fr = FresnelDielectric(c30, 1.5);
  const double gs0 = 1 / (DegToRad(5) * std::sqrt(2 * kPi)), gv0 = 1 / (DegToRad(10) * std::sqrt(2 * kPi));
  const double surface = fr * gs0 / (c30 * c30);
  const double volume = (1 - fr) * (1 - fr) * (0.7 * gv0 + 0.3) / (2 * c30) / (c30 * c30);
  double f[3];
  m.EvalRgb(Vec3(0, s30, c30), Vec3(0, -s30, c30), f);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[c], surface + volume * t.albedo[c], 1e-12 * f[c]);
  // Off the specular cone by 10 deg (wo tilted along the thread): the surface Gaussian drops by
  // exp(-0.5 (5/5)^2) since theta_h = 5 deg (by hand, same pieces otherwise).
  double g[3];
  const Vec3 wo2 = DirectionFromAngles(DegToRad(20), -kPi / 2);  // (0, -sin 20, cos 20)
  m.EvalRgb(Vec3(0, s30, c30), wo2, g);
  const double th_d = DegToRad(25), cos_d = std::cos(th_d);
  const double fr2 = FresnelDielectric(cos_d, 1.5);
  const double surface2 = fr2 * gs0 * std::exp(-0.5) / (cos_d * cos_d);
  const double volume2 =
      (1 - fr2) * (1 - fr2) * (0.7 * gv0 * std::exp(-0.125) + 0.3) / (c30 + std::cos(DegToRad(20))) / (cos_d * cos_d);
  EXPECT_NEAR(g[0], surface2 + volume2 * 0.2, 1e-12 * g[0]);
}

std::vector<Vec3> Dirs(double max_deg) {
  std::vector<Vec3> d;
  for (double t : {0.0, 15.0, 35.0, 60.0, 75.0, 85.0, 89.0, max_deg})
    for (double p = 0; p < 360; p += 30) d.push_back(DirectionFromAngles(DegToRad(t), DegToRad(p + 7)));
  return d;
}

TEST(Sadeghi2013Model, ReciprocityForWatertightFabrics) {
  // Every factor of Eqs. 2-13 is symmetric in (wi, wo); Eq. 15's gap term (1 - a1 - a2)(wo . n) is
  // not, so only fabrics with a1 + a2 = 1 are reciprocal (all but linen_plain, a = 0.33 + 0.33).
  // Linen is reciprocal when wi and wo have the same elevation (then the gap terms agree).
  const auto dirs = Dirs(89.9);
  for (const auto& name : Sadeghi2013PresetNames()) {
    SCOPED_TRACE(name);
    const auto m = MakeSadeghi2013(name);
    const bool linen = name == "linen_plain";
    int checked = 0;
    for (std::size_t i = 0; i < dirs.size(); i += 3)
      for (std::size_t j = 0; j < dirs.size(); j += 5) {
        if (linen && std::abs(dirs[i].z() - dirs[j].z()) > 0) continue;
        double a[3], b[3];
        m->EvalRgb(dirs[i], dirs[j], a);
        m->EvalRgb(dirs[j], dirs[i], b);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 1e-10 * a[c] + 1e-300);
        ++checked;
      }
    EXPECT_GT(checked, 10);
  }
}

TEST(Sadeghi2013Model, FiniteEverywhereAndConstantOverTheTile) {
  // theta up to 89.9 deg both sides, retro-reflection, mirror pairs; below the horizon -> 0.
  const auto dirs = Dirs(89.9);
  for (const auto& name : Sadeghi2013PresetNames()) {
    SCOPED_TRACE(name);
    const auto m = MakeSadeghi2013(name);
    double peak = 0;
    for (const Vec3& wi : dirs)
      for (const Vec3& wo : dirs) {
        double f[3];
        m->EvalRgb(wi, wo, f);
        for (double x : f) {
          ASSERT_TRUE(std::isfinite(x) && x >= 0) << wi.transpose() << " | " << wo.transpose();
          peak = std::max(peak, x);
        }
      }
    EXPECT_GT(peak, 0);
    float a[3], b[3], c[3];
    const Vec3 wi = DirectionFromAngles(0.5, 0.2), wo = DirectionFromAngles(0.7, 2.9);
    m->Eval(Vec2(0.1, 0.2), wi, wo, a);
    m->Eval(Vec2(0.9, 0.6), wi, wo, b);
    m->EvalBrdf(wi, wo, c);
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(a[k], b[k]);
      EXPECT_EQ(a[k], c[k]);
    }
    std::vector<Vec2> uv = {Vec2(0, 0), Vec2(0.5, 0.5)};
    float batch[6];
    m->EvalBatch(wi, wo, uv.data(), 2, batch);
    EXPECT_EQ(batch[3], c[0]);
    double below[3];
    m->EvalRgb(Vec3(0, 0.3, -0.9), wo, below);
    EXPECT_EQ(below[0], 0.0);
    m->EvalRgb(wi, Vec3(0.3, 0, -1e-9), below);
    EXPECT_EQ(below[0], 0.0);
  }
}

TEST(Sadeghi2013Model, PresetsParametersAndErrors) {
  EXPECT_EQ(Sadeghi2013PresetNames().size(), 6u);
  const auto m = MakeSadeghi2013Model("charmeuse_front", {{"eta", 1.6}});
  EXPECT_EQ(m->name(), "sadeghi2013/charmeuse_front");
  const auto d = m->Describe();
  EXPECT_DOUBLE_EQ(d["eta"].get<double>(), 1.6);
  ASSERT_EQ(d["threads"].size(), 2u);
  EXPECT_DOUBLE_EQ(d["threads"][0]["coverage"].get<double>(), 0.9);
  EXPECT_NEAR(d["threads"][0]["gamma_s_deg"].get<double>(), 2.5, 1e-12);
  EXPECT_GE(d["choices"].size(), 5u);
  // The steeper of the flat thread's pieces (-18 .. 0 deg over length 2) needs 36 samples at 0.5 deg.
  EXPECT_GT(d["threads"][0]["tangent_samples"].get<int>(), 100);
  for (const auto& [preset, params, field] : std::vector<std::tuple<std::string, nlohmann::json, std::string>>{
           {"denim", nlohmann::json::object(), "denim"},
           {"velvet", {{"eta", 1.0}}, "eta"},
           {"velvet", {{"eta", "x"}}, "eta"},
           {"velvet", {{"sigma", 10}}, "sigma"},
           {"velvet", {{"tangent_step_deg", 0}}, "tangent_step_deg"}}) {
    try {
      MakeSadeghi2013(preset, params);
      ADD_FAILURE() << preset << " " << params.dump();
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kUsage);
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  }
}

TEST(Sadeghi2013Model, DirectionalAlbedoIsBounded) {
  // Directional albedo rho(wi) = int f cos(theta_o) dwo by a 64 x 64 midpoint grid in the
  // concentric-map square (equal-area cells of 2 pi / 64^2 sr, about 2.2 deg across). The narrowest
  // lobe (gamma_s = 2.5 deg) is then resolved to within ~20 %, far inside the bound tested:
  // rho < 1 (energy conservation; the presets give 0.002 .. 0.31 at 128^2) and rho > 0, per channel.
  const int n = 64;
  for (const auto& name : Sadeghi2013PresetNames()) {
    SCOPED_TRACE(name);
    const auto m = MakeSadeghi2013(name);
    for (double ti : {0.0, 60.0, 85.0})
      for (double pi : {0.0, 90.0}) {
        const Vec3 wi = DirectionFromAngles(DegToRad(ti), DegToRad(pi));
        double rho[3] = {0, 0, 0};
        for (int a = 0; a < n; ++a)
          for (int b = 0; b < n; ++b) {
            const Vec3 wo = HemisphereFromSquare(Vec2((a + 0.5) / n, (b + 0.5) / n));
            double f[3];
            m->EvalRgb(wi, wo, f);
            for (int c = 0; c < 3; ++c) rho[c] += f[c] * wo.z() * 2 * kPi / (n * n);
          }
        for (int c = 0; c < 3; ++c) {
          EXPECT_LT(rho[c], 1.0) << "theta_i " << ti << " phi_i " << pi << " channel " << c;
          if (name != "velvet" || c < 2) {
            EXPECT_GT(rho[c], 1e-4) << "theta_i " << ti << " channel " << c;
          }
        }
      }
  }
}

}  // namespace
}  // namespace btf
