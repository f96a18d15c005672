// Where the registration error at steep views comes from: each candidate cause
// measured on its own against btf-synth truth, at 60 and 75 deg (bonn81 views 45 and 70).
// docs/btf-register.md, "Accuracy at steep views", gives the table these tests print:
//   build-dev/tests/test_register_slow --gtest_filter='SteepViews.*'
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <array>
#include <map>
#include <mutex>

#include <Eigen/LU>
#include <fmt/format.h>

#include "libbtf/io/dataset_io.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/register/radiometry.h"
#include "libbtf/register/rectify.h"
#include "libbtf/synth/model.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

constexpr int kN = 64;         // normtexture side, as RegisterAccuracy.PerElevationUpTo75Degrees
constexpr int kEdge = 4;       // "interior" leaves out 4 texels (2.5 mm) at the edge, as that test
const std::string kViews = "45,70";  // 60 and 75 deg
// The accuracy table's rig: markers 1 mm above the cloth, lens k1 = -0.05, 1280 x 960, camera at
// 500 mm (btf-synth photos defaults otherwise: focal length so the plate fills 90 % of the height).
const std::string kRig = " --lights 0 --marker-height 1 --k1 -0.05";

struct Rel {
  double all = 0, interior = 0;
};

// Relative RMS of `test` against `ref` over all texels and over the interior.
Rel Compare(const Image& ref, const Image& test) {
  EXPECT_EQ(ref.width, test.width);
  EXPECT_EQ(ref.channels, test.channels);
  double e = 0, r = 0, ei = 0, ri = 0;
  for (int y = 0; y < ref.height; ++y)
    for (int x = 0; x < ref.width; ++x)
      for (int c = 0; c < ref.channels; ++c) {
        const double a = ref.at(x, y, c), b = test.at(x, y, c), d2 = (a - b) * (a - b);
        e += d2, r += a * a;
        if (x >= kEdge && y >= kEdge && x < ref.width - kEdge && y < ref.height - kEdge) ei += d2, ri += a * a;
      }
  return {std::sqrt(e / r), std::sqrt(ei / ri)};
}

Image ImageOf(const Dataset& d, int v) {
  Image im(d.width(), d.height(), d.channels());
  const auto s = d.image(v, 0);
  std::copy(s.begin(), s.end(), im.pixels.begin());
  return im;
}

// Runs a tool command once per process and caches its output folder/file by the command's arguments.
fs::path Cached(const std::string& kind, const std::string& args) {
  static std::mutex mu;
  static std::map<std::string, fs::path> cache;
  std::lock_guard<std::mutex> lock(mu);
  const std::string key = kind + "|" + args;
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  static const fs::path base = test::TempDir();  // the first caller's folder: later tests do not clear it
  const fs::path dir = base / fmt::format("set{}", cache.size());
  fs::create_directories(dir);
  const fs::path out = kind == "photos" ? dir / "ph" : dir / "gt.h5";
  const std::string cmd = test::Tool("btf-synth") + " " + kind + " --quiet " + args + " -o " + out.string() + " 2>/dev/null";
  EXPECT_EQ(test::RunCommand(cmd), 0) << cmd;
  return cache[key] = out;
}

// Photos of views 45 and 70 (60, 75 deg) with the accuracy rig plus `extra` btf-synth options.
fs::path Photos(const std::string& extra = "") { return Cached("photos", "--views " + kViews + kRig + " " + extra); }

// btf-synth btf truth of the same views at N = 64, S x S jittered samples per texel.
Dataset Truth(int samples) {
  return ReadDataset(Cached("btf", fmt::format("--views {} --lights 0 --resolution {} --tiles 10 --samples {}", kViews,
                                               kN, samples)));
}

struct PhotoOf {
  Manifest manifest;
  PhotoEntry entry;
  PhotoTruth truth;
  Image image;
  double sample_mm = 0;
};

