#include "libbtf/eval/metrics.h"

#include "libbtf/compress/codec_source.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "libbtf/core/error.h"
#include "libbtf/eval/annotate.h"
#include "libbtf/io/dataset_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

double MaxValue(const Dataset& d) {
  double m = -1e300;
  for (float v : d.data()) m = std::max(m, double(v));
  return m;
}

TEST(EvalMetrics, ConstantOffsetGivesKnownFigures) {
  const Dataset ref = test::MakeTestDataset(2, 3, 4, 5);
  Dataset t = ref;
  const double delta = 0.01;
  double ssr = 0;
  for (std::size_t i = 0; i < t.size(); ++i) {
    t.data()[i] = float(double(ref.data()[i]) + delta);
    ssr += double(ref.data()[i]) * ref.data()[i];
  }
  CompareOptions o;
  const auto s = Compare(o, *MemorySource(ref), *MemorySource(t));
  // Values are float32 near 1-2: the stored difference deviates from 0.01 by about 1e-7.
  const double tol = 1e-6;
  EXPECT_NEAR(s.rmse, delta, tol);
  EXPECT_NEAR(s.max_abs, delta, tol);
  EXPECT_DOUBLE_EQ(s.peak, MaxValue(ref));
  EXPECT_EQ(s.peak_source, "max |reference value|");
  ASSERT_TRUE(s.psnr_db.has_value());
  EXPECT_NEAR(*s.psnr_db, 20 * std::log10(s.peak / delta), 1e-3);  // 1e-6 relative rmse -> ~1e-5 dB
  ASSERT_TRUE(s.rel_l2.has_value());
  EXPECT_NEAR(*s.rel_l2, delta * std::sqrt(double(ref.size()) / ssr), 1e-6);
  EXPECT_EQ(s.values, ref.size());
  for (double v : s.view_rmse) EXPECT_NEAR(v, delta, tol);
  for (double v : s.light_rmse) EXPECT_NEAR(v, delta, tol);
}

TEST(EvalMetrics, PerViewAndPerLightTablesLocateTheError) {
  const Dataset ref = test::MakeTestDataset(3, 4, 6, 5);
  Dataset t = ref;
  // Error 0.1 only in view 1; within it, 0.3 extra at light 2, texel (y 4, x 3), channel 1.
  for (int l = 0; l < 4; ++l)
    for (int y = 0; y < 6; ++y)
      for (int x = 0; x < 5; ++x)
        for (int c = 0; c < 3; ++c) t.at(1, l, y, x, c) += 0.1f;
  t.at(1, 2, 4, 3, 1) += 0.3f;
  const auto s = Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t));
  EXPECT_NEAR(s.view_rmse[0], 0.0, 1e-12);
  EXPECT_NEAR(s.view_rmse[2], 0.0, 1e-12);
  const double n_img = 6 * 5 * 3;
  // View 1: 4*n_img values of 0.1 except one of 0.4.
  EXPECT_NEAR(s.view_rmse[1], std::sqrt(((4 * n_img - 1) * 0.01 + 0.16) / (4 * n_img)), 1e-6);
  EXPECT_NEAR(s.light_rmse[0], std::sqrt(n_img * 0.01 / (3 * n_img)), 1e-6);
  EXPECT_NEAR(s.light_rmse[2], std::sqrt(((n_img - 1) * 0.01 + 0.16) / (3 * n_img)), 1e-6);
  EXPECT_NEAR(s.max_abs, 0.4, 1e-6);
  EXPECT_EQ(s.max_view, 1);
  EXPECT_EQ(s.max_light, 2);
  EXPECT_EQ(s.max_y, 4);
  EXPECT_EQ(s.max_x, 3);
  EXPECT_EQ(s.max_channel, 1);
  ASSERT_FALSE(s.worst.empty());
  EXPECT_EQ(s.worst[0].view, 1);
  EXPECT_EQ(s.worst[0].light, 2);
}

TEST(EvalMetrics, IdenticalInputs) {
  const Dataset ref = test::MakeTestDataset(2, 2, 8, 8);
  const auto s = Compare(CompareOptions(), *MemorySource(ref), *MemorySource(ref));
  EXPECT_EQ(s.rmse, 0.0);
  EXPECT_EQ(s.max_abs, 0.0);
  EXPECT_FALSE(s.psnr_db.has_value());  // infinite
  ASSERT_TRUE(s.mean_ssim.has_value());
  EXPECT_NEAR(*s.mean_ssim, 1.0, 1e-12);  // exact up to rounding of identical sums
  EXPECT_TRUE(s.ToJson()["identical"].get<bool>());
  EXPECT_TRUE(s.ToJson()["psnr_db"].is_null());
}

