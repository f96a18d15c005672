// The issue #13 "done when" checks on btf-synth ground truth (slow: tens of seconds).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include <nlohmann/json.hpp>

#include "libbtf/io/rig.h"
#include "tests/test_util.h"

namespace btf {
namespace {

using json = nlohmann::json;

TEST(RigAccuracy, CalibrateRecoversTheWideAngleCamera) {
  // 15 photos of the default 6 x 6 AprilGrid (2-bit border) by a 640 x 480 camera with f = 500 px,
  // k1 = -0.15, k2 = 0.02, views 0-14 of bonn81 (0, 15 and 30 deg), 90 mm away. The truth: fx = fy =
  // 500, cx = 319.5, cy = 239.5 (btf-synth's image centre), k1, k2 as given, p1 = p2 = k3 = 0.
  // Bounds from the issue: fx, fy within 0.2 %, k1 within 2 %, RMS <= 0.1 px.
  const auto dir = test::TempDir();
  const std::string synth = test::Tool("btf-synth") +
                            " photos --quiet --target aprilgrid --views 0-14 --lights 0 --width 640 --height 480 "
                            "--focal 500 --camera-distance 90 --k1 -0.15 --k2 0.02 -o " + dir.string();
  ASSERT_EQ(test::RunCommand(synth), 0) << synth;
  std::string out;
  const std::string cal = test::Tool("btf-register") + " calibrate --quiet --json " + (dir / "manifest.json").string() +
                          " --board " + (dir / "board.json").string() + " -o " + (dir / "camera.json").string();
  ASSERT_EQ(test::RunCommand(cal, &out), 0) << cal << out;
  const json j = json::parse(out);
  const CameraFile c = ReadCameraFile(dir / "camera.json");
  std::printf("fx %.4f fy %.4f cx %.4f cy %.4f k1 %.6f k2 %.6f p1 %.2e p2 %.2e k3 %.2e RMS %.4f px, %d views\n",
              c.camera.fx, c.camera.fy, c.camera.cx, c.camera.cy, c.camera.k1, c.camera.k2, c.camera.p1, c.camera.p2,
              c.camera.k3, c.rms_px, j["views_used"].get<int>());
  EXPECT_EQ(j["views_used"], 15);
  EXPECT_LT(std::abs(c.camera.fx / 500 - 1), 0.002);
  EXPECT_LT(std::abs(c.camera.fy / 500 - 1), 0.002);
  EXPECT_LT(std::abs(c.camera.k1 / -0.15 - 1), 0.02);
  EXPECT_LE(c.rms_px, 0.1);
  EXPECT_EQ(c.camera.width, 640);
  EXPECT_TRUE(j["outliers"].empty());
  // camera.json keys of the issue.
  std::ifstream in(dir / "camera.json");
  const json cj = json::parse(in);
  for (const char* k : {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "rms_px", "image_size"})
    EXPECT_TRUE(cj.contains(k)) << k;
}

}  // namespace
}  // namespace btf
