// Real-rig inputs end to end: Kalibr AprilGrid (2-bit border) photos from btf-synth in 8-bit sRGB
// JPEG with blur and noise, ArUco markers, calibration errors and run --camera.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "libbtf/core/error.h"
#include "libbtf/io/rig.h"
#include "libbtf/register/calibrate.h"
#include "libbtf/register/detect.h"
#include "tests/register/corner_rms.h"
#include "tests/test_util.h"

namespace btf {
namespace {

using json = nlohmann::json;

using test::CornerRms;

TEST(RigCli, AprilGridWithTwoBitBorderInSrgbJpegIsFoundWithBoardCoordinates) {
  // 30 deg view of a 6 x 6 AprilGrid, 640 x 480, 8-bit sRGB JPEG quality 90, blur 0.7 px, noise
  // 0.5 % of full scale, k1 = -0.05. Bound 0.08 px: modules are 5.4 px at 0 deg here and the
  // photo's 3 x 3 samples per pixel quantise edges to 1/3 px (docs/btf-register.md, "Accuracy");
  // the 0.05 px figure at 1024 x 768 with 8 x 8 samples is in rig_slow_test.cpp.
  const auto dir = test::TempDir();
  const std::string synth = test::Tool("btf-synth") +
                            " photos --quiet --target aprilgrid --views 9 --lights 0 --width 640 --height 480 "
                            "--focal 800 --camera-distance 300 --format jpeg --transfer srgb --jpeg-quality 90 "
                            "--blur 0.7 --noise 0.005 --k1 -0.05 -o " + dir.string();
  ASSERT_EQ(test::RunCommand(synth), 0) << synth;
  const auto truth = ReadTruth(dir / "truth.json");
  ASSERT_EQ(truth.size(), 1u);
  ASSERT_EQ(truth[0].marker_corners_px.size(), 36u);
  std::string out;
  const std::string det = test::Tool("btf-register") + " detect --json " + (dir / truth[0].file).string() +
                          " --board " + (dir / "board.json").string();
  ASSERT_EQ(test::RunCommand(det, &out), 0) << det << out;
  const json j = json::parse(out);
  int found = 0;
  const double rms = CornerRms(j, truth[0], &found);
  std::printf("AprilGrid 30 deg, 640x480 JPEG: %d of 36 tags, corner RMS %.4f px\n", found, rms);
  EXPECT_EQ(found, 36);
  EXPECT_LT(rms, 0.08);
  EXPECT_EQ(j["border_bits"], 2);
  // Board coordinates: tag 7 (row 1, column 1), its bottom-left corner.
  const Board board = ReadBoard(dir / "board.json");
  for (const auto& t : j["tags"])
    if (t["id"] == 7) {
      EXPECT_TRUE(t["on_board"].get<bool>());
      EXPECT_NEAR(t["corners_board_mm"][0][0].get<double>(), board.markers[7].corners_mm[0].x(), 1e-9);
      EXPECT_NEAR(t["corners_board_mm"][0][1].get<double>(), board.markers[7].corners_mm[0].y(), 1e-9);
    }
  // A disc PSF of radius 1.4 px (the same second moment as sigma 0.7: R^2 / 4 = sigma^2) instead of
  // the Gaussian: same bound (measured 36 of 36, 0.059 px; a symmetric PSF does not move an edge's
  // 50 % point), the PSF recorded in the manifest.
  const auto disc = dir / "disc";
  std::string cmd = synth;
  cmd.replace(cmd.find("--blur 0.7"), 10, "--psf disc --disc-radius 1.4");
  cmd.replace(cmd.find(dir.string()), dir.string().size(), disc.string());
  ASSERT_EQ(test::RunCommand(cmd), 0) << cmd;
  EXPECT_EQ(ReadManifest(disc / "manifest.json").extra["psf"]["radius_px"], 1.4);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-register") + " detect --json " + (disc / truth[0].file).string() +
                                 " --board " + (disc / "board.json").string(),
                             &out),
            0)
      << out;
  int found_disc = 0;
  const double rms_disc = CornerRms(json::parse(out), truth[0], &found_disc);
  std::printf("AprilGrid 30 deg, 640x480 JPEG, disc PSF r = 1.4 px: %d of 36 tags, corner RMS %.4f px\n", found_disc,
              rms_disc);
  EXPECT_EQ(found_disc, 36);
  EXPECT_LT(rms_disc, 0.08);
  // With the default 1-bit border nothing decodes (the 0 of 36).
  const std::string det1 = test::Tool("btf-register") + " detect --json --family tag36h11 " +
                           (dir / truth[0].file).string();
  ASSERT_EQ(test::RunCommand(det1, &out), 0) << det1 << out;
  EXPECT_EQ(json::parse(out)["tags"].size(), 0u);
}

