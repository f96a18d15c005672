#include "libbtf/eval/render.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/compress/codec_source.h"
#include "libbtf/eval/annotate.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// A Lambertian BTF: every value rho / pi.
Dataset Lambertian(double rho, int texels = 4) {
  const Sampling s = Sampling::Bonn81();
  Dataset d(s, s, texels, texels, 3);
  std::fill(d.data().begin(), d.data().end(), float(rho / kPi));
  return d;
}

TEST(EvalRender, PointLightOnLambertianMatchesTheClosedForm) {
  const Dataset d = Lambertian(0.5);
  const auto btf = DatasetEvaluator(d);
  for (const char* scene : {"patch", "cylinder"}) {
    RenderOptions o;
    o.scene = scene;
    o.width = 64, o.height = 48;
    const Image img = Render(*btf, o);
    int hits = 0;
    for (int y = 0; y < o.height; ++y)
      for (int x = 0; x < o.width; ++x) {
        const SurfacePoint sp = TracePixel(o, x, y);
        double expected = o.background;
        if (sp.hit) {
          ++hits;
          const Vec3 to_light = o.light_position - sp.position;
          const double cos_i = to_light.normalized().dot(sp.normal);
          const double cos_o = (sp.camera - sp.position).normalized().dot(sp.normal);
          expected = cos_i > 0 && cos_o > 0 ? 0.5 / kPi * cos_i * o.light_intensity / to_light.squaredNorm() : 0.0;
        }
        // float32 BTF values and float output: 1e-5 relative.
        ASSERT_NEAR(img.at(x, y, 1), expected, 1e-5 * std::max(1.0, expected)) << scene << " " << x << "," << y;
      }
    EXPECT_GT(hits, o.width * o.height / 5) << scene;  // the object fills a good part of the frame
  }
}

TEST(EvalRender, WhiteFurnace) {
  // Uniform environment of radiance 1: a Lambertian surface of albedo rho reflects rho, for every
  // normal. The 256 fixed directions integrate cos over the hemisphere with a quadrature error
  // that we bound at 1 % (measured: 0 for the patch, where the Fibonacci set's equally spaced z
  // make a midpoint rule that is exact for cos = z; 0.11 % on the cylinder's tilted normals).
  const Dataset d = Lambertian(0.8);
  const auto btf = DatasetEvaluator(d);
  for (const char* scene : {"patch", "cylinder"}) {
    RenderOptions o;
    o.scene = scene;
    o.lighting = "environment";
    o.environment = "uniform";
    o.environment_samples = 256;
    o.width = 48, o.height = 40;
    const Image img = Render(*btf, o);
    for (int y = 0; y < o.height; ++y)
      for (int x = 0; x < o.width; ++x)
        if (TracePixel(o, x, y).hit) {
          ASSERT_NEAR(img.at(x, y, 0), 0.8, 0.01 * 0.8) << scene << " " << x << "," << y;
        }
  }
}

TEST(EvalRender, CodecEvaluatorMatchesDatasetEvaluator) {
  // A codec keeping every component reproduces the dataset, so both renders agree to float
  // rounding of the PCA (bounded at 1e-3 relative to the image's peak).
  const Sampling s = Sampling::Bonn81();
  Dataset d(s.Subset({0, 1, 2, 3, 4, 5, 6, 7, 8, 9}), s.Subset({0, 1, 3, 5, 8, 11, 14, 19, 25, 30}), 8, 8, 3);
  for (int v = 0; v < d.num_views(); ++v)
    for (int l = 0; l < d.num_lights(); ++l)
      for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x)
          for (int c = 0; c < 3; ++c)
            d.at(v, l, y, x, c) = float(0.2 + 0.1 * std::sin(v + 2 * l) + 0.05 * ((x + y) % 3) + 0.02 * c);
  CompressOptions co;
  co.method = CodecMethod::kPcaView;
  co.components = 9;  // lights - 1: lossless up to rounding
  const Codec codec = test::CompressDataset(d, co);
  RenderOptions o;
  o.width = 40, o.height = 32;
  o.scene = "cylinder";
  const Image a = Render(*DatasetEvaluator(d), o), b = Render(*CodecEvaluator(codec), o);
  float peak = 0;
  for (float v : a.pixels) peak = std::max(peak, v);
  ASSERT_GT(peak, 0.0f);
  for (std::size_t i = 0; i < a.pixels.size(); ++i) ASSERT_NEAR(a.pixels[i], b.pixels[i], 1e-3 * peak) << i;
}

