// Photo synthesis: real tag36h11 codes (checked against libapriltag's own bitmap and detector),
// the truth file's geometry, and the round trip photos -> rectification with the true
// homography -> the ground-truth normtextures.
#include "libbtf/synth/photo_synth.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagStandard41h12.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/synth/apriltag_render.h"
#include "libbtf/synth/btf_generator.h"
#include "libbtf/synth/irawan2006.h"
#include "tests/synth_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(AprilTagRender, MatchesLibraryBitmap) {
  struct Fam {
    const char* name;
    apriltag_family_t* (*create)();
    void (*destroy)(apriltag_family_t*);
  };
  for (const Fam& f : {Fam{"tag36h11", tag36h11_create, tag36h11_destroy},
                       Fam{"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy}}) {
    apriltag_family_t* fam = f.create();
    for (int id : {0, 1, 5, 100, static_cast<int>(fam->ncodes) - 1}) {
      const TagBitmap t = RenderTag(f.name, id);
      image_u8_t* im = apriltag_to_image(fam, id);
      ASSERT_EQ(im->width, t.total_width);
      for (int r = 0; r < t.total_width; ++r)
        for (int c = 0; c < t.total_width; ++c)
          ASSERT_EQ(t.at(r, c) != 0, im->buf[r * im->stride + c] > 127) << f.name << " id " << id << " " << r << "," << c;
      std::free(im->buf);  // image_u8_destroy lives in libapriltag-utils, which we do not link
      std::free(im);
    }
    f.destroy(fam);
  }
  EXPECT_THROW(RenderTag("tag36h11", 587), Error);
  EXPECT_THROW(RenderTag("aruco", 0), Error);
}

struct Detection {
  int id;
  std::array<Vec2, 4> corners;  // OpenCV pixel convention
};

std::vector<Detection> Detect(const Image& img) {
  std::vector<std::uint8_t> gray(static_cast<std::size_t>(img.width) * img.height);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const double g = (img.at(x, y, 0) + img.at(x, y, 1) + img.at(x, y, 2)) / 3;
      gray[static_cast<std::size_t>(y) * img.width + x] = static_cast<std::uint8_t>(std::clamp(g * 255 + 0.5, 0.0, 255.0));
    }
  image_u8_t im{img.width, img.height, img.width, gray.data()};
  apriltag_family_t* tf = tag36h11_create();
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family_bits(td, tf, 1);
  td->quad_decimate = 1;
  td->nthreads = 1;
  zarray_t* dets = apriltag_detector_detect(td, &im);
  std::vector<Detection> out;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d;
    zarray_get(dets, i, &d);
    Detection det{d->id, {}};
    for (int k = 0; k < 4; ++k) det.corners[k] = Vec2(d->p[k][0] - 0.5, d->p[k][1] - 0.5);  // AprilTag: corner origin
    out.push_back(det);
  }
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(td);
  tag36h11_destroy(tf);
  return out;
}

