// Accuracy of btf-register per view elevation on btf-synth photos (docs/btf-register.md table).
// Prints the table it asserts: run build-register/tests/test_register_slow to reproduce.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <vector>

#include <Eigen/LU>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/io/dataset_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

using json = nlohmann::json;

// Relative RMS of view v of `reg` against `gt` (light 0), over all texels and over the interior
// (4 texels = 2.5 mm in from the edge): at 75 deg the 1 mm high markers occlude a strip of up to
// h tan(75) = 3.7 mm of the sample edge in the photo itself, which no registration can undo.
std::pair<double, double> RelativeRms(const Dataset& gt, const Dataset& reg, int v) {
  double e = 0, r = 0, ei = 0, ri = 0;
  for (int y = 0; y < reg.height(); ++y)
    for (int x = 0; x < reg.width(); ++x)
      for (int c = 0; c < reg.channels(); ++c) {
        const double a = gt.at(v, 0, y, x, c), b = reg.at(v, 0, y, x, c);
        e += (a - b) * (a - b), r += a * a;
        if (x >= 4 && y >= 4 && x < reg.width() - 4 && y < reg.height() - 4) ei += (a - b) * (a - b), ri += a * a;
      }
  return {std::sqrt(e / r), std::sqrt(ei / ri)};
}

// The table's rig: btf-synth photos of bonn81 `views` (light 0; markers 1 mm above the cloth,
// lens distortion k1 = -0.05, 1280 x 960, default 3 x 3 pixel samples, no noise) in dir/ph, and
// the truth dir/gt.h5 at 64 x 64 with 32 x 32 jittered samples per texel: with 8 x 8 the truth
// itself is 1.5 % off at 60 and 75 deg (0.2 % at 32 x 32 against 64 x 64; test_register_slow
// --gtest_filter=SteepViews.TruthSamplingPoseAndResamplingFilter prints both).
void SynthTableRig(const std::filesystem::path& dir, const std::string& views) {
  const std::string synth = test::Tool("btf-synth");
  ASSERT_EQ(test::RunCommand(synth + " photos --quiet --views " + views + " --lights 0 --marker-height 1 --k1 -0.05 -o " +
                             (dir / "ph").string()),
            0);
  ASSERT_EQ(test::RunCommand(synth + " btf --quiet --views " + views +
                             " --lights 0 --resolution 64 --tiles 10 --samples 32 -o " + (dir / "gt.h5").string() +
                             " 2>/dev/null"),
            0);
}

TEST(RegisterAccuracy, PerElevationUpTo75Degrees) {
  const auto dir = test::TempDir();
  // bonn81 views 0, 1, 9, 25, 45, 70 = 0, 15, 30, 45, 60, 75 deg.
  SynthTableRig(dir, "0,1,9,25,45,70");
  ASSERT_FALSE(HasFatalFailure());
  for (const std::string filter : {"area", "spline"}) {
    std::string out;
    ASSERT_EQ(test::RunCommand(test::Tool("btf-register") + " run --quiet " + (dir / "ph/manifest.json").string() +
                                   " -o " + (dir / ("d-" + filter + ".h5")).string() + " --resolution 64 --filter " +
                                   filter + " --truth " + (dir / "ph/truth.json").string() + " --report " +
                                   (dir / ("r-" + filter + ".json")).string(),
                               &out),
              0)
        << out;
  }
  std::ifstream in(dir / "r-area.json");
  const json rep = json::parse(in);
  const Dataset area = ReadDataset(dir / "d-area.h5"), spline = ReadDataset(dir / "d-spline.h5"),
                gt = ReadDataset(dir / "gt.h5");
  ASSERT_EQ(area.size(), gt.size());
  ASSERT_EQ(spline.size(), gt.size());
  fmt::print("theta  markers  corner_rms_px  homography_rms_px  homography_max_px  rel_rms_all  rel_rms_interior  "
             "spline_all  spline_interior\n");
  for (int v = 0; v < area.num_views(); ++v) {
    const json& p = rep["photos"][v];
    const double theta = RadToDeg(area.views().angles(v).theta);
    const auto [rel, rel_in] = RelativeRms(gt, area, v);
    const auto [rel_s, rel_in_s] = RelativeRms(gt, spline, v);
    const double corner = p["truth_corner_rms_px"], hrms = p["truth_homography_rms_px"], hmax = p["truth_homography_max_px"];
    fmt::print("{:5.0f}  {:7d}  {:13.3f}  {:17.4f}  {:17.4f}  {:11.4f}  {:16.4f}  {:10.4f}  {:15.4f}\n", theta,
               p["markers_found"].get<int>(), corner, hrms, hmax, rel, rel_in, rel_s, rel_in_s);
    EXPECT_EQ(p["status"], "ok");
    // The occlusion warning fires exactly where the table shows the edge strip (75 deg only).
    EXPECT_EQ(p["warnings"].size(), theta > 70 ? 1u : 0u) << theta << " " << p["warnings"].dump();
    // Bounds (measured values in docs/btf-register.md): the homography over the sample within 0.1 px
    // at every elevation up to 75 deg; corners 0.2 px (0-15 deg suffer btf-synth's 3x3 pixel
    // sampling of axis-aligned edges), 0.1 px from 30 to 75 deg.
    EXPECT_LT(hrms, 0.1) << theta;
    EXPECT_LT(corner, theta >= 29 ? 0.1 : 0.2) << theta;
    // Normtexture vs ground truth (interior). The error left is the photo's sampling of the
    // foreshortened texel, not the pose (docs/btf-register.md, "Accuracy at steep views"): measured
    // area 0.012-0.021 up to 60 deg and 0.069 at 75 deg (texel 1.5 px across), spline 0.010-0.015
    // and 0.061. Bounds: 0.03 up to 60 deg, 0.09 at 75 deg; the spline filter must not be worse than
    // area weighting anywhere (+0.002 for the run-to-run-free but view-dependent margin).
    EXPECT_LT(rel_in, theta < 70 ? 0.03 : 0.09) << theta;
    EXPECT_LT(rel_in_s, theta < 70 ? 0.03 : 0.09) << theta;
    EXPECT_LT(rel_in_s, rel_in + 0.002) << theta;
  }
}