TEST(EvalMetrics, SsimOfConstantImagesMatchesTheFormula) {
  // Constant images a and b: variances and covariance vanish, SSIM = (2ab + C1) / (a^2 + b^2 + C1).
  const int h = 9, w = 7;
  std::vector<float> a(h * w, 1.0f), b(h * w, 0.5f);
  const double peak = 1, c1 = 1e-4;
  EXPECT_NEAR(MeanSsim(a.data(), b.data(), h, w, 1, peak), (1.0 + c1) / (1.25 + c1), 1e-12);
  // Structure matters: a pattern against its negative has SSIM < 0 in the structure term.
  std::vector<float> p(h * w), q(h * w);
  for (int i = 0; i < h * w; ++i) p[i] = 0.5f + 0.4f * float((i % 2) * 2 - 1), q[i] = 1.0f - p[i];
  EXPECT_LT(MeanSsim(p.data(), q.data(), h, w, 1, peak), 0.0);
}

TEST(EvalMetrics, AllZeroReference) {
  Dataset ref = test::MakeTestDataset(1, 2, 3, 3);
  std::fill(ref.data().begin(), ref.data().end(), 0.0f);
  Dataset t = ref;
  t.data()[5] = 0.5f;
  const auto s = Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t));
  EXPECT_FALSE(s.rel_l2.has_value());
  // No peak: PSNR and SSIM are undefined (not a figure made from a peak of 1), with a note.
  EXPECT_EQ(s.peak, 0.0);
  EXPECT_EQ(s.peak_source, "none (reference all zero)");
  EXPECT_FALSE(s.psnr_db.has_value());
  EXPECT_FALSE(s.mean_ssim.has_value());
  ASSERT_EQ(s.notes.size(), 1u);
  EXPECT_NE(s.notes[0].find("all zero"), std::string::npos);
  EXPECT_NE(s.Report().find("psnr       undefined"), std::string::npos) << s.Report();
  ExitCode psnr_code{};
  EXPECT_NE(test::ErrorOf([&] { s.Metric("psnr"); }, &psnr_code).find("--peak"), std::string::npos);
  EXPECT_EQ(psnr_code, ExitCode::kBadInput);
  // With --peak they are defined again.
  CompareOptions with_peak;
  with_peak.peak = 1;
  const auto p = Compare(with_peak, *MemorySource(ref), *MemorySource(t));
  EXPECT_TRUE(p.psnr_db.has_value());
  EXPECT_TRUE(p.mean_ssim.has_value());
  EXPECT_TRUE(p.notes.empty());
  EXPECT_NEAR(s.rmse, 0.5 / std::sqrt(double(ref.size())), 1e-9);
  try {
    s.Metric("rel");
    FAIL() << "rel of an all-zero reference must be refused";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("--metric rmse"), std::string::npos);
  }
  // Both all zero: identical, relative error 0.
  EXPECT_EQ(*Compare(CompareOptions(), *MemorySource(ref), *MemorySource(ref)).rel_l2, 0.0);
}

// One outlier among values near 1: the relative error and PSNR are the outlier's; a note says so
// (and btf-compress's summary warns with the same text). Without the outlier: no note.
TEST(EvalMetrics, AReferenceDominatedByOneValueIsNoted) {
  Dataset ref = test::MakeTestDataset(2, 3, 40, 50);  // 36000 values
  Dataset t = ref;
  for (float& x : t.data()) x *= 1.1f;
  EXPECT_TRUE(Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t)).notes.empty());
  ref.at(1, 2, 3, 4, 0) = 1e30f;
  t.at(1, 2, 3, 4, 0) = 1e30f;
  const auto s = Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t));
  EXPECT_LT(*s.rel_l2, 1e-20);  // the outlier's: the 10 % error of the rest vanishes beside it
  ASSERT_EQ(s.notes.size(), 1u);
  EXPECT_NE(s.notes[0].find("1e+30"), std::string::npos) << s.notes[0];
  EXPECT_NE(s.notes[0].find("--metric rmse"), std::string::npos) << s.notes[0];
  EXPECT_NE(s.Report().find("note       the reference's largest"), std::string::npos);
}

TEST(EvalMetrics, RefusesNanAndInfNamingTheItem) {
  const Dataset ref = test::MakeTestDataset(2, 3, 4, 5);
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    Dataset t = ref;
    t.at(1, 2, 3, 4, 0) = bad;
    try {
      Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t, "test.h5"));
      FAIL() << "non-finite value accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput);
      const std::string m = e.what();
      EXPECT_NE(m.find("test.h5"), std::string::npos) << m;
      EXPECT_NE(m.find("view 1, light 2, texel (y 3, x 4), channel 0"), std::string::npos) << m;
      EXPECT_NE(m.find(std::isnan(bad) ? "NaN" : "Inf"), std::string::npos) << m;
    }
  }
}