TEST(PhotoSynth, MarkersAreDetectedWhereTruthSaysUpTo75Degrees) {
  const auto model = MakeIrawan2006Model("twill");
  PhotoOptions o;
  o.width = 960;
  o.height = 720;  // 14 px per module at 0 deg (>= 12 needed for 75 deg)
  o.pixel_samples = 3;
  const Board board = MakeBoard(o, model->tile_size_mm());
  // bonn81: 0 = 0 deg, 19 = 45 deg, 69 = 75 deg (phi 0), 80 = 75 deg.
  for (int view : {0, 19, 69, 80}) {
    const Vec3 v = o.views[view];
    const CameraPose cam = MakeCamera(o, board, v);
    Image img = RenderPhoto(*model, board, o, cam, v, o.lights[0]);
    double peak = 0;
    for (float x : img.pixels) peak = std::max(peak, double(x));
    for (float& x : img.pixels) x = static_cast<float>(x / peak);
    const auto dets = Detect(img);
    int matched = 0;
    double worst = 0;
    Vec2 mean_offset = Vec2::Zero();
    for (const Marker& m : board.markers) {
      std::array<Vec2, 4> truth;
      bool visible = true;
      for (int k = 0; k < 4; ++k) visible &= cam.Project(Vec3(m.corners_mm[k].x(), m.corners_mm[k].y(), 0), &truth[k]);
      ASSERT_TRUE(visible);
      for (const Detection& d : dets)
        if (d.id == m.id) {
          ++matched;
          for (int k = 0; k < 4; ++k) {
            worst = std::max(worst, (d.corners[k] - truth[k]).norm());
            mean_offset += (d.corners[k] - truth[k]) / 32.0;
          }
        }
    }
    EXPECT_EQ(matched, 8) << "view " << view;
    EXPECT_EQ(dets.size(), 8u) << "no false or duplicate detections";
    // A wrong corner order would put corners a tag side (> 100 px) off; a pixel-convention error
    // would show as a common offset of 0.5 px. What remains is AprilTag 3.3.0's own corner noise
    // (integer-truncated edge refinement on 8-bit gray): measured up to 0.5 px per corner at
    // 75 deg and a mean offset under 0.12 px.
    EXPECT_LT(mean_offset.norm(), 0.2) << "view " << view;
    EXPECT_LT(worst, 0.7) << "view " << view;
  }
}

TEST(PhotoSynth, TruthCornersHoldWithDistortionAndRaisedMarkers) {
  // truth.json's corners come from the projection model (marker plane z = h, then distortion);
  // the picture comes from ray casting (inverse distortion, ray-plane hits). Detection in the
  // written PNG must land on the truth corners: the same bounds as above.
  const auto model = MakeIrawan2006Model("twill");
  PhotoOptions o;
  o.view_indices = {19};
  o.light_indices = {0};
  o.width = 960;
  o.height = 720;
  o.k1 = -0.08;
  o.k2 = 0.02;
  o.marker_height_mm = 1.5;
  const auto dir = test::TempDir();
  SynthesizePhotos(o, *model, dir, {});
  const auto truth = ReadTruth(dir / "truth.json");
  const Image img = ReadImage(dir / truth[0].file);
  const auto dets = Detect(img);
  ASSERT_EQ(dets.size(), 8u);
  ASSERT_EQ(truth[0].marker_corners_px.size(), 8u);
  Vec2 mean_offset = Vec2::Zero();
  double worst = 0;
  for (const Detection& d : dets) {
    const auto& t = truth[0].marker_corners_px.at(d.id);
    for (int k = 0; k < 4; ++k) {
      mean_offset += (d.corners[k] - t[k]) / 32.0;
      worst = std::max(worst, (d.corners[k] - t[k]).norm());
    }
  }
  EXPECT_LT(mean_offset.norm(), 0.2);
  EXPECT_LT(worst, 0.7);
  // And the effects are real: ignoring the height or the distortion moves corners by > 1 px.
  const Board board = ReadBoard(dir / "board.json");
  const CameraPose cam = MakeCamera(o, board, o.views[19]);
  Vec2 flat;
  ASSERT_TRUE(cam.Project(Vec3(board.markers[0].corners_mm[0].x(), board.markers[0].corners_mm[0].y(), 0), &flat));
  EXPECT_GT((flat - truth[0].marker_corners_px.at(0)[0]).norm(), 1.0);
}

