// Ground-truth BTF generation: the texel mean converges to the analytic BRDF over all bonn81
// pairs; streaming to a file gives the same numbers; texel geometry and provenance.
#include "libbtf/synth/btf_generator.h"

#include <gtest/gtest.h>

#include <cmath>

#include "libbtf/io/dataset_io.h"
#include "libbtf/synth/irawan2006.h"
#include "tests/synth/generator_check.h"
#include "tests/synth_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(BtfGenerator, TexelMeanConvergesToAnalyticBrdfOverAllBonnPairs) {
  // Twill at 16^2 texels x 8^2 samples: 128 strata per tile side, stratum edges on the 4 x 8 grid.
  const double worst = test::ExpectTexelMeanConverges("twill", 16, 8);
  RecordProperty("worst_error_in_sd", std::to_string(worst));
}

TEST(BtfGenerator, ErrorStaysWithinTheStratifiedBoundWhenWindowsDoNotAlign) {
  // Plain weave (2 x 2 units) at 7 texels: with S = 1 and S = 9 the window edges at x = 1, y = 1
  // cut through strata (7 and 63 strata per 2 units), so they count as boundary too.
  const Irawan2006Params params = Irawan2006Preset("plain");
  const Irawan2006Model model(params);
  BtfOptions o;
  o.views = Sampling::Single(DirectionFromAngles(0.5, 0.3));
  o.lights = Sampling::Single(DirectionFromAngles(0.4, 2.0));
  o.resolution = 7;
  float f[3];
  model.EvalBrdf(o.lights[0], o.views[0], f);
  const double spec = model.SpecularFactor(o.lights[0], o.views[0]);
  ASSERT_GT(model.HighlightFraction(o.lights[0], o.views[0]), 0.05);
  for (int s : {1, 9}) {
    o.samples = s;
    const Dataset ds = test::GenerateDataset(model, o);
    double mean = 0;
    for (std::size_t i = 0; i < ds.data().size(); i += 3) mean += ds.data()[i];
    mean /= ds.num_texels();
    const int grid = o.resolution * s;
    const double d = 2.0 / grid;  // stratum size in units
    const double nb = test::BoundaryStrata(params, d, d) + 2 * grid;  // + the two interior window lines
    const double tol = 6 * std::sqrt(nb) / (2.0 * grid * grid);
    EXPECT_LT(std::abs(mean - f[0]) / spec, tol) << "samples " << s;
    if (s == 9) {
      EXPECT_LT(tol, 0.02);  // the bound itself is tight enough to mean something
    }
  }
}

TEST(BtfGenerator, StreamedFileEqualsInMemoryAndCarriesProvenance) {
  const auto model = MakeIrawan2006Model("sateen");
  BtfOptions o;
  o.views = Sampling::Bonn81().Subset({0, 7, 40});
  o.lights = Sampling::Bonn81().Subset({3, 9});
  o.resolution = 12;
  o.tiles = 2;
  o.samples = 3;
  o.irregularity = 0.03;
  const Dataset mem = test::GenerateDataset(*model, o);
  const auto dir = test::TempDir();
  const BtfSummary s = WriteGeneratedBtf(o, *model, dir / "gt.h5");
  EXPECT_EQ(s.texel_values, 3u * 2 * 12 * 12);
  EXPECT_EQ(s.model_evaluations, s.texel_values * 9);
  const Dataset file = ReadDataset(dir / "gt.h5");
  ASSERT_EQ(file.data().size(), mem.data().size());
  EXPECT_EQ(file.data(), mem.data());  // same seed, same positions, thread-count independent
  EXPECT_EQ(file.views().name(), "bonn81[0,7,40]");
  EXPECT_NEAR(file.info().texel_size_mm, 2 * model->tile_size_mm() / 12, 1e-12);
  EXPECT_EQ(file.info().provenance["supersampling"]["samples_per_axis"], 3);
  EXPECT_EQ(file.info().provenance["model"]["preset"], "sateen");
  for (float x : file.data()) ASSERT_TRUE(std::isfinite(x) && x >= 0);
}

TEST(BtfGenerator, TexelGeometryPutsRowZeroAtTheTop) {
  BtfOptions o;
  o.resolution = 4;
  o.tiles = 2;
  o.samples = 2;
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x)
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          const Vec2 uv = TexelSampleUv(o, x, y, i, j);
          // Stratum (i, j) of texel (x, y): u in tiles*(x + i/2 .. x + (i+1)/2)/N, v from the top.
          EXPECT_GE(uv.x(), 2.0 * (x + i / 2.0) / 4);
          EXPECT_LE(uv.x(), 2.0 * (x + (i + 1) / 2.0) / 4);
          EXPECT_LE(uv.y(), 2.0 * (1 - (y + j / 2.0) / 4));
          EXPECT_GE(uv.y(), 2.0 * (1 - (y + (j + 1) / 2.0) / 4));
        }
  // Irregularity: RMS displacement equals the amplitude (within sampling error of 4096 points).
  const PatternWarp w(0.05, 11);
  double ms = 0;
  for (int k = 0; k < 4096; ++k) {
    const Vec2 p(37.0 * HashUniform(1, k), 37.0 * HashUniform(2, k));
    ms += (w.Apply(p) - p).squaredNorm();
  }
  EXPECT_NEAR(std::sqrt(ms / 4096), 0.05, 0.01);  // 20%: finite-sample fluctuation of 4 waves
  EXPECT_EQ(PatternWarp(0, 1).Apply(Vec2(0.3, 0.4)), Vec2(0.3, 0.4));
}

TEST(BtfGenerator, BadOptionsAreUsageErrors) {
  const auto model = MakeIrawan2006Model("plain");
  BtfOptions o;
  o.resolution = 0;
  EXPECT_THROW(test::GenerateDataset(*model, o), Error);
  o.resolution = 4;
  o.samples = 0;
  EXPECT_THROW(test::GenerateDataset(*model, o), Error);
  o.samples = 2;
  o.tiles = -1;
  EXPECT_THROW(test::GenerateDataset(*model, o), Error);
}

TEST(BtfGenerator, BrdfDatasetMatchesEvalBrdf) {
  const auto model = MakeIrawan2006Model("twill");
  const Sampling s = Sampling::Bonn81().Subset({0, 10, 50, 80});
  const Dataset ds = GenerateBrdf(*model, s, s);
  ASSERT_EQ(ds.height(), 1);
  for (int v = 0; v < 4; ++v)
    for (int l = 0; l < 4; ++l) {
      float f[3];
      model->EvalBrdf(s[l], s[v], f);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(ds.at(v, l, 0, 0, c), f[c]);
    }
}

}  // namespace
}  // namespace btf