// The 2 % bound at 75 deg, for a camera with 3 x the pixels per mm of the table's (3840 x 2880,
// 11 megapixels, same 500 mm and field of view): a texel then spans 4.4 px across its
// foreshortened side instead of 1.5. btf-register run --filter spline against the 32 x 32 truth.
TEST(RegisterAccuracy, SeventyFiveDegreesWithinTwoPercentAtThreeTimesThePixels) {
  const auto dir = test::TempDir();
  const std::string synth = test::Tool("btf-synth");
  ASSERT_EQ(test::RunCommand(synth + " photos --quiet --views 70 --lights 0 --marker-height 1 --k1 -0.05 --width 3840 "
                             "--height 2880 -o " + (dir / "ph").string()),
            0);
  ASSERT_EQ(test::RunCommand(synth + " btf --quiet --views 70 --lights 0 --resolution 64 --tiles 10 --samples 32 -o " +
                             (dir / "gt.h5").string() + " 2>/dev/null"),
            0);
  const Dataset gt = ReadDataset(dir / "gt.h5");
  for (const std::string filter : {"area", "spline"}) {
    std::string out;
    ASSERT_EQ(test::RunCommand(test::Tool("btf-register") + " run --quiet " + (dir / "ph/manifest.json").string() +
                                   " -o " + (dir / "d.h5").string() + " --resolution 64 --filter " + filter +
                                   " --truth " + (dir / "ph/truth.json").string() + " --report " +
                                   (dir / "r.json").string(),
                               &out),
              0)
        << out;
    std::ifstream in(dir / "r.json");
    const json p = json::parse(in)["photos"][0];
    const auto [rel, rel_in] = RelativeRms(gt, ReadDataset(dir / "d.h5"), 0);
    const auto masked = p["masked_texels"]["hidden_by_markers"].get<int>();
    fmt::print("75 deg, 3840 x 2880, filter {}: homography RMS {:.4f} px, rel. RMS all {:.4f}, interior {:.4f}, {} texels "
               "masked (hidden by markers)\n",
               filter, p["truth_homography_rms_px"].get<double>(), rel, rel_in, masked);
    // Measured: spline 0.014 interior (area 0.020, over the 2 %). Bound: the 2 % with spline.
    if (filter == "spline") {
      EXPECT_LT(rel_in, 0.02);
    }
    EXPECT_GT(masked, 0);  // the near edge behind the raised markers is masked and counted
  }
}

