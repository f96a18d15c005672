#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "libbtf/core/error.h"
#include "libbtf/register/detect.h"
#include "tests/register/render_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// Corner RMS of the detections against the true projections of the board corners.
double CornerRms(const std::vector<TagDetection>& dets, const Board& board, const PhotoGeometry& truth, int* matched) {
  double ss = 0;
  int n = 0;
  *matched = 0;
  for (const auto& d : dets)
    for (const auto& m : board.markers)
      if (m.id == d.id) {
        ++*matched;
        for (int k = 0; k < 4; ++k) {
          Vec2 p;
          EXPECT_TRUE(truth.Project(Vec3(m.corners_mm[k].x(), m.corners_mm[k].y(), m.height_mm), &p));
          ss += (d.corners[k] - p).squaredNorm();
          ++n;
        }
      }
  return n ? std::sqrt(ss / n) : 1e9;
}

TEST(Detect, FindsEveryMarkerWithSubPixelCornersInBoardOrder) {
  const Board board = test::MakeRingBoard(40, 8, 0);
  // Corner RMS bound 0.05 px (issue budget 0.1; noise-free renders with 8x8 supersampled edges,
  // measured 0.000 at 0 deg and 0.012 at 60 deg). A wrong 0.5 px pixel-center shift would give
  // >= 0.7 px, a wrong corner order several px.
  for (double theta : {0.0, 45.0, 60.0}) {
    const auto cam = test::LookAt(theta, 30, 300, 900, 700, 2400);
    const Image photo = test::RenderPhoto(cam, board, [](double, double) { return 0.5; });
    TagDetector det;
    const auto dets = det.Detect(photo);
    int matched = 0;
    const double rms = CornerRms(dets, board, cam.Geometry(), &matched);
    std::printf("theta %2.0f: corner RMS %.3f px over %d markers\n", theta, rms, matched);  // docs/btf-register.md
    EXPECT_EQ(matched, 8) << "theta " << theta;
    EXPECT_EQ(dets.size(), 8u);
    EXPECT_LT(rms, 0.05) << "theta " << theta;
    for (const auto& d : dets) {
      EXPECT_EQ(d.hamming, 0);
      EXPECT_GT(d.decision_margin, 50);
    }
  }
}

TEST(Detect, OurEdgeFitRemovesTheBiasOfLibapriltagRefineEdges) {
  // Why refine_edges is off by default: on a frontal render with pixel-aligned edges libapriltag
  // 3.3.0's refinement moves every corner by about (-0.125, -0.125) px; without it the quad is
  // exact here, and our edge fit keeps it exact.
  const Board board = test::MakeRingBoard(40, 8, 0);
  const auto cam = test::LookAt(0, 0, 300, 900, 700, 2400);
  const Image photo = test::RenderPhoto(cam, board, [](double, double) { return 0.5; });
  auto mean_error = [&](const TagDetectorOptions& o) {
    TagDetector det(o);
    Vec2 sum = Vec2::Zero();
    int n = 0;
    for (const auto& d : det.Detect(photo))
      for (int k = 0; k < 4; ++k) {
        Vec2 p;
        const auto& m = board.markers[d.id];
        EXPECT_TRUE(cam.Geometry().Project(Vec3(m.corners_mm[k].x(), m.corners_mm[k].y(), 0), &p));
        sum += d.corners[k] - p;
        ++n;
      }
    EXPECT_EQ(n, 32);
    return Vec2(sum / std::max(n, 1));
  };
  TagDetectorOptions lib;
  lib.refine_edges = true;
  lib.refine_corners = false;
  const Vec2 biased = mean_error(lib);
  EXPECT_NEAR(biased.x(), -0.125, 0.03);
  EXPECT_NEAR(biased.y(), -0.125, 0.03);
  const Vec2 ours = mean_error(TagDetectorOptions{});
  EXPECT_LT(ours.norm(), 0.005);
}

TEST(Detect, DropsTagsCutByTheImageBorder) {
  const Board board = test::MakeRingBoard(40, 8, 0);
  auto cam = test::LookAt(0, 0, 300, 900, 700, 2400);
  cam.model.cx -= 200;  // shift the board left: the left column of markers is cut by the border
  const Image photo = test::RenderPhoto(cam, board, [](double, double) { return 0.5; });
  TagDetector det;
  for (const auto& d : det.Detect(photo))
    for (const auto& c : d.corners) EXPECT_GE(c.x(), det.options().border_margin_px);
}

TEST(Detect, BadOptionsAndFamiliesAreUsageErrors) {
  TagDetectorOptions o;
  o.family = "tag99h1";
  try {
    TagDetector d(o);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
    EXPECT_NE(std::string(e.what()).find("tag36h11"), std::string::npos);  // lists what is known
  }
  o = {};
  o.quad_decimate = 0.5;
  EXPECT_THROW(o.Check(), Error);
  EXPECT_EQ(TagFamilies().size(), 9u + 21u);  // libapriltag's nine and OpenCV's 21 ArUco dictionaries
  o = {};
  o.border_bits = 3;
  EXPECT_THROW(o.Check(), Error);
  o = {};
  o.family = "tagStandard41h12";
  o.border_bits = 2;  // its data bits lie outside the border ring
  EXPECT_THROW(o.Check(), Error);
  o = {};
  o.family = "aruco:DICT_9X9_1";
  EXPECT_THROW(o.Check(), Error);
  // The X-junction refinement's fields, each named in the message.
  o = {};
  o.x_corners = "subpix";
  EXPECT_NE(test::ErrorOf([&] { o.Check(); }).find("x_corners"), std::string::npos);
  o = {};
  o.subpix_window = 0;
  EXPECT_NE(test::ErrorOf([&] { o.Check(); }).find("subpix_window"), std::string::npos);
  o.subpix_window = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(test::ErrorOf([&] { o.Check(); }).find("subpix_window"), std::string::npos);
}

TEST(Detect, GrayIsLinearAndScaledToThe995thPercentile) {
  Image im(100, 10, 3);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 100; ++x)
      for (int c = 0; c < 3; ++c) im.at(x, y, c) = x < 50 ? 0.2f : 0.4f;
  im.at(0, 0, 0) = std::nanf("");
  const auto g = GrayForDetection(im);
  EXPECT_EQ(g[1], 128);  // 0.2 / 0.4 * 255 = 127.5 -> linear, no gamma
  EXPECT_EQ(g[99], 255);
  EXPECT_EQ(g[0], 0);  // a NaN channel makes the pixel 0, never NaN in the detector
}

}  // namespace
}  // namespace btf
