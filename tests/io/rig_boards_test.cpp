// Board files other than ours (Kalibr AprilGrid YAML), the camera file, and their bad-input errors.
#include <chrono>
#include <fstream>

#include <gtest/gtest.h>

#include "libbtf/core/error.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "tests/test_util.h"

namespace btf {
namespace {

void Write(const std::filesystem::path& p, const std::string& text) { std::ofstream(p) << text; }

// The message of the bad-input error ReadBoard throws (empty if it does not throw one).
std::string BoardError(const std::filesystem::path& p) {
  try {
    ReadBoard(p);
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput) << e.what();
    return e.what();
  }
  return "";
}

TEST(RigBoards, KalibrAprilGridYamlGivesTagsRowMajorFromTheBottomLeft) {
  const auto dir = test::TempDir();
  // Kalibr's documented template, comments included.
  Write(dir / "aprilgrid.yaml",
        "target_type: 'aprilgrid' #gridtype\ntagCols: 6               #number of apriltags\ntagRows: 6               "
        "#number of apriltags\ntagSize: 0.088           #size of apriltag, edge to edge [m]\ntagSpacing: 0.3          "
        "#ratio of space between tags to tagSize\n");
  const Board b = ReadBoard(dir / "aprilgrid.yaml");
  EXPECT_EQ(b.family, "tag36h11");
  EXPECT_EQ(b.border_bits, 2);
  ASSERT_EQ(b.markers.size(), 36u);
  EXPECT_TRUE(b.grid.valid());
  EXPECT_DOUBLE_EQ(b.grid.tag_size_mm, 88.0);
  // Grid side 6 x 88 + 5 x 26.4 = 660 mm, centred: tag 0's bottom-left corner at (-330, -330).
  EXPECT_NEAR(b.markers[0].corners_mm[0].x(), -330, 1e-9);
  EXPECT_NEAR(b.markers[0].corners_mm[0].y(), -330, 1e-9);
  // Counter-clockwise from the bottom left (y up): RB, RT, LT.
  EXPECT_NEAR(b.markers[0].corners_mm[1].x(), -242, 1e-9);
  EXPECT_NEAR(b.markers[0].corners_mm[2].y(), -242, 1e-9);
  EXPECT_NEAR(b.markers[0].corners_mm[3].x(), -330, 1e-9);
  // Ids row-major: tag 1 is right of tag 0, tag 6 above it.
  EXPECT_EQ(b.markers[1].id, 1);
  EXPECT_NEAR(b.markers[1].corners_mm[0].x(), -330 + 88 * 1.3, 1e-9);
  EXPECT_EQ(b.markers[6].id, 6);
  EXPECT_NEAR(b.markers[6].corners_mm[0].y(), -330 + 88 * 1.3, 1e-9);
  EXPECT_NEAR(b.markers[35].corners_mm[2].x(), 330, 1e-9);

  // Our board JSON keeps the grid and the border.
  WriteBoard(dir / "b.json", b);
  const Board r = ReadBoard(dir / "b.json");
  EXPECT_EQ(r.border_bits, 2);
  EXPECT_EQ(r.grid.rows, 6);
  EXPECT_EQ(r.markers.size(), 36u);
}

TEST(RigBoards, CharucoYamlGivesItsMarkersCentredWithYUp) {
  const auto dir = test::TempDir();
  Write(dir / "c.yaml", "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareSize: 0.04\nmarkerSize: 0.03\n"
                        "dictionary: DICT_5X5_100\n");
  const Board b = ReadBoard(dir / "c.yaml");
  EXPECT_EQ(b.family, "aruco:DICT_5X5_100");
  ASSERT_EQ(b.markers.size(), 17u);  // the white squares of a 5 x 7 board
  EXPECT_EQ(b.charuco.squares_x, 5);
  for (const auto& m : b.markers) {
    EXPECT_NEAR(m.corners_mm[1].x() - m.corners_mm[0].x(), 30, 1e-3);  // LB -> RB: +x
    EXPECT_NEAR(m.corners_mm[3].y() - m.corners_mm[0].y(), 30, 1e-3);  // LB -> LT: +y
    for (const auto& c : m.corners_mm) EXPECT_TRUE(std::abs(c.x()) <= 100 && std::abs(c.y()) <= 140);
  }
  WriteBoard(dir / "c.json", b);
  EXPECT_EQ(ReadBoard(dir / "c.json").charuco.dictionary, "DICT_5X5_100");
}

TEST(RigBoards, BadBoardFilesNameFileAndField) {
  const auto dir = test::TempDir();
  Write(dir / "syntax.yaml", "target_type: 'aprilgrid\n");
  EXPECT_NE(BoardError(dir / "syntax.yaml").find("line 1 has a quoted value that does not end"), std::string::npos);
  Write(dir / "missing.yaml", "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSpacing: 0.3\n");
  EXPECT_NE(BoardError(dir / "missing.yaml").find("missing required field 'tagSize'"), std::string::npos);
  Write(dir / "type.yaml", "target_type: checkerboard\ntargetCols: 6\n");
  EXPECT_NE(BoardError(dir / "type.yaml").find("'target_type' is 'checkerboard'"), std::string::npos);
  Write(dir / "num.yaml", "target_type: aprilgrid\ntagCols: 6\ntagRows: six\ntagSize: 0.1\ntagSpacing: 0.3\n");
  EXPECT_NE(BoardError(dir / "num.yaml").find("'tagRows' must be an integer"), std::string::npos);
  Write(dir / "neg.yaml", "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: -0.1\ntagSpacing: 0.3\n");
  EXPECT_NE(BoardError(dir / "neg.yaml").find("'tagSize' must be > 0"), std::string::npos);
  Write(dir / "dict.yaml", "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareSize: 0.04\nmarkerSize: 0.03\n"
                           "dictionary: DICT_9X9_1\n");
  EXPECT_NE(BoardError(dir / "dict.yaml").find("field 'dictionary' is 'DICT_9X9_1'"), std::string::npos);
  Write(dir / "msize.yaml", "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareSize: 0.04\nmarkerSize: 0.05\n"
                            "dictionary: DICT_5X5_100\n");
  EXPECT_NE(BoardError(dir / "msize.yaml").find("'markerSize' must be > 0 and below squareSize"), std::string::npos);
  Write(dir / "many.yaml", "target_type: charuco\nsquaresX: 20\nsquaresY: 20\nsquareSize: 0.04\nmarkerSize: 0.03\n"
                           "dictionary: DICT_4X4_50\n");
  EXPECT_NE(BoardError(dir / "many.yaml").find("needs 200 markers but DICT_4X4_50 has 50"), std::string::npos);
  for (const char* f : {"syntax.yaml", "missing.yaml"}) EXPECT_NE(BoardError(dir / f).find(f), std::string::npos);
  // Our JSON board: a bad border.
  Write(dir / "b.json",
        R"({"format": "libbtf-board", "format_version": "1.0.0", "family": "tag36h11", "sample_size_mm": 40,
            "border_bits": 3, "markers": [{"id": 0, "corners_mm": [[0,0],[1,0],[1,1],[0,1]]}]})");
  EXPECT_NE(BoardError(dir / "b.json").find("border_bits must be 1 or 2"), std::string::npos);
}