PhotoOf LoadPhoto(const fs::path& dir, int k) {
  PhotoOf p;
  p.manifest = ReadManifest(dir / "manifest.json");
  p.entry = p.manifest.photos.at(static_cast<std::size_t>(k));
  for (const PhotoTruth& t : ReadTruth(dir / "truth.json"))
    if (t.file == p.entry.file) p.truth = t;
  ImageReadOptions ro;
  ro.colorspace = "linear";  // btf-synth's default: linear 16-bit PNG
  p.image = ReadImage(dir / p.entry.file, ro);
  p.sample_mm = ReadBoard(dir / "board.json").sample_size_mm;
  return p;
}

PlateToPixel TrueProjection(const PhotoOf& p) {
  return [&p](const Vec2& q, Vec2* px) {
    return ProjectToPixel(p.entry.camera, p.truth.camera_from_plate_rotation, p.truth.camera_from_plate_translation,
                          Vec3(q.x(), q.y(), 0), px);
  };
}

// The k-th photo of `dir` rectified with the TRUE pose (truth.json) and converted to BRDF: the
// error left is the photo's and the resampling filter's, not the pose's.
Image RectifyTruePose(const fs::path& dir, int k, const RectifyOptions& ro) {
  const PhotoOf p = LoadPhoto(dir, k);
  Image tex = Rectify(p.image, TrueProjection(p), p.sample_mm, ro);
  ApplyRadiometry(tex, p.entry, p.sample_mm);
  return tex;
}

RectifyOptions Rect() {
  RectifyOptions ro;
  ro.resolution = kN;
  return ro;
}

// btf-register run on `dir` (fitted pose, masks, radiometry): view slot k of the dataset.
Image Pipeline(const fs::path& dir, int k, const std::string& extra = "") {
  const fs::path out = dir.parent_path() / fmt::format("d{}.h5", std::hash<std::string>{}(extra) % 100000);
  const std::string cmd = test::Tool("btf-register") + " run --quiet " + (dir / "manifest.json").string() + " -o " +
                          out.string() + fmt::format(" --resolution {} ", kN) + extra;
  std::string log;
  EXPECT_EQ(test::RunCommand(cmd, &log), 0) << cmd << "\n" << log;
  return ImageOf(ReadDataset(out), k);
}

const char* Theta(int k) { return k == 0 ? "60" : "75"; }

TEST(SteepViews, TruthSamplingPoseAndResamplingFilter) {
  const Dataset gt8 = Truth(8), gt32 = Truth(32), gt64 = Truth(64);
  const fs::path ph = Photos();
  for (int k = 0; k < 2; ++k) {
    const Image t8 = ImageOf(gt8, k), t32 = ImageOf(gt32, k);
    const Rel truth_self = Compare(t32, t8), truth32 = Compare(ImageOf(gt64, k), t32);
    fmt::print("{} deg: truth 32x32 vs 64x64 {:.4f} / {:.4f}\n", Theta(k), truth32.all, truth32.interior);
    const Rel pipe = Compare(t32, Pipeline(ph, k));
    const Rel pose = Compare(t32, RectifyTruePose(ph, k, Rect()));
    RectifyOptions dense = Rect();
    dense.samples_per_px = 16;
    dense.max_samples_per_axis = 64;
    const Rel dense_r = Compare(t32, RectifyTruePose(ph, k, dense));
    fmt::print("{} deg: truth 8x8 vs 32x32 {:.4f} / {:.4f}; pipeline {:.4f} / {:.4f}; true pose {:.4f} / {:.4f}; true pose, "
               "16 samples/px {:.4f} / {:.4f}  (all / interior)\n",
               Theta(k), truth_self.all, truth_self.interior, pipe.all, pipe.interior, pose.all, pose.interior,
               dense_r.all, dense_r.interior);
    // Measured (60 / 75 deg, interior): truth 8x8 0.0145 / 0.0149 off the 32x32 one, which is
    // 0.0019 / 0.0020 off 64x64; pipeline 0.0205 / 0.0686, true pose 0.0206 / 0.0680; 16 samples
    // per px 0.0191 / 0.0672. So: the 32x32 truth is a reference to 0.5 %; the 8x8 truth is not.
    EXPECT_LT(truth32.interior, 0.005);
    EXPECT_GT(truth_self.interior, 0.01);
    // The pose is not the limit: the true pose changes the result by less than 0.003.
    EXPECT_NEAR(pipe.interior, pose.interior, 0.003);
    // Nor the rectifier's sample count: 4x denser sampling gains less than 0.003.
    EXPECT_NEAR(dense_r.interior, pose.interior, 0.003);
  }
}