TEST(EvalRender, ManyChannelsAndOneChannel) {
  // A 20-channel (spectral-like) BTF shows its first three channels; a 1-channel BTF is gray.
  const Sampling s = Sampling::Bonn81().Subset({0, 1, 2, 3, 4, 5, 6});
  Dataset many(s, s, 2, 2, 20), one(s, s, 2, 2, 1);
  many.info().channel_names.assign(20, "band");
  one.info().channel_names = {"Y"};
  for (std::size_t i = 0; i < many.size(); ++i) many.data()[i] = float(0.01 * (i % 20 + 1));
  std::fill(one.data().begin(), one.data().end(), 0.05f);
  RenderOptions o;
  o.width = 24, o.height = 20;
  const Image a = Render(*DatasetEvaluator(many), o), b = Render(*DatasetEvaluator(one), o);
  for (int y = 0; y < o.height; ++y)
    for (int x = 0; x < o.width; ++x) {
      if (!TracePixel(o, x, y).hit) continue;
      // Channel k of a constant BTF renders as value_k times the same geometric factor.
      const double g = a.at(x, y, 0) / 0.01;
      EXPECT_NEAR(a.at(x, y, 1), 0.02 * g, 1e-5 * std::max(1.0, g));
      EXPECT_NEAR(a.at(x, y, 2), 0.03 * g, 1e-5 * std::max(1.0, g));
      EXPECT_EQ(b.at(x, y, 0), b.at(x, y, 1));
      EXPECT_EQ(b.at(x, y, 0), b.at(x, y, 2));
    }
}

TEST(EvalRender, ComparisonPanelReportsTheDifference) {
  Image a(10, 8, 3), b(10, 8, 3);
  std::fill(a.pixels.begin(), a.pixels.end(), 1.0f);
  std::fill(b.pixels.begin(), b.pixels.end(), 1.05f);
  PanelStats st;
  const Image panel = ComparisonPanel(a, b, "truth", "test", 0.1, &st);
  EXPECT_NEAR(st.max_rel_diff, 0.05, 1e-6);  // 5 % of the truth level everywhere
  EXPECT_NEAR(st.mean_rel_diff, 0.05, 1e-6);
  // Layout: 8-pixel gaps, a 22-pixel label strip, then truth | test | difference.
  ASSERT_EQ(panel.width, 3 * 10 + 4 * 8);
  ASSERT_EQ(panel.height, 8 + 22 + 8);
  // The truth (luminance 1 = its 99th percentile) shows at exposure 0.8; the difference, 5 % of
  // a 10 % full scale, is the middle of the color map.
  float mid[3];
  FalseColor(0.5, mid);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(panel.at(8 + 5, 22 + 4, k), 0.8f, 1e-5);
    EXPECT_NEAR(panel.at(8 + 2 * 18 + 5, 22 + 4, k), mid[k], 1e-5);
  }
}

// Counts pixels of the label strip (above the images) that are not the white background.
int LabelPixels(const Image& panel) {
  int n = 0;
  for (int y = 0; y < 22; ++y)
    for (int x = 0; x < panel.width; ++x) n += panel.at(x, y, 0) < 0.9f;
  return n;
}

TEST(EvalRender, ComparisonPanelLabelsUseTheFont) {
  if (LabelFont().empty()) GTEST_SKIP() << "no DejaVu Sans (fonts-dejavu-core) on this machine";
  Image a(120, 40, 3);
  std::fill(a.pixels.begin(), a.pixels.end(), 0.5f);
  PanelStats st;
  const Image panel = ComparisonPanel(a, a, "ground truth", "decoded", 0.1, &st);
  EXPECT_TRUE(st.labelled);
  EXPECT_GT(LabelPixels(panel), 100);  // three labels of dark glyphs on white
}

TEST(EvalRender, ComparisonPanelWithoutAFontHasNoText) {
  const char* old = std::getenv("BTF_FONT");
  const std::string saved = old ? old : "";
  setenv("BTF_FONT", "/nonexistent/font.ttf", 1);
  Image a(120, 40, 3);
  std::fill(a.pixels.begin(), a.pixels.end(), 0.5f);
  PanelStats st;
  const Image panel = ComparisonPanel(a, a, "ground truth", "decoded", 0.1, &st);
  if (old)
    setenv("BTF_FONT", saved.c_str(), 1);
  else
    unsetenv("BTF_FONT");
  EXPECT_FALSE(st.labelled);
  EXPECT_EQ(LabelPixels(panel), 0);
  EXPECT_EQ(panel.width, 3 * 120 + 4 * 8);  // same layout, blank strip
}

TEST(EvalRender, OptionsAreChecked) {
  RenderOptions o;
  o.scene = "teapot";
  EXPECT_THROW(o.Check(), Error);
  o = {};
  o.environment_samples = 2;
  EXPECT_THROW(o.Check(), Error);
}

}  // namespace
}  // namespace btf