// The 2 % bound at 75 deg on the table's 1280 x 960 photos, for a periodic sample: the unit
// tile reconstructed from every photo pixel (--tile-average --tile-method reconstruct) against the
// plain tile average (--tile-average) and the per-texel rectification, at 0, 60 and 75 deg (view 0
// is in the run: the lattice is estimated on the most frontal view, here rectified at 128 x 128:
// at 64 x 64 a twill harmonic aliases and the estimated lattice is wrong, docs/btf-register.md).
TEST(RegisterAccuracy, TileReconstructionAtSteepViews) {
  const auto dir = test::TempDir();
  SynthTableRig(dir, "0,45,70");
  ASSERT_FALSE(HasFatalFailure());
  const Dataset gt = ReadDataset(dir / "gt.h5");
  const std::vector<std::pair<std::string, std::string>> methods = {
      {"rectified", ""}, {"average", " --tile-average --lattice-resolution 128"},
      {"reconstruct", " --tile-average --lattice-resolution 128 --tile-method reconstruct"}};
  std::map<std::string, std::vector<std::pair<double, double>>> rms;
  for (const auto& [name, flags] : methods) {
    std::string out;
    ASSERT_EQ(test::RunCommand(test::Tool("btf-register") + " run --quiet " + (dir / "ph/manifest.json").string() +
                                   " -o " + (dir / (name + ".h5")).string() + " --resolution 64" + flags,
                               &out),
              0)
        << out;
    const Dataset d = ReadDataset(dir / (name + ".h5"));
    ASSERT_EQ(d.size(), gt.size());
    for (int v = 0; v < d.num_views(); ++v) rms[name].push_back(RelativeRms(gt, d, v));
  }
  fmt::print("theta  rectified_all  rectified_interior  average_all  average_interior  reconstruct_all  "
             "reconstruct_interior\n");
  for (int v = 0; v < gt.num_views(); ++v) {
    const double theta = RadToDeg(gt.views().angles(v).theta);
    fmt::print("{:5.0f}  {:13.4f}  {:18.4f}  {:11.4f}  {:16.4f}  {:15.4f}  {:20.4f}\n", theta, rms["rectified"][v].first,
               rms["rectified"][v].second, rms["average"][v].first, rms["average"][v].second,
               rms["reconstruct"][v].first, rms["reconstruct"][v].second);
  }
  // Measured (docs/btf-register.md, "Unit-tile reconstruction"), interior = all texels (the tiling
  // is the same everywhere): reconstruct 0.0028 / 0.0061 / 0.0109 at 0 / 60 / 75 deg, the tile
  // average 0.0546 / 0.0803 / 0.0941, per-texel rectification 0.0079 / 0.0205 / 0.0686 interior.
  // Bounds: about 2 x the measured value at 0 and 60 deg (0.006, 0.012), the 2 % at 75 deg;
  // and better than both other methods at every view.
  for (int v = 0; v < gt.num_views(); ++v) {
    const double theta = RadToDeg(gt.views().angles(v).theta);
    const double bound = theta < 1 ? 0.006 : theta < 70 ? 0.012 : 0.02;
    EXPECT_LT(rms["reconstruct"][v].first, bound) << theta;
    EXPECT_LT(rms["reconstruct"][v].second, bound) << theta;
    EXPECT_LT(rms["reconstruct"][v].second, rms["average"][v].second) << theta;
    EXPECT_LT(rms["reconstruct"][v].second, rms["rectified"][v].second) << theta;
  }
}

TEST(RegisterAccuracy, EveryBonn81ViewRegisters) {
  // All 81 bonn81 views (0-75 deg), one light, small 640 x 480 photos (about 10 px per marker
  // module at 0 deg), markers 0.5 mm high. Every photo must register; the homography over the
  // sample must stay within 0.15 px (measured max 0.079 px, at 75 deg).
  const auto dir = test::TempDir();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " photos --quiet --lights 0 --width 640 --height 480 "
                             "--marker-height 0.5 -o " + (dir / "ph").string()),
            0);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-register") + " run --quiet --json " + (dir / "ph/manifest.json").string() +
                                 " -o " + (dir / "d.h5").string() + " --resolution 64 --truth " +
                                 (dir / "ph/truth.json").string() + " --report " + (dir / "r.json").string(),
                             &out),
            0)
      << out;
  std::ifstream in(dir / "r.json");
  const json rep = json::parse(in);
  ASSERT_EQ(rep["photos_ok"], 81);
  double worst = 0;
  for (const auto& p : rep["photos"]) worst = std::max(worst, p["truth_homography_rms_px"].get<double>());
  fmt::print("bonn81, 81 views: all registered, worst homography RMS {:.4f} px\n", worst);
  EXPECT_LT(worst, 0.15);
}

TEST(RegisterAccuracy, LatticeOfTheTwillMatchesTheModelTile) {
  const auto dir = test::TempDir();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " photos --quiet --views 0 --lights 0,9 -o " + (dir / "ph").string()), 0);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-register") + " run --quiet --json --tile-average " +
                                 (dir / "ph/manifest.json").string() + " -o " + (dir / "d.h5").string() +
                                 " --resolution 128",
                             &out),
            0);
  const json j = json::parse(out);
  const json& L = j["lattice"];
  Eigen::Matrix2d A;
  A << L["a1_texels"][0].get<double>(), L["a2_texels"][0].get<double>(), L["a1_texels"][1].get<double>(),
      L["a2_texels"][1].get<double>();
  // The model tile is 4 mm = 12.8 texels (40 mm at 128 texels). The estimate must generate the tile
  // lattice: (12.8, 0) and (0, 12.8) are integer combinations of a1, a2 (0.01 texel); the twill's
  // smallest repeat is a quarter of the tile (one yarn diagonally, measured area 40.96 texels^2).
  for (const Vec2& t : {Vec2(12.8, 0), Vec2(0, 12.8)}) {
    const Vec2 c = A.inverse() * t;
    const Vec2 back = A * Vec2(c.array().round());
    fmt::print("tile vector ({}, {}) = {:.4f} a1 + {:.4f} a2, error {:.4f} texels\n", t.x(), t.y(), c.x(), c.y(),
               (back - t).norm());
    EXPECT_LT((back - t).norm(), 0.01);
  }
  EXPECT_NEAR(std::abs(A.determinant()), 12.8 * 12.8 / 4, 0.1);
}

}  // namespace
}  // namespace btf
