#include "libbtf/core/directions.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "libbtf/core/error.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(Directions, AnglesRoundTrip) {
  for (double t : {0.0, 1e-9, 0.3, 1.0, kPi / 2 - 1e-6, kPi / 2})
    for (double p : {-3.0, -1.0, 0.0, 0.5, 3.1}) {
      const Vec3 d = DirectionFromAngles(t, p);
      EXPECT_NEAR(d.norm(), 1.0, 1e-15);
      const Angles a = AnglesFromDirection(d);
      EXPECT_NEAR(a.theta, t, 1e-12);
      if (t > 1e-6) {
        EXPECT_NEAR(a.phi, p, 1e-9);
      }
    }
  // Frame: phi = 0 is +x (weft), phi = 90 deg is +y (warp), theta = 0 is the normal.
  EXPECT_TRUE(DirectionFromAngles(kPi / 2, 0).isApprox(Vec3::UnitX()));
  EXPECT_TRUE(DirectionFromAngles(kPi / 2, kPi / 2).isApprox(Vec3::UnitY()));
  EXPECT_TRUE(DirectionFromAngles(0, 1).isApprox(Vec3::UnitZ()));
}

TEST(Directions, HalfAndDifferenceVectors) {
  const Vec3 wi = DirectionFromAngles(0.7, 0.2), wo = DirectionFromAngles(0.4, 2.5);
  const Vec3 h = HalfVector(wi, wo);
  EXPECT_NEAR(h.norm(), 1, 1e-15);
  EXPECT_NEAR(h.dot(wi), h.dot(wo), 1e-15);  // symmetric about h
  // The difference vector has polar angle theta_d with cos(theta_d) = wi . h.
  const Vec3 d = DifferenceVector(wi, wo);
  EXPECT_NEAR(d.z(), wi.dot(h), 1e-12);
  EXPECT_NEAR(d.norm(), 1, 1e-12);
  // Degenerate wi = -wo: documented fallback to the normal, no NaN.
  EXPECT_TRUE(HalfVector(Vec3::UnitX(), -Vec3::UnitX()).isApprox(Vec3::UnitZ()));
}

TEST(Directions, ConcentricMapRoundTripIncludingWedgeBoundariesAndPole) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec2> pts{{0.5, 0.5}, {0, 0}, {1, 1}, {0, 1}, {1, 0}, {0.75, 0.75}, {0.25, 0.75}, {0.5, 1}, {0.5, 0}};
  for (int i = 0; i < 2000; ++i) pts.emplace_back(u(rng), u(rng));
  for (const Vec2& st : pts) {
    const Vec2 xy = ConcentricSquareToDisk(st);
    EXPECT_LE(xy.norm(), 1 + 1e-12);
    EXPECT_LT((ConcentricDiskToSquare(xy) - st).norm(), 1e-9) << st.transpose();
    const Vec3 w = HemisphereFromSquare(st);
    EXPECT_NEAR(w.norm(), 1, 1e-12);
    EXPECT_GE(w.z(), -1e-15);
    EXPECT_LT((SquareFromHemisphere(w) - st).norm(), 1e-6) << st.transpose();
  }
  EXPECT_TRUE(HemisphereFromSquare({0.5, 0.5}).isApprox(Vec3::UnitZ()));
}

TEST(Directions, ElevatedLiftIsEqualArea) {
  // Uniform samples on the square must be uniform in solid angle, so z = cos(theta) is uniform
  // on [0, 1]: E[z] = 1/2 and E[z^2] = 1/3. The map is continuous and piecewise smooth, so the
  // midpoint rule on a 400 x 400 grid is accurate to about 1e-5; 1e-4 leaves margin while a
  // non-equal-area lift (e.g. the orthographic one, E[z] = 2/3) fails by orders of magnitude.
  const int n = 400;
  double mean_z = 0, mean_z2 = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double z = HemisphereFromSquare({(i + 0.5) / n, (j + 0.5) / n}).z();
      mean_z += z;
      mean_z2 += z * z;
    }
  mean_z /= n * n;
  mean_z2 /= n * n;
  EXPECT_NEAR(mean_z, 0.5, 1e-4);
  EXPECT_NEAR(mean_z2, 1.0 / 3.0, 1e-4);
}

TEST(Sampling, Bonn81Layout) {
  const Sampling s = Sampling::Bonn81();
  ASSERT_EQ(s.size(), 81);
  const int counts[] = {1, 6, 12, 18, 20, 24};
  int k = 0;
  for (int r = 0; r < 6; ++r)
    for (int i = 0; i < counts[r]; ++i, ++k) {
      EXPECT_NEAR(RadToDeg(s.angles(k).theta), 15.0 * r, 1e-9);
      if (r > 0) {
        double phi = RadToDeg(s.angles(k).phi);
        if (phi < -1e-9) phi += 360;
        EXPECT_NEAR(phi, i * 360.0 / counts[r], 1e-9);
      }
    }
  EXPECT_EQ(Sampling::Ubo151().size(), 151);
}

TEST(Sampling, NearestAndBarycentric) {
  const Sampling s = Sampling::Bonn81();
  for (int i = 0; i < s.size(); ++i) {
    EXPECT_EQ(s.Nearest(s[i]), i);
    const Interpolant ip = s.Barycentric(s[i]);
    // Exact at sampled directions.
    double w_self = 0;
    for (int k = 0; k < ip.count; ++k)
      if (ip.index[k] == i) w_self += ip.weight[k];
    EXPECT_NEAR(w_self, 1, 1e-9);
  }
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(0, 1);
  for (int it = 0; it < 500; ++it) {
    const Vec3 d = DirectionFromAngles(DegToRad(75 * u(rng)), 2 * kPi * u(rng));
    const Interpolant ip = s.Barycentric(d);
    ASSERT_EQ(ip.count, 3);
    double sum = 0;
    Vec3 mix = Vec3::Zero();
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(ip.weight[k], 0);
      sum += ip.weight[k];
      mix += ip.weight[k] * s[ip.index[k]];
    }
    EXPECT_NEAR(sum, 1, 1e-12);
    // The weights reproduce the query direction when it lies inside the triangle of its three
    // nearest samples; with clamping it stays within the local spacing (<= 15 deg rings).
    EXPECT_GT(mix.normalized().dot(d), std::cos(DegToRad(8)));
    EXPECT_EQ(ip.index[0], s.Nearest(d));
  }
}

TEST(Sampling, FromFileAndErrors) {
  const auto dir = test::TempDir();
  {
    std::ofstream f(dir / "dirs.txt");
    f << "# theta phi\n0 0\n45 90  # comment\n\n80 -30\n";
  }
  const Sampling s = Sampling::Named((dir / "dirs.txt").string());
  ASSERT_EQ(s.size(), 3);
  EXPECT_NEAR(RadToDeg(s.angles(1).theta), 45, 1e-9);
  EXPECT_NEAR(RadToDeg(s.angles(2).phi), -30, 1e-9);
  {
    std::ofstream f(dir / "bad.txt");
    f << "10 20\n30 x\n";
  }
  try {
    Sampling::FromFile(dir / "bad.txt");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Sampling::Named("no-such-sampling"), Error);
}

}  // namespace
}  // namespace btf