TEST(EvalMetrics, RefusesIncompatibleInputs) {
  const Dataset ref = test::MakeTestDataset(2, 3, 4, 5);
  auto expect_bad = [&](const Dataset& t, const std::string& needle) {
    try {
      Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t));
      FAIL() << "incompatible inputs accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput);
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_bad(test::MakeTestDataset(2, 3, 4, 6), "shapes must match");
  expect_bad(test::MakeTestDataset(2, 4, 4, 5), "light directions");
  // Same counts, different directions.
  Dataset t(Sampling::Bonn81().Subset({5, 6}), ref.lights(), 4, 5, 3);
  expect_bad(t, "view direction 0 differs");
}

TEST(EvalMetrics, FileStreamingMatchesMemoryAndWritesErrorMaps) {
  const auto dir = test::TempDir();
  const Dataset ref = test::MakeTestDataset(3, 2, 6, 7);
  Dataset t = ref;
  for (std::size_t i = 0; i < t.size(); ++i) t.data()[i] += 0.001f * float(i % 13);
  WriteDataset(dir / "ref.h5", ref);
  WriteDataset(dir / "test.h5", t);
  CompareOptions o;
  o.error_maps_dir = dir;
  o.error_maps = 2;
  const auto a = Compare(CompareOptions(), *MemorySource(ref), *MemorySource(t));
  const auto b = Compare(o, *OpenSource(dir / "ref.h5"), *OpenSource(dir / "test.h5"));
  EXPECT_DOUBLE_EQ(a.rmse, b.rmse);  // same values, same summation order
  EXPECT_DOUBLE_EQ(*a.mean_ssim, *b.mean_ssim);
  ASSERT_EQ(b.error_map_files.size(), 2u);
  for (const auto& f : b.error_map_files) {
    const Image im = ReadImage(f);
    EXPECT_GE(im.width, 256);  // 7 texels upscaled to at least 256 pixels
    // Written as sRGB PNGs: the white margin reads back as white.
    EXPECT_NEAR(im.at(0, 0, 0), 1.0f, 1e-3);
  }
}

TEST(EvalMetrics, ErrorMapColorsAndColorBar) {
  // 4 x 3 texels, 2 channels: texel (y 0, x 0) is off by `scale` in both channels (RMS = scale),
  // texel (y 1, x 2) by half of it, the rest exact.
  const int h = 3, w = 4, c = 2;
  const double scale = 0.2;
  std::vector<float> ref(h * w * c, 0.3f), test = ref;
  test[0] += 0.2f, test[1] -= 0.2f;
  test[(1 * w + 2) * c] += 0.1f, test[(1 * w + 2) * c + 1] += 0.1f;
  const Image im = ErrorMapImage(ref.data(), test.data(), h, w, c, scale, 256);
  const int zoom = 64, pad = 8;  // 4 texels upscaled to 256 pixels
  ASSERT_EQ(im.width, 4 * zoom + 2 * pad);
  float lo[3], mid[3], hi[3];
  FalseColor(0, lo), FalseColor(0.5, mid), FalseColor(1, hi);
  auto expect_color = [&](int x, int y, const float* want) {
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(im.at(x, y, k), want[k], 1e-4) << x << "," << y << " " << k;
  };
  expect_color(pad + zoom / 2, pad + zoom / 2, hi);                // texel (0, 0)
  expect_color(pad + 2 * zoom + 3, pad + zoom + zoom - 3, mid);    // texel (y 1, x 2)
  expect_color(pad + 4 * zoom - 1, pad + 3 * zoom - 1, lo);        // texel (y 2, x 3)
  // The color bar runs through the same map, 0 at the left end, `scale` at the right.
  const int bar_y = pad + 3 * zoom + 6 + 6;
  expect_color(pad, bar_y, lo);
  expect_color(im.width - pad - 1, bar_y, hi);
  // Its numbers are drawn below it (when the font exists).
  int dark = 0;
  for (int y = bar_y + 8; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) dark += im.at(x, y, 0) < 0.5f;
  if (LabelFont().empty())
    EXPECT_EQ(dark, 0);
  else
    EXPECT_GT(dark, 50);
}

TEST(EvalMetrics, OptionsAreChecked) {
  CompareOptions o;
  o.peak = -1;
  EXPECT_THROW(o.Check(), Error);
  o = {};
  o.ssim_sigma = 0;
  EXPECT_THROW(o.Check(), Error);
}

}  // namespace
}  // namespace btf
