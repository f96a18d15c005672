// btf-synth photos' real-camera options: AprilGrid target, border bits, encodings, blur.
#include <gtest/gtest.h>

#include "libbtf/core/error.h"
#include "libbtf/synth/apriltag_render.h"
#include "libbtf/synth/photo_synth.h"

namespace btf {
namespace {

TEST(PhotoOptions, NewOptionsAreCheckedByName) {
  const auto bad = [](auto edit, const char* field) {
    PhotoOptions o;
    edit(o);
    try {
      o.Check();
      ADD_FAILURE() << "no error for " << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kUsage);
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  bad([](PhotoOptions& o) { o.format = "tiff"; }, "format");
  bad([](PhotoOptions& o) { o.transfer = "gamma"; }, "transfer");
  bad([](PhotoOptions& o) { o.format = "exr", o.transfer = "srgb"; }, "transfer");
  bad([](PhotoOptions& o) { o.jpeg_quality = 0; }, "jpeg-quality");
  bad([](PhotoOptions& o) { o.blur_px = -1; }, "blur");
  bad([](PhotoOptions& o) { o.target = "checkerboard"; }, "target");
  bad([](PhotoOptions& o) { o.target = "charuco", o.charuco_dictionary = "DICT_APRILTAG_36h11"; }, "charuco-dictionary");
  bad([](PhotoOptions& o) { o.charuco_squares_x = 1; }, "charuco-squares-x");
  bad([](PhotoOptions& o) { o.charuco_square_mm = 10, o.charuco_marker_mm = 10; }, "charuco-marker-mm");
  bad([](PhotoOptions& o) { o.border_bits = 3; }, "border-bits");
  bad([](PhotoOptions& o) { o.grid_spacing = 0; }, "grid-spacing");
  bad([](PhotoOptions& o) { o.pixel_aspect = 0; }, "pixel-aspect");
  PhotoOptions ok;
  ok.format = "jpeg", ok.transfer = "srgb", ok.blur_px = 0.7, ok.target = "aprilgrid";
  EXPECT_NO_THROW(ok.Check());
}

TEST(PhotoOptions, PixelAspectGivesNonSquarePixels) {
  PhotoOptions o;
  o.target = "aprilgrid", o.width = 640, o.height = 480, o.focal_px = 500, o.pixel_aspect = 1.1;
  const Board board = MakeBoard(o, 1.0);
  const CameraPose cam = MakeCamera(o, board, Vec3(0, 0, 1));
  EXPECT_EQ(cam.camera.fx, 500);
  EXPECT_NEAR(cam.camera.fy, 550, 1e-12);
  // A plate point off the axis lands 1.1 x further from the principal point vertically.
  Vec2 p;
  ASSERT_TRUE(cam.Project(Vec3(10, 10, 0), &p));
  EXPECT_NEAR((p.y() - cam.camera.cy) / (p.x() - cam.camera.cx), -1.1, 1e-9);  // image y points down
}

TEST(PhotoOptions, AprilGridBoardFillsTheImageAtTheGivenFocal) {
  PhotoOptions o;
  o.target = "aprilgrid";
  o.width = 640, o.height = 480, o.focal_px = 500, o.camera_distance_mm = 90;
  const Board b = MakeBoard(o, 4.0);
  EXPECT_EQ(b.markers.size(), 36u);
  EXPECT_EQ(b.border_bits, 2);
  EXPECT_EQ(b.sample_size_mm, 0);
  // Grid side 7.5 tags = 85 % of 480 px at f = 500, 90 mm: 0.85 * 480 * 90 / 500 / 7.5 mm per tag.
  EXPECT_NEAR(b.grid.tag_size_mm, 0.85 * 480 * 90 / 500 / 7.5, 1e-12);
  EXPECT_NEAR(b.markers[35].corners_mm[2].x(), 0.85 * 480 * 90 / 500 / 2, 1e-9);
  // Without a focal: Kalibr's 88 mm.
  o.focal_px = 0;
  EXPECT_DOUBLE_EQ(MakeBoard(o, 4.0).grid.tag_size_mm, 88.0);
}

TEST(PhotoOptions, TwoBitBorderTagKeepsTheDataBitsInside) {
  const TagBitmap one = RenderTag("tag36h11", 5), two = RenderTag("tag36h11", 5, 2);
  EXPECT_EQ(one.total_width, 10);
  EXPECT_EQ(two.total_width, 12);
  EXPECT_EQ(two.width_at_border, 10);
  // Quiet ring white, 2-module border black, the 6 x 6 data the same as with 1 bit.
  for (int i = 0; i < 12; ++i) {
    EXPECT_EQ(two.at(0, i), 1);
    EXPECT_EQ(two.at(1, i), i == 0 || i == 11 ? 1 : 0);
    EXPECT_EQ(two.at(2, i), i == 0 || i == 11 ? 1 : 0);  // rows 1-2 and 9-10, columns 1-2 and 9-10: border
    EXPECT_EQ(two.at(i, 2), i == 0 || i == 11 ? 1 : 0);
    EXPECT_EQ(two.at(10, i), i == 0 || i == 11 ? 1 : 0);
  }
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) EXPECT_EQ(two.at(3 + r, 3 + c), one.at(2 + r, 2 + c)) << r << " " << c;
  EXPECT_THROW(RenderTag("tagStandard41h12", 0, 2), Error);
}

}  // namespace
}  // namespace btf