// Averages photo values over each texel footprint of the sample region (K x K points per texel
// mapped through the homography, bilinear in the photo): a minimal rectifier for the test.
std::vector<double> Rectify(const Image& img, const Eigen::Matrix3d& H, double sample_mm, int N, int K) {
  std::vector<double> out(static_cast<std::size_t>(N) * N * 3, 0.0);
  for (int row = 0; row < N; ++row)
    for (int col = 0; col < N; ++col)
      for (int j = 0; j < K; ++j)
        for (int i = 0; i < K; ++i) {
          const double x = -sample_mm / 2 + (col + (i + 0.5) / K) / N * sample_mm;
          const double y = sample_mm / 2 - (row + (j + 0.5) / K) / N * sample_mm;
          const Eigen::Vector3d p = H * Eigen::Vector3d(x, y, 1);
          const double px = p.x() / p.z(), py = p.y() / p.z();
          const int x0 = static_cast<int>(std::floor(px)), y0 = static_cast<int>(std::floor(py));
          const double fx = px - x0, fy = py - y0;
          for (int c = 0; c < 3; ++c) {
            const double v = (1 - fx) * (1 - fy) * img.at(x0, y0, c) + fx * (1 - fy) * img.at(x0 + 1, y0, c) +
                             (1 - fx) * fy * img.at(x0, y0 + 1, c) + fx * fy * img.at(x0 + 1, y0 + 1, c);
            out[(static_cast<std::size_t>(row) * N + col) * 3 + c] += v / (K * K);
          }
        }
  return out;
}

TEST(PhotoSynth, RectifiedPhotosReproduceGroundTruthNormtextures) {
  const auto model = MakeIrawan2006Model("twill");
  PhotoOptions o;
  o.view_indices = {0, 7, 19};  // 0, 30, 45 deg
  o.light_indices = {0, 9};
  o.width = 1280;
  o.height = 960;
  o.pixel_samples = 3;
  o.sample_tiles = 10;
  o.irregularity = 0.02;  // the BTF below uses the same warp: irregular but identical
  const auto dir = test::TempDir() / "photos";
  const PhotoSummary sum = SynthesizePhotos(o, *model, dir, {});
  ASSERT_EQ(sum.photos, 6);
  const Manifest man = ReadManifest(dir / "manifest.json");
  const auto truth = ReadTruth(dir / "truth.json");
  const Board board = ReadBoard(dir / man.board_file);
  ASSERT_EQ(man.photos.size(), 6u);
  ASSERT_EQ(truth.size(), 6u);
  EXPECT_EQ(man.bit_depth, 16);
  // Ground truth: the same texel grid over the sample region (20 texels = 2 per tile).
  constexpr int N = 20;
  BtfOptions bo;
  bo.views = o.views.Subset(o.view_indices);
  bo.lights = o.lights.Subset(o.light_indices);
  bo.resolution = N;
  bo.tiles = o.sample_tiles;
  bo.samples = 16;
  bo.irregularity = o.irregularity;
  bo.irregularity_seed = o.irregularity_seed;
  const Dataset gt = test::GenerateDataset(*model, bo);
  double max_rel_rms = 0, max_mean_err = 0;
  for (std::size_t k = 0; k < man.photos.size(); ++k) {
    const PhotoEntry& e = man.photos[k];
    EXPECT_EQ(truth[k].file, e.file);
    EXPECT_EQ(truth[k].marker_corners_px.size(), 8u);
    const Image img = ReadImage(dir / e.file);
    // 18 px per texel at 0 deg; 40 x 40 points per texel (0.45 px apart): dense enough that the
    // average of bilinear lookups equals the box average over the footprint (no aliasing).
    auto rect = Rectify(img, truth[k].image_from_plate, board.sample_size_mm, N, 40);
    const double E = e.light_intensity * e.light_dir.z();  // directional light
    const int v = static_cast<int>(std::find(o.view_indices.begin(), o.view_indices.end(), e.view_index) -
                                   o.view_indices.begin());
    const int l = static_cast<int>(std::find(o.light_indices.begin(), o.light_indices.end(), e.light_index) -
                                   o.light_indices.begin());
    const auto g = gt.image(v, l);
    double se = 0, sg = 0, mean_r = 0, mean_g = 0;
    // The outer ring of texels is left out: there the photo's pixels mix material and paper.
    for (int row = 1; row < N - 1; ++row)
      for (int col = 1; col < N - 1; ++col)
        for (int c = 0; c < 3; ++c) {
          const std::size_t i = (static_cast<std::size_t>(row) * N + col) * 3 + c;
          const double r = rect[i] / (e.exposure * E);
          se += (r - g[i]) * (r - g[i]);
          sg += double(g[i]) * g[i];
          mean_r += r;
          mean_g += g[i];
        }
    max_rel_rms = std::max(max_rel_rms, std::sqrt(se / sg));
    max_mean_err = std::max(max_mean_err, std::abs(mean_r - mean_g) / mean_g);
    const double rel_rms = std::sqrt(se / sg), mean_err = std::abs(mean_r - mean_g) / mean_g;
    // The mean is preserved by the pixel box filter and bilinear resampling away from the
    // sample border; 0.2 % covers 16-bit quantization and the supersampling of both sides
    // (measured <= 0.06 %).
    EXPECT_LT(mean_err, 0.002) << e.file;
    // Per texel, the photo's pixel box filter and the bilinear lookup blur texel edges by about
    // one pixel against texels of 13-18 px: 2 % relative RMS bounds that blur (measured
    // 0.6-1.0 %); a wrong homography, radiometry or uv mapping gives tens of percent.
    EXPECT_LT(rel_rms, 0.02) << e.file;
  }
  RecordProperty("max_rel_rms", std::to_string(max_rel_rms));
  RecordProperty("max_mean_err", std::to_string(max_mean_err));
}