TEST(RigCli, CharucoCornersOfASyntheticPhotoMatchTheTruth) {
  // 30 deg view (bonn81 view 9) of btf-synth's default ChArUco board (9 x 7 squares, DICT_5X5_100,
  // 85 % of the image at 0 deg) by the wide-angle calibration camera (640 x 480, f = 500 px,
  // k1 = -0.15, k2 = 0.02), 8-bit sRGB PNG, blur 0.7 px, noise 0.5 % of full scale, 3 x 3 samples
  // per pixel. Every corner in view must be found (the whole board is in view); bound 0.12 px RMS
  // against truth.json's charuco_corners (measured 0.091: cornerSubPix's windows stay inside the
  // 7 px white margin around the markers, and its bias there is ~0.07 px even at 16 x 16 samples
  // per pixel; docs/btf-register.md, "Real-rig inputs").
  const auto dir = test::TempDir();
  const std::string synth = test::Tool("btf-synth") +
                            " photos --quiet --target charuco --views 9 --lights 0 --width 640 --height 480 "
                            "--focal 500 --camera-distance 90 --k1 -0.15 --k2 0.02 --format png8 --transfer srgb "
                            "--blur 0.7 --noise 0.005 -o " + dir.string();
  ASSERT_EQ(test::RunCommand(synth), 0) << synth;
  const auto truth = ReadTruth(dir / "truth.json");
  ASSERT_EQ(truth.size(), 1u);
  ASSERT_EQ(truth[0].charuco_corners_px.size(), 48u);  // (9 - 1) x (7 - 1) inner corners, all in view
  const Board board = ReadBoard(dir / "board.json");
  ASSERT_TRUE(board.charuco.valid());
  std::string out;
  const std::string det = test::Tool("btf-register") + " detect --json " + (dir / truth[0].file).string() +
                          " --board " + (dir / "board.json").string();
  ASSERT_EQ(test::RunCommand(det, &out), 0) << det << out;
  const json j = json::parse(out);
  int markers_found = 0;
  const double marker_rms = CornerRms(j, truth[0], &markers_found);
  const std::vector<Vec2> mm = CharucoCornersMm(board.charuco);
  double ss = 0, worst = 0;
  int found = 0;
  for (const auto& c : j["charuco_corners"]) {
    const int id = c["id"].get<int>();
    const auto it = truth[0].charuco_corners_px.find(id);
    ASSERT_NE(it, truth[0].charuco_corners_px.end()) << id;
    const Vec2 p(c["pixel_px"][0].get<double>(), c["pixel_px"][1].get<double>());
    ss += (p - it->second).squaredNorm();
    worst = std::max(worst, (p - it->second).norm());
    ++found;
    EXPECT_NEAR(c["board_mm"][0].get<double>(), mm[static_cast<std::size_t>(id)].x(), 1e-9);
    EXPECT_NEAR(c["board_mm"][1].get<double>(), mm[static_cast<std::size_t>(id)].y(), 1e-9);
  }
  const double rms = found ? std::sqrt(ss / found) : 1e9;
  std::printf("ChArUco 30 deg, 640x480 sRGB PNG: %d of %zu markers (corner RMS %.4f px), %d of 48 chessboard "
              "corners, RMS %.4f px, worst %.4f px\n",
              markers_found, truth[0].marker_corners_px.size(), marker_rms, found, rms, worst);
  EXPECT_EQ(markers_found, static_cast<int>(truth[0].marker_corners_px.size()));
  EXPECT_EQ(found, 48);
  EXPECT_LT(rms, 0.12);
}