// OpenCV's YAML parser recurses once per level: a Kalibr file nested 40,000 deep overflowed the
// stack (exit 139). Only a flat mapping reaches the parser: nesting in flow and block style, and
// what else a Kalibr target never holds (tags, lists, control bytes), is refused before parsing.
TEST(RigBoards, DeeplyNestedYamlIsRefusedBeforeParsing) {
  const auto dir = test::TempDir();
  const std::string flat = "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n";
  Write(dir / "flow.yaml", flat + "extra: " + std::string(40000, '[') + std::string(40000, ']') + "\n");
  Write(dir / "block.yaml", flat + "extra:\n");
  {
    std::ofstream f(dir / "block.yaml", std::ios::app);
    for (int i = 0; i < 40000; ++i) f << "- ";
    f << "x\n";
  }
  Write(dir / "mapping.yaml", flat + "extra: {a: " + std::string(40000, '{') + "}\n");
  Write(dir / "indent.yaml", flat + "extra:\n" + std::string(100, ' ') + "a: 1\n");
  Write(dir / "tag.yaml", flat + "extra: !!str x\n");
  Write(dir / "ctrl.yaml", flat + "extra: a\x12" "b\n");
  for (const auto& [name, problem] : std::vector<std::pair<std::string, std::string>>{
           {"flow.yaml", "line 6 has a flow collection"},
           {"block.yaml", "line 7 is not 'key: value'"},
           {"mapping.yaml", "line 6 has a flow collection"},
           {"indent.yaml", "line 7 is indented"},
           {"tag.yaml", "line 6 has a value starting with '!'"},
           {"ctrl.yaml", "line 6 holds a byte that is not printable ASCII"}}) {
    const std::string what = BoardError(dir / name);
    EXPECT_NE(what.find(name + "': " + problem), std::string::npos) << what;
    EXPECT_NE(what.find("a Kalibr target is one flat mapping"), std::string::npos) << what;
  }
  // Brackets, commas and dashes inside quoted text or comments, negative numbers and "---" are fine.
  Write(dir / "quoted.yaml", "---\n" + flat + "note: '" + std::string(200, '[') + "' # [x, y]\nother: \"- - {{ \\\" [[[\"\n" +
                                 "offset: -0.5 # a comment, with {braces}\nempty:\n\n   \n# end\n");
  EXPECT_EQ(ReadBoard(dir / "quoted.yaml").markers.size(), 36u);
  // A file far beyond any target's size is not parsed.
  Write(dir / "big.yaml", flat + "# " + std::string(2 << 20, 'x') + "\n");
  EXPECT_NE(BoardError(dir / "big.yaml").find("at most 1048576 bytes"), std::string::npos);
}