TEST(PhotoSynth, ExrPhotosHoldRadianceAndPointLightFalloff) {
  const auto model = MakeIrawan2006Model("plain");
  PhotoOptions o;
  o.view_indices = {0};
  o.light_indices = {0};
  o.width = 320;
  o.height = 240;
  o.pixel_samples = 2;
  o.format = "exr";
  o.light_distance_mm = 400;
  const auto dir = test::TempDir();
  SynthesizePhotos(o, *model, dir, {});
  const Manifest man = ReadManifest(dir / "manifest.json");
  ASSERT_EQ(man.bit_depth, 0);
  EXPECT_EQ(man.photos[0].exposure, 1);
  EXPECT_EQ(man.photos[0].light_intensity, 400.0 * 400.0);  // auto: irradiance 1 at the center
  const Image img = ReadImage(dir / man.photos[0].file);
  const auto truth = ReadTruth(dir / "truth.json");
  // White paper near a plate corner: L = 0.8/pi * I cos / r^2 exactly (pixel fully on paper).
  const Board board = ReadBoard(dir / "board.json");
  // Detection squares end at 40 mm, cards (quiet zone) at 42 mm, the paper at 46 mm.
  ASSERT_NEAR(board.markers[0].corners_mm[0].x(), -40, 1e-9);
  const Vec3 P(-44, 0, 0);
  const Eigen::Vector3d p = truth[0].image_from_plate * Eigen::Vector3d(P.x(), P.y(), 1);
  const int px = static_cast<int>(std::lround(p.x() / p.z())), py = static_cast<int>(std::lround(p.y() / p.z()));
  const Vec3 L = Vec3(0, 0, 400) - P;
  const double expect = 0.8 / kPi * 160000 * (L.z() / L.norm()) / L.squaredNorm();
  // The pixel's footprint (~0.09 mm) changes r^2 by < 1e-4: 1e-3 relative covers that and float
  // storage.
  EXPECT_NEAR(img.at(px, py, 1), expect, 1e-3 * expect);
  EXPECT_LT(expect, 0.8 / kPi * 0.99);  // falloff is really there
}

TEST(PhotoSynth, SelectionAndBadOptions) {
  PhotoOptions o;
  o.view_indices = {0, 1, 7, 19};
  o.light_indices = {0, 3, 9};
  EXPECT_EQ(SelectPhotos(o).size(), 12u);
  o.max_photos = 5;
  const auto s = SelectPhotos(o);
  ASSERT_EQ(s.size(), 5u);
  for (std::size_t i = 1; i < s.size(); ++i) EXPECT_NE(s[i], s[i - 1]);
  o.view_indices = {81};
  EXPECT_THROW(o.Check(), Error);
  o.view_indices = {0};
  o.format = "jpg";
  EXPECT_THROW(o.Check(), Error);
}

}  // namespace
}  // namespace btf