TEST(RigDetect, ArucoMarkersInOurCornerOrderAndPixelConvention) {
  // A DICT_5X5_100 marker drawn by OpenCV, 10 px per module, placed at a known offset on white.
  for (int border : {1, 2}) {
    const auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_100);
    const int modules = 5 + 2 * border, side = 10 * modules;
    cv::Mat marker;
    dict->drawMarker(42, side, marker, border);
    const int W = 400, H = 300, x0 = 137, y0 = 81;
    Image im(W, H, 1);
    for (auto& v : im.pixels) v = 0.8f;
    for (int y = 0; y < side; ++y)
      for (int x = 0; x < side; ++x) im.at(x0 + x, y0 + y, 0) = marker.at<unsigned char>(y, x) ? 0.8f : 0.05f;
    TagDetectorOptions o;
    o.family = "aruco:DICT_5X5_100";
    o.border_bits = border;
    const TagDetector det(o);
    const auto d = det.Detect(im);
    ASSERT_EQ(d.size(), 1u) << "border " << border;
    EXPECT_EQ(d[0].id, 42);
    // OpenCV convention: the square spans pixel edges x0 - 0.5 .. x0 + side - 0.5. Order LB, RB, RT, LT.
    const Vec2 lb(x0 - 0.5, y0 + side - 0.5), rb(x0 + side - 0.5, y0 + side - 0.5), rt(x0 + side - 0.5, y0 - 0.5),
        lt(x0 - 0.5, y0 - 0.5);
    const std::array<Vec2, 4> want = {lb, rb, rt, lt};
    for (int k = 0; k < 4; ++k)  // our edge fit on pixel-aligned edges: exact to 0.01 px
      EXPECT_LT((d[0].corners[k] - want[k]).norm(), 0.01) << "border " << border << " corner " << k;
  }
}

TEST(RigDetect, CharucoBoardMarkersMatchTheBoardFile) {
  // OpenCV draws a 5 x 7 ChArUco board (DICT_5X5_100, 40 px squares, 30 px markers, 20 px margin);
  // our detector finds its 17 markers and the homography from the board's corners (mm, from the
  // YAML definition read by ReadBoard) to the detected corners fits all 68 to 0.02 px, which holds
  // only with the right layout, ids, corner order and y direction.
  const auto dir = test::TempDir();
  std::ofstream(dir / "charuco.yaml") << "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareSize: 0.04\n"
                                         "markerSize: 0.03\ndictionary: DICT_5X5_100\n";
  const Board board = ReadBoard(dir / "charuco.yaml");
  ASSERT_EQ(board.markers.size(), 17u);
  EXPECT_EQ(board.family, "aruco:DICT_5X5_100");
  const auto cb = cv::aruco::CharucoBoard::create(5, 7, 0.04f, 0.03f,
                                                  cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_100));
  cv::Mat drawn;
  cb->draw(cv::Size(240, 320), drawn, 20, 1);
  Image im(drawn.cols, drawn.rows, 1);
  for (int y = 0; y < drawn.rows; ++y)
    for (int x = 0; x < drawn.cols; ++x) im.at(x, y, 0) = drawn.at<unsigned char>(y, x) ? 0.8f : 0.05f;
  TagDetectorOptions o;
  o.family = board.family;
  const auto dets = TagDetector(o).Detect(im);
  EXPECT_EQ(dets.size(), 17u);
  std::vector<cv::Point2f> mm, px;
  for (const auto& d : dets)
    for (const auto& m : board.markers)
      if (m.id == d.id)
        for (int k = 0; k < 4; ++k) {
          mm.emplace_back(static_cast<float>(m.corners_mm[k].x()), static_cast<float>(m.corners_mm[k].y()));
          px.emplace_back(static_cast<float>(d.corners[k].x()), static_cast<float>(d.corners[k].y()));
        }
  ASSERT_EQ(mm.size(), 68u);
  const cv::Mat H = cv::findHomography(mm, px, 0);
  ASSERT_FALSE(H.empty());
  std::vector<cv::Point2f> proj;
  cv::perspectiveTransform(mm, proj, H);
  double ss = 0;
  for (std::size_t i = 0; i < proj.size(); ++i) ss += std::pow(proj[i].x - px[i].x, 2) + std::pow(proj[i].y - px[i].y, 2);
  const double rms = std::sqrt(ss / static_cast<double>(proj.size()));
  std::printf("ChArUco 5x7: %zu markers, board-to-image homography RMS %.4f px\n", dets.size(), rms);
  EXPECT_LT(rms, 0.02);
  // Board y up: the image y of a marker with larger board y is smaller.
  EXPECT_LT(H.at<double>(1, 1) / H.at<double>(2, 2), 0);
}

