// Board / manifest / truth files: round trips are exact (JSON doubles print with full precision),
// and malformed files are refused with a message naming the file and the field.
#include <fstream>
#include <functional>

#include <Eigen/Geometry>

#include <gtest/gtest.h>

#include "libbtf/core/error.h"
#include "libbtf/io/rig.h"
#include "tests/test_util.h"

namespace btf {
namespace {

Board TwoMarkerBoard() {
  Board b;
  b.sample_size_mm = 30;
  for (int id : {3, 7}) {
    Marker m;
    m.id = id;
    const double x0 = id * 10.0;
    m.corners_mm = {Vec2(x0, 0), Vec2(x0 + 8, 0), Vec2(x0 + 8, 8), Vec2(x0, 8)};
    m.height_mm = 0.25 * id;
    b.markers.push_back(m);
  }
  return b;
}

void WriteText(const std::filesystem::path& p, const std::string& s) { std::ofstream(p) << s; }


TEST(RigIo, BoardRoundTrip) {
  const auto dir = test::TempDir();
  const Board b = TwoMarkerBoard();
  WriteBoard(dir / "board.json", b);
  const Board r = ReadBoard(dir / "board.json");
  ASSERT_EQ(r.markers.size(), 2u);
  EXPECT_EQ(r.family, "tag36h11");
  EXPECT_EQ(r.sample_size_mm, 30);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(r.markers[i].id, b.markers[i].id);
    EXPECT_EQ(r.markers[i].height_mm, b.markers[i].height_mm);
    for (int k = 0; k < 4; ++k) EXPECT_EQ(r.markers[i].corners_mm[k], b.markers[i].corners_mm[k]);
  }
}

TEST(RigIo, ManifestAndTruthRoundTrip) {
  const auto dir = test::TempDir();
  Manifest m;
  m.board_file = "board.json";
  m.views = Sampling::Bonn81().Subset({0, 5});
  m.lights = Sampling::Bonn81();
  m.bit_depth = 16;
  PhotoEntry e;
  e.file = "v005_l010.png";
  e.view_index = 1;
  e.light_index = 10;
  e.view_dir = m.views[1];
  e.light_dir = m.lights[10];
  e.exposure = 0.3;
  e.light_intensity = 2.5;
  e.light_distance_mm = 1000;
  e.camera_distance_mm = 400;
  e.camera = CameraModel{640, 480, 1000.5, 1001, 319.5, 239.5, -0.05, 0.01};
  m.photos.push_back(e);
  m.extra = {{"model", "irawan2006"}};
  WriteManifest(dir / "manifest.json", m);
  const Manifest r = ReadManifest(dir / "manifest.json");
  EXPECT_EQ(r.board_file, "board.json");
  EXPECT_EQ(r.views.size(), 2);
  EXPECT_EQ(r.views.name(), m.views.name());
  EXPECT_EQ(r.lights.size(), 81);
  EXPECT_EQ(r.bit_depth, 16);
  ASSERT_EQ(r.photos.size(), 1u);
  const PhotoEntry& p = r.photos[0];
  EXPECT_EQ(p.file, e.file);
  EXPECT_EQ(p.view_index, 1);
  EXPECT_EQ(p.light_index, 10);
  EXPECT_NEAR((p.view_dir - e.view_dir).norm(), 0, 1e-15);  // renormalized on read: last-bit changes only
  EXPECT_EQ(p.exposure, 0.3);
  EXPECT_EQ(p.light_distance_mm, 1000);
  EXPECT_EQ(p.camera.fx, 1000.5);
  EXPECT_EQ(p.camera.k1, -0.05);
  EXPECT_EQ(r.extra["model"], "irawan2006");

  PhotoTruth t;
  t.file = e.file;
  t.image_from_plate << 10, 0.5, 320, -0.25, -9, 240, 1e-4, 2e-4, 1;
  t.camera_from_plate_rotation = Eigen::AngleAxisd(0.3, Vec3(0, 1, 0)).toRotationMatrix();
  t.camera_from_plate_translation = Vec3(1, 2, 400);
  t.marker_corners_px[3] = {Vec2(1, 2), Vec2(3, 4), Vec2(5, 6), Vec2(7, 8)};
  WriteTruth(dir / "truth.json", {t});
  const auto rt = ReadTruth(dir / "truth.json");
  ASSERT_EQ(rt.size(), 1u);
  EXPECT_EQ(rt[0].image_from_plate, t.image_from_plate);
  EXPECT_EQ(rt[0].camera_from_plate_rotation, t.camera_from_plate_rotation);
  EXPECT_EQ(rt[0].camera_from_plate_translation, t.camera_from_plate_translation);
  ASSERT_EQ(rt[0].marker_corners_px.count(3), 1u);
  EXPECT_EQ(rt[0].marker_corners_px.at(3)[2], Vec2(5, 6));
}

TEST(RigIo, BadFilesNameFileAndField) {
  const auto dir = test::TempDir();
  ExitCode code{};
  // Missing file: I/O error.
  std::string msg = test::ErrorOf([&] { ReadBoard(dir / "nope.json"); }, &code);
  EXPECT_EQ(code, ExitCode::kIo);
  EXPECT_NE(msg.find("nope.json"), std::string::npos);
  // Not JSON.
  WriteText(dir / "b.json", "{ not json");
  msg = test::ErrorOf([&] { ReadBoard(dir / "b.json"); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  // Duplicate ids.
  Board b = TwoMarkerBoard();
  b.markers[1].id = 3;
  msg = test::ErrorOf([&] { WriteBoard(dir / "dup.json", b); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(msg.find("duplicate marker id 3"), std::string::npos) << msg;
  EXPECT_FALSE(std::filesystem::exists(dir / "dup.json"));
  // A missing field names its path.
  WriteText(dir / "m.json",
            R"({"format":"libbtf-board","format_version":"1.0.0","family":"tag36h11","sample_size_mm":40,
                "markers":[{"id":1,"corners_mm":[[0,0],[1,0],[1,1]]}]})");
  msg = test::ErrorOf([&] { ReadBoard(dir / "m.json"); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(msg.find("markers[0].corners_mm"), std::string::npos) << msg;
  EXPECT_NE(msg.find("m.json"), std::string::npos) << msg;
  // Newer major version.
  WriteText(dir / "v.json", R"({"format":"libbtf-board","format_version":"2.0.0"})");
  msg = test::ErrorOf([&] { ReadBoard(dir / "v.json"); }, &code);
  EXPECT_NE(msg.find("newer"), std::string::npos) << msg;
  // Manifest: index outside the sampling.
  Manifest m;
  m.board_file = "board.json";
  m.views = Sampling::Bonn81().Subset({0});
  m.lights = Sampling::Bonn81().Subset({0});
  PhotoEntry e;
  e.file = "a.png";
  e.view_index = 0;
  e.light_index = 0;
  e.camera = CameraModel{10, 10, 10, 10, 5, 5, 0, 0};
  m.photos = {e};
  WriteManifest(dir / "man.json", m);
  EXPECT_NO_THROW(ReadManifest(dir / "man.json"));
  m.photos[0].light_index = 4;
  WriteManifest(dir / "man.json", m);
  msg = test::ErrorOf([&] { ReadManifest(dir / "man.json"); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(msg.find("photos[0].light_index"), std::string::npos) << msg;
}

}  // namespace
}  // namespace btf