// Found by fuzz_rig: a YAML whose top level is not a mapping made OpenCV assert in
// FileStorage::operator[] (exit 5), and a 26-byte one made its parser loop forever. Both are bad
// input naming the file, at once; so is a file with no mapping at all.
TEST(RigBoards, YamlThatIsNoFlatMappingIsBadInputAtOnce) {
  const auto dir = test::TempDir();
  Write(dir / "seq.yaml", "- target_type: aprilgrid\n- tagCols: 6\n");
  Write(dir / "assert.yaml", std::string(44, '-') + "\xff\xff" + std::string(18, '-') + "\n!");
  Write(dir / "loop.yaml", "-----,C--\n!---\n!");
  Write(dir / "empty.yaml", "# nothing\n");
  const auto t0 = std::chrono::steady_clock::now();
  for (const char* name : {"seq.yaml", "assert.yaml", "loop.yaml"})
    EXPECT_NE(BoardError(dir / name).find(std::string(name) + "': line 1 "), std::string::npos) << name;
  EXPECT_NE(BoardError(dir / "empty.yaml").find("empty.yaml': not a Kalibr target"), std::string::npos);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2.0);
}

// A ChArUco board whose dictionary is too small is refused from its sizes, before OpenCV builds
// the board (which matched ~10^5 corners against ~5 x 10^4 markers: 15-20 s for 115 bytes).
TEST(RigBoards, CharucoBoardTooLargeForItsDictionaryIsRefusedAtOnce) {
  const auto dir = test::TempDir();
  Write(dir / "c.yaml", "target_type: charuco\nsquaresX: 316\nsquaresY: 316\nsquareSize: 0.04\nmarkerSize: 0.03\n"
                        "dictionary: DICT_4X4_50\n");
  const auto t0 = std::chrono::steady_clock::now();
  const std::string what = BoardError(dir / "c.yaml");
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2.0);
  EXPECT_NE(what.find("c.yaml': the board needs 49928 markers but DICT_4X4_50 has 50"), std::string::npos) << what;
  // Our board JSON's charuco block is checked the same way, naming its own fields.
  Write(dir / "c.json",
        R"({"format": "libbtf-board", "format_version": "1.0.0", "family": "aruco:DICT_4X4_50", "sample_size_mm": 0,
            "charuco": {"squares_x": 1, "squares_y": 7, "square_mm": 40, "marker_mm": 30, "dictionary": "DICT_4X4_50"},
            "markers": [{"id": 0, "corners_mm": [[0,0],[1,0],[1,1],[0,1]]}]})");
  EXPECT_NE(BoardError(dir / "c.json").find("fields 'charuco.squares_x' and 'charuco.squares_y'"), std::string::npos);
}