TEST(SteepViews, PhotoPixelSamplingAndResolution) {
  const Dataset gt32 = Truth(32);
  std::map<std::string, Rel> at75;
  for (const std::string extra : {"", "--pixel-samples 8", "--width 2560 --height 1920"}) {
    const fs::path ph = Photos(extra);
    for (int k = 0; k < 2; ++k) {
      const Rel r = Compare(ImageOf(gt32, k), RectifyTruePose(ph, k, Rect()));
      fmt::print("{} deg, photos '{}': true pose {:.4f} / {:.4f}\n", Theta(k), extra, r.all, r.interior);
      if (k == 1) at75[extra] = r;
    }
  }
  // Measured at 75 deg (interior): 0.0680 (3 x 3 samples per pixel), 0.0621 (8 x 8), 0.0291 (twice
  // the pixels per mm). The photo's resolution is the limit: doubling it must more than halve the
  // error less 10 %; btf-synth's own pixel supersampling moves it by less than 0.01.
  EXPECT_LT(at75["--width 2560 --height 1920"].interior, 0.55 * at75[""].interior);
  EXPECT_NEAR(at75["--pixel-samples 8"].interior, at75[""].interior, 0.01);
}

// A real rig sees every texel from its own direction (camera at 500 mm: up to 3.2 deg off the
// nominal one at the 40 mm sample's corners), while the truth is evaluated at the nominal direction.
// --true-directions renders that; --camera-distance 5000 (btf-synth scales the automatic focal
// length with the distance, so the sample covers the same pixels) removes it.
TEST(SteepViews, Perspective) {
  const Dataset gt32 = Truth(32);
  std::map<std::string, std::array<Rel, 2>> r;
  for (const std::string extra :
       {"", "--true-directions", "--camera-distance 5000", "--camera-distance 5000 --true-directions"}) {
    const fs::path ph = Photos(extra);
    for (int k = 0; k < 2; ++k) {
      r[extra][k] = Compare(ImageOf(gt32, k), RectifyTruePose(ph, k, Rect()));
      fmt::print("{} deg, photos '{}': true pose {:.4f} / {:.4f}\n", Theta(k), extra, r[extra][k].all,
                 r[extra][k].interior);
    }
  }
  // Measured (60 / 75 deg, interior): nominal 0.0206 / 0.0680, true directions 0.0250 / 0.0687;
  // at 5000 mm 0.0224 / 0.0635 and 0.0225 / 0.0636. Perspective is a small part at 60 deg and
  // negligible at 75 deg; with a far camera it vanishes (bound 0.002).
  for (int k = 0; k < 2; ++k) {
    EXPECT_LT(r["--true-directions"][k].interior - r[""][k].interior, 0.008) << Theta(k);
    EXPECT_NEAR(r["--camera-distance 5000 --true-directions"][k].interior, r["--camera-distance 5000"][k].interior, 0.002)
        << Theta(k);
  }
}

TEST(SteepViews, ResamplingFilters) {
  const Dataset gt32 = Truth(32);
  for (const std::string extra : {"", "--noise 0.01", "--width 2560 --height 1920", "--width 3840 --height 2880"}) {
    const fs::path ph = Photos(extra);
    for (int k = 0; k < 2; ++k) {
      std::map<std::string, Rel> res;
      for (const std::string f : {"area", "bilinear", "spline"}) {
        RectifyOptions ro = Rect();
        ro.filter = f;
        const Rel r = Compare(ImageOf(gt32, k), RectifyTruePose(ph, k, ro));
        fmt::print("{} deg, photos '{}', filter {}: true pose {:.4f} / {:.4f}\n", Theta(k), extra, f, r.all, r.interior);
        res[f] = r;
      }
      // The histopolating spline beats area weighting on every photo set and view, with read noise
      // too (measured 0.0152 against 0.0206 at 60 deg, 0.0607 against 0.0680 at 75 deg for
      // 1280 x 960; docs/btf-register.md lists every set).
      EXPECT_LT(res["spline"].interior, res["area"].interior) << Theta(k) << " " << extra;
    }
  }
}