TEST(RigCli, CalibrateWithTooFewViewsNamesTheFilesAndField) {
  const auto dir = test::TempDir();
  const std::string synth = test::Tool("btf-synth") +
                            " photos --quiet --target aprilgrid --views 0,1 --lights 0 --width 320 --height 240 "
                            "--focal 250 --camera-distance 90 --pixel-samples 1 -o " + dir.string();
  ASSERT_EQ(test::RunCommand(synth), 0) << synth;
  std::string out;
  const std::string cal = test::Tool("btf-register") + " calibrate " + (dir / "manifest.json").string() + " --board " +
                          (dir / "board.json").string() + " -o " + (dir / "camera.json").string();
  EXPECT_EQ(test::RunCommand(cal + " 2>&1", &out), 3) << out;
  EXPECT_NE(out.find("2 usable photos of 2, at least 3 needed (min_views)"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "camera.json"));
  // run needs a sample region: a calibration target's manifest fails fast.
  const std::string run = test::Tool("btf-register") + " run " + (dir / "manifest.json").string() + " -o " +
                          (dir / "d.h5").string() + " 2>&1";
  EXPECT_EQ(test::RunCommand(run, &out), 3) << out;
  EXPECT_NE(out.find("sample_size_mm is 0"), std::string::npos) << out;
  // A bad model is a usage error.
  EXPECT_EQ(test::RunCommand(cal + " --model pinhole 2>&1", &out), 2) << out;
  // A board file that does not parse: exit 3 naming the file.
  std::ofstream(dir / "bad.yaml") << "target_type: aprilgrid\ntagRows: 6\n";
  const std::string bad = test::Tool("btf-register") + " calibrate " + (dir / "manifest.json").string() +
                          " --board " + (dir / "bad.yaml").string() + " -o " + (dir / "c.json").string() + " 2>&1";
  EXPECT_EQ(test::RunCommand(bad, &out), 3) << out;
  EXPECT_NE(out.find("bad.yaml"), std::string::npos) << out;
  EXPECT_NE(out.find("missing required field 'tagCols'"), std::string::npos) << out;
}

// btf-synth ring photos (`synth_flags`), the manifest's camera, and `btf-register run
// --resolution 8 --truth` on them, whose report Run(extra flags) returns.
struct CameraRun {
  std::filesystem::path dir = test::TempDir();
  CameraFile manifest_camera;
  std::string out;  // the last command's output