// Finite but absurd coordinates (1e308 mm) passed every check and reached OpenCV, which asserted
// (exit 5). Board coordinates and sizes must lie within 1 km of the origin: refused as bad input
// naming the file and the item.
TEST(RigBoards, AbsurdCoordinatesAndSizesAreBadInputNamingTheField) {
  const auto dir = test::TempDir();
  const auto board = [&](const std::string& corners, const std::string& extra = "") {
    Write(dir / "b.json", R"({"format": "libbtf-board", "format_version": "1.0.0", "family": "tag36h11",
                             "sample_size_mm": 40, "markers": [{"id": 0, "corners_mm": [[0,0],[1,0],[1,1],[0,1]]},
                             {"id": 7, "corners_mm": )" + corners + "}" + extra + "]}");
    return BoardError(dir / "b.json");
  };
  std::string what = board("[[0,0],[1e308,0],[1,1],[0,1]]");
  EXPECT_NE(what.find("b.json': markers[1] (id 7): corner 1 is (1e+308, 0)"), std::string::npos) << what;
  EXPECT_NE(what.find("within +-1e+06 mm"), std::string::npos) << what;
  what = board(R"([[0,0],[1,0],[1,1],[0,1]], "height_mm": -2e6)");
  EXPECT_NE(what.find("markers[1] (id 7): height_mm is -2000000"), std::string::npos) << what;
  EXPECT_EQ(board("[[0,0],[1e6,0],[1e6,1e6],[0,1e6]]"), "");  // 1 km is still a board
  const std::string grid = "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSpacing: 0.3\ntagSize: ";
  Write(dir / "g.yaml", grid + "1e300\n");
  EXPECT_NE(BoardError(dir / "g.yaml").find("fields 'tagSize' (1e+300 m) and 'tagSpacing'"), std::string::npos);
  Write(dir / "g.yaml", grid + "300\n");  // 6 x 390 m = 2.3 km wide
  EXPECT_NE(BoardError(dir / "g.yaml").find("reaching past +-1e+06 mm"), std::string::npos);
  Write(dir / "s.yaml", "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareSize: 1e300\nmarkerSize: 1e299\n"
                        "dictionary: DICT_5X5_100\n");
  EXPECT_NE(BoardError(dir / "s.yaml").find("field 'squareSize' must be > 0 (metres)"), std::string::npos);
}