// The model itself, without photos: its texel-box average against the same convolved with one
// photo pixel's footprint on the plate (the pixel box mapped through the true camera's local
// Jacobian), both with dense samples. What the photo's own pixel integration costs at best.
TEST(SteepViews, PixelFootprintOfTheModel) {
  const auto model = MakeModel("irawan2006", "twill");
  const fs::path ph = Photos();
  const Sampling views = Sampling::Bonn81();
  for (int k = 0; k < 2; ++k) {
    const PhotoOf p = LoadPhoto(ph, k);
    const PlateToPixel project = TrueProjection(p);
    const double S = p.sample_mm, texel = S / kN, tile = model->tile_size_mm();
    const int ts = 16, ps = 4;
    Image box(kN, kN, 3), conv(kN, kN, 3);
    std::vector<Vec2> uv_box, uv_conv;
    std::vector<float> vals;
    for (int row = 0; row < kN; ++row)
      for (int col = 0; col < kN; ++col) {
        const Vec2 c = TexelCenterMm(col, row, kN, S);
        Vec2 p0, pu, pv;
        ASSERT_TRUE(project(c, &p0) && project(c + Vec2(1e-3, 0), &pu) && project(c + Vec2(0, 1e-3), &pv));
        Eigen::Matrix2d J;
        J.col(0) = (pu - p0) / 1e-3;
        J.col(1) = (pv - p0) / 1e-3;
        const Eigen::Matrix2d Jinv = J.inverse();  // pixel offset -> plate mm
        uv_box.clear(), uv_conv.clear();
        for (int j = 0; j < ts; ++j)
          for (int i = 0; i < ts; ++i) {
            const Vec2 q(-S / 2 + (col + (i + 0.5) / ts) * texel, S / 2 - (row + (j + 0.5) / ts) * texel);
            uv_box.push_back((q + Vec2(S / 2, S / 2)) / tile);
            for (int b = 0; b < ps; ++b)
              for (int a = 0; a < ps; ++a) {
                const Vec2 d((a + 0.5) / ps - 0.5, (b + 0.5) / ps - 0.5);
                uv_conv.push_back((q + Jinv * d + Vec2(S / 2, S / 2)) / tile);
              }
          }
        for (auto* pr : {&uv_box, &uv_conv}) {
          vals.resize(pr->size() * 3);
          model->EvalBatch(views[0], views[k == 0 ? 45 : 70], pr->data(), static_cast<int>(pr->size()), vals.data());
          Image& out = pr == &uv_box ? box : conv;
          for (int ch = 0; ch < 3; ++ch) {
            double a = 0;
            for (std::size_t s = 0; s < pr->size(); ++s) a += vals[s * 3 + ch];
            out.at(col, row, ch) = static_cast<float>(a / static_cast<double>(pr->size()));
          }
        }
      }
    const Rel r = Compare(box, conv);
    const Rel against_truth = Compare(ImageOf(Truth(32), k), box);
    fmt::print("{} deg: model texel box vs texel box * pixel footprint {:.4f} / {:.4f} (dense texel box vs truth 32x32 "
               "{:.4f} / {:.4f})\n",
               Theta(k), r.all, r.interior, against_truth.all, against_truth.interior);
    // Measured 0.0155 at 60 deg, 0.0374 at 75 deg: the pixel's own box integration alone is about
    // half of the 75 deg error (0.068), growing with the footprint (0.43 mm = 0.68 texel across).
    EXPECT_GT(r.interior, k == 0 ? 0.01 : 0.025) << Theta(k);
    EXPECT_LT(r.interior, k == 0 ? 0.025 : 0.05) << Theta(k);
  }
}

}  // namespace
}  // namespace btf