  explicit CameraRun(const std::string& synth_flags) {
    const std::string synth = test::Tool("btf-synth") + " photos --quiet --lights 0 --width 480 --height 360 " +
                              synth_flags + " -o " + dir.string();
    EXPECT_EQ(test::RunCommand(synth), 0) << synth;
    manifest_camera.camera = ReadManifest(dir / "manifest.json").photos.at(0).camera;
  }
  // " --camera FILE" for `cf` written as dir/name.
  std::string CameraFlag(const std::string& name, const CameraFile& cf) const {
    WriteCameraFile(dir / name, cf);
    return " --camera " + (dir / name).string();
  }
  json Run(const std::string& extra) {
    const std::string run = test::Tool("btf-register") + " run --quiet --json " + (dir / "manifest.json").string() +
                            " --resolution 8 --truth " + (dir / "truth.json").string() + " --report " +
                            (dir / "r.json").string() + " -o " + (dir / "d.h5").string() + extra;
    EXPECT_EQ(test::RunCommand(run, &out), 0) << out;
    std::ifstream in(dir / "r.json");
    return json::parse(in);
  }
};

TEST(RigCli, RunTakesTheCameraFromCameraJson) {
  // Ring photos with k1 = -0.05: run with a camera.json holding the true intrinsics registers as
  // with the manifest's; one with a wrong fx fails the reprojection bound or moves the pose.
  CameraRun c("--views 0 --pixel-samples 1 --k1 -0.05");
  const json r = c.Run(c.CameraFlag("camera.json", c.manifest_camera));
  EXPECT_LT(r["photos"][0]["truth_homography_rms_px"].get<double>(), 0.1);
  CameraFile wrong = c.manifest_camera;
  wrong.camera.fx *= 1.05, wrong.camera.fy *= 1.05;
  const json r2 = c.Run(" --allow-missing" + c.CameraFlag("wrong.json", wrong));
  EXPECT_EQ(r2["photos"][0]["model"], "pose");
  EXPECT_GT(r2["photos"][0]["reprojection_rms_px"].get<double>(), r["photos"][0]["reprojection_rms_px"].get<double>());
}

TEST(RigLens, FisheyeProjectionIsOpenCvsAndUndistortionInvertsIt) {
  // cv::fisheye::projectPoints (alpha 0) is the reference; 1e-9 px is rounding (values ~ 1e3 px).
  CameraModel c;
  c.model = "fisheye";
  c.width = 640, c.height = 480, c.fx = 500, c.fy = 505, c.cx = 319.5, c.cy = 239.5;
  c.k1 = 0.08, c.k2 = -0.02, c.k3 = 0.004, c.k4 = -0.001;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.4, Vec3(1, 2, 0.5).normalized()).toRotationMatrix();
  const Vec3 t(3, -2, 90);
  std::vector<cv::Point3d> pts;
  for (double x : {-60.0, -20.0, 0.0, 35.0, 70.0})
    for (double y : {-50.0, 0.0, 0.01, 45.0}) pts.emplace_back(x, y, 1.5);
  cv::Mat rvec, Rm;
  cv::eigen2cv(R, Rm);
  cv::Rodrigues(Rm, rvec);
  const cv::Mat tvec = (cv::Mat_<double>(3, 1) << t.x(), t.y(), t.z());
  const cv::Mat K = (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
  const cv::Mat D = (cv::Mat_<double>(4, 1) << c.k1, c.k2, c.k3, c.k4);
  std::vector<cv::Point2d> ref;
  cv::fisheye::projectPoints(pts, ref, rvec, tvec, K, D);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    Vec2 px;
    ASSERT_TRUE(ProjectToPixel(c, R, t, Vec3(pts[i].x, pts[i].y, pts[i].z), &px));
    EXPECT_NEAR(px.x(), ref[i].x, 1e-9) << i;
    EXPECT_NEAR(px.y(), ref[i].y, 1e-9) << i;
    // Back to the ray: Newton converges to 1e-12 in the normalized plane.
    const Vec3 cam = R * Vec3(pts[i].x, pts[i].y, pts[i].z) + t;
    Vec2 ray;
    ASSERT_TRUE(UndistortNormalized(c, Vec2((px.x() - c.cx) / c.fx, (px.y() - c.cy) / c.fy), &ray));
    EXPECT_NEAR(ray.x(), cam.x() / cam.z(), 1e-12) << i;
    EXPECT_NEAR(ray.y(), cam.y() / cam.z(), 1e-12) << i;
  }
  // Degenerate: the centre maps to itself; beyond what the lens reaches (theta_d = 3 rad, past 90
  // degrees) there is no ray; a lens whose theta_d(theta) folds back (k1 = -0.9) has none past its fold.
  Vec2 ray;
  ASSERT_TRUE(UndistortNormalized(c, Vec2(0, 0), &ray));
  EXPECT_EQ(ray, Vec2(0, 0));
  EXPECT_FALSE(UndistortNormalized(c, Vec2(3, 0), &ray));
  CameraModel fold = c;
  fold.k1 = -0.9, fold.k2 = fold.k3 = fold.k4 = 0;  // theta_d peaks at theta = 0.61 rad, 0.405
  EXPECT_FALSE(UndistortNormalized(fold, Vec2(0.45, 0), &ray));
  EXPECT_TRUE(UndistortNormalized(fold, Vec2(0.3, 0), &ray));
}