TEST(RigBoards, CameraFileRoundTripAndErrors) {
  const auto dir = test::TempDir();
  CameraFile f;
  f.camera.width = 640, f.camera.height = 480;
  f.camera.fx = 500.5, f.camera.fy = 499.5, f.camera.cx = 319.5, f.camera.cy = 239.5;
  f.camera.k1 = -0.15, f.camera.k2 = 0.02, f.camera.p1 = 1e-4, f.camera.p2 = -2e-4, f.camera.k3 = 0.001;
  f.rms_px = 0.02;
  WriteCameraFile(dir / "camera.json", f);
  const CameraFile r = ReadCameraFile(dir / "camera.json");
  EXPECT_EQ(r.camera.model, "radtan");
  EXPECT_EQ(r.camera.width, 640);
  EXPECT_DOUBLE_EQ(r.camera.fx, 500.5);
  EXPECT_DOUBLE_EQ(r.camera.k3, 0.001);
  EXPECT_DOUBLE_EQ(r.camera.p2, -2e-4);
  EXPECT_DOUBLE_EQ(r.rms_px, 0.02);
  // A fisheye camera: k1..k4, no p1, p2.
  f.camera.model = "fisheye";
  f.camera.p1 = f.camera.p2 = 0, f.camera.k4 = -0.003;
  WriteCameraFile(dir / "fisheye.json", f);
  const CameraFile fe = ReadCameraFile(dir / "fisheye.json");
  EXPECT_TRUE(fe.camera.fisheye());
  EXPECT_DOUBLE_EQ(fe.camera.k1, -0.15);
  EXPECT_DOUBLE_EQ(fe.camera.k3, 0.001);
  EXPECT_DOUBLE_EQ(fe.camera.k4, -0.003);
  EXPECT_FALSE(fe.camera.has_extended_distortion());
  Write(dir / "model.json", R"({"model": "pinhole", "image_size": [640, 480], "fx": 500, "fy": 500, "cx": 320, "cy": 240})");
  try {
    ReadCameraFile(dir / "model.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("model.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("must be 'radtan' or 'fisheye'"), std::string::npos) << e.what();
  }
  Write(dir / "bad.json", R"({"image_size": [640, 480], "fx": 500, "fy": 500, "cx": 320, "cy": 240, "k1": 0})");
  try {
    ReadCameraFile(dir / "bad.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("missing required field 'k2'"), std::string::npos) << e.what();
  }
}

TEST(RigBoards, ProjectionWithTangentialAndK3MatchesOpenCvRadtan) {
  // x = 0.2, y = -0.1 (normalised): OpenCV radtan by hand.
  CameraModel c;
  c.fx = 500, c.fy = 510, c.cx = 320, c.cy = 240, c.k1 = -0.1, c.k2 = 0.01, c.p1 = 0.001, c.p2 = -0.002, c.k3 = 0.003;
  Vec2 px;
  ASSERT_TRUE(ProjectToPixel(c, Eigen::Matrix3d::Identity(), Vec3::Zero(), Vec3(0.2, -0.1, 1), &px));
  const double x = 0.2, y = -0.1, r2 = x * x + y * y, f = 1 - 0.1 * r2 + 0.01 * r2 * r2 + 0.003 * r2 * r2 * r2;
  const double xd = x * f + 2 * 0.001 * x * y - 0.002 * (r2 + 2 * x * x);
  const double yd = y * f + 0.001 * (r2 + 2 * y * y) + 2 * -0.002 * x * y;
  EXPECT_NEAR(px.x(), 500 * xd + 320, 1e-12);
  EXPECT_NEAR(px.y(), 510 * yd + 240, 1e-12);
}

TEST(ImageIoColorspace, OverrideDecodesIntegerFilesAsAsked) {
  const auto dir = test::TempDir();
  Image im(4, 1, 1);
  im.pixels = {0.0f, 0.25f, 0.5f, 1.0f};
  ImageWriteOptions wo;
  wo.has_format = true;
  wo.format = PixelFormat::kUint16;
  WriteImage(dir / "lin.png", im, wo);  // tagged linear
  const Image a = ReadImage(dir / "lin.png");
  EXPECT_NEAR(a.pixels[2], 0.5, 1e-4);
  ImageReadOptions srgb;
  srgb.colorspace = "srgb";
  EXPECT_NEAR(ReadImage(dir / "lin.png", srgb).pixels[2], SrgbToLinear(0.5f), 1e-4);
  ImageReadOptions g;
  g.colorspace = "gamma";
  g.gamma = 2.2;
  EXPECT_NEAR(ReadImage(dir / "lin.png", g).pixels[2], std::pow(0.5, 2.2), 1e-4);
  // sRGB-tagged 8-bit PNG and JPEG decode to linear by default.
  wo.format = PixelFormat::kUint8;
  wo.srgb = true;
  WriteImage(dir / "s.png", im, wo);
  EXPECT_NEAR(ReadImage(dir / "s.png").pixels[2], 0.5, 0.01);  // 8-bit sRGB step near 0.5: 0.004
  ImageReadOptions lin;
  lin.colorspace = "linear";
  EXPECT_NEAR(ReadImage(dir / "s.png", lin).pixels[2], LinearToSrgb(0.5f), 0.003);
  ImageReadOptions bad;
  bad.colorspace = "rec709";
  EXPECT_THROW(bad.Check(), Error);
}

}  // namespace
}  // namespace btf