TEST(RigCli, RunTakesAFisheyeCameraFromCameraJson) {
  // RunTakesTheCameraFromCameraJson through a fisheye lens (k1..k4 = 0.05, -0.01, 0, 0), at 0 and
  // 45 deg, same bound on the homography against the truth (0.1 px). 3 x 3 samples per pixel (the
  // radtan test's 1 x 1 quantises corners to whole pixels: 0.44 px corner RMS at 0 deg, which left
  // 0.115 px on the homography here and 0.032 with radtan, by chance of where the edges fall; with
  // 3 x 3: 0.029 and 0.003 px). The manifest records the fisheye camera (run uses it), camera.json
  // replaces it; a camera.json that drops the lens (radtan, no distortion) is worse by more than 3x
  // (measured 0.175 and 0.101 px).
  CameraRun c("--views 0,25 --pixel-samples 3 --lens fisheye --fisheye-k 0.05,-0.01,0,0");
  ASSERT_TRUE(c.manifest_camera.camera.fisheye());
  EXPECT_EQ(c.manifest_camera.camera.k2, -0.01);
  json fisheye;
  for (const std::string& extra : {std::string(), c.CameraFlag("camera.json", c.manifest_camera)}) {
    const json r = c.Run(extra);
    fisheye = r;
    for (const auto& p : r["photos"]) {
      std::printf("fisheye%s: %s homography RMS %.4f px, reprojection %.4f px\n", extra.empty() ? " (manifest)" : "",
                  p["file"].get<std::string>().c_str(), p["truth_homography_rms_px"].get<double>(),
                  p["reprojection_rms_px"].get<double>());
      EXPECT_EQ(p["model"], "pose");
      EXPECT_LT(p["truth_homography_rms_px"].get<double>(), 0.1) << p["file"];
    }
  }
  CameraFile pinhole = c.manifest_camera;
  pinhole.camera.model = "radtan";
  pinhole.camera.k1 = pinhole.camera.k2 = 0;
  const json r = c.Run(" --allow-missing" + c.CameraFlag("pinhole.json", pinhole));
  for (std::size_t i = 0; i < r["photos"].size(); ++i)
    EXPECT_GT(r["photos"][i]["truth_homography_rms_px"].get<double>(),
              3 * fisheye["photos"][i]["truth_homography_rms_px"].get<double>())
        << r["photos"][i]["file"];
}

}  // namespace
}  // namespace btf
