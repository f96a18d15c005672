// The btf-synth tool: each subcommand end to end on tiny jobs, JSON summaries, exit codes.
#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include "libbtf/io/dataset_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/synth/irawan2006.h"
#include "tests/test_util.h"

namespace btf {
namespace {

std::string Synth(const std::string& args) { return test::Tool("btf-synth") + " " + args + " 2>/dev/null"; }

TEST(BtfSynthCli, BtfWritesTheRequestedSubsetWithProvenance) {
  const auto dir = test::TempDir();
  std::string out;
  ASSERT_EQ(test::RunCommand(Synth("btf --model irawan2006 --preset plain --directions bonn81 --views 0,7 "
                                   "--lights 3-5 --resolution 8 --tiles 2 --samples 2 --json -o " +
                                   (dir / "gt.h5").string()),
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["texel_values"], 2 * 3 * 8 * 8);
  const Dataset ds = ReadDataset(dir / "gt.h5");
  EXPECT_EQ(ds.views().name(), "bonn81[0,7]");
  EXPECT_EQ(ds.lights().name(), "bonn81[3,4,5]");
  EXPECT_EQ(ds.info().provenance["model"]["preset"], "plain");
  EXPECT_EQ(ds.info().provenance["tiles_per_side"], 2.0);
  EXPECT_NEAR(ds.info().texel_size_mm, 2 * 4.0 / 8, 1e-12);
}

TEST(BtfSynthCli, BrdfJsonMatchesTheLibrary) {
  const auto dir = test::TempDir();
  ASSERT_EQ(test::RunCommand(Synth("brdf --preset twill --views 0,40 --lights 10 --params '{\"ks\": 0.5}' --json-out " +
                                   (dir / "b.json").string() + " -o " + (dir / "b.h5").string())),
            0);
  std::ifstream in(dir / "b.json");
  const auto j = nlohmann::json::parse(in);
  ASSERT_EQ(j["values"].size(), 2u);
  const auto model = MakeIrawan2006Model("twill", {{"ks", 0.5}});
  const Sampling s = Sampling::Bonn81();
  float f[3];
  model->EvalBrdf(s[10], s[40], f);
  EXPECT_FLOAT_EQ(j["values"][1]["value"][0].get<float>(), f[0]);
  EXPECT_EQ(ReadDataset(dir / "b.h5").height(), 1);
}

TEST(BtfSynthCli, PhotosWriteManifestTruthAndBoard) {
  const auto dir = test::TempDir() / "set";
  ASSERT_EQ(test::RunCommand(Synth("photos --views 0,19 --lights 0,3,9 --max-photos 4 --width 320 --height 240 "
                                   "--pixel-samples 1 --noise 0.01 -o " +
                                   dir.string())),
            0);
  const Manifest m = ReadManifest(dir / "manifest.json");
  EXPECT_EQ(m.photos.size(), 4u);
  EXPECT_EQ(ReadTruth(dir / "truth.json").size(), 4u);
  EXPECT_EQ(ReadBoard(dir / "board.json").markers.size(), 8u);
  for (const auto& p : m.photos) EXPECT_TRUE(std::filesystem::exists(dir / p.file)) << p.file;
  EXPECT_EQ(m.extra["noise_sd"], 0.01);
}

TEST(BtfSynthCli, BadArgumentsGiveUsageErrors) {
  const auto dir = test::TempDir();
  const std::string o = " -o " + (dir / "x.h5").string();
  EXPECT_EQ(test::RunCommand(Synth("btf --preset denim" + o)), 2);
  EXPECT_EQ(test::RunCommand(Synth("btf --views 81" + o)), 2);
  EXPECT_EQ(test::RunCommand(Synth("btf --params '{bad'" + o)), 2);
  EXPECT_EQ(test::RunCommand(Synth("brdf --views 0")), 2);  // no output named
  EXPECT_EQ(test::RunCommand(Synth("photos --format jpg -o " + dir.string())), 2);
  // Lens options: an unknown model, radtan coefficients with a fisheye lens, fisheye ones without,
  // a wrong count: usage errors naming the field.
  std::string out;
  EXPECT_EQ(test::RunCommand(Synth("photos --lens pinhole -o " + dir.string()) + " 2>&1", &out), 2);
  EXPECT_NE(out.find("'lens'"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(Synth("photos --lens fisheye --k1 0.1 -o " + dir.string()) + " 2>&1", &out), 2);
  EXPECT_NE(out.find("'k1/k2'"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(Synth("photos --fisheye-k 0.1,0,0,0 -o " + dir.string()) + " 2>&1", &out), 2);
  EXPECT_NE(out.find("'fisheye-k'"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(Synth("photos --lens fisheye --fisheye-k 0.1,0 -o " + dir.string())), 2);
  // PSF options: disc without a radius, a radius with the Gaussian, both blurs at once.
  EXPECT_EQ(test::RunCommand(Synth("photos --psf disc -o " + dir.string()) + " 2>&1", &out), 2);
  EXPECT_NE(out.find("'psf'"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(Synth("photos --disc-radius 1 -o " + dir.string())), 2);
  EXPECT_EQ(test::RunCommand(Synth("photos --psf disc --disc-radius 1 --blur 0.7 -o " + dir.string())), 2);
  EXPECT_EQ(test::RunCommand(Synth("photos --psf box -o " + dir.string())), 2);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.h5"));
}

}  // namespace
}  // namespace btf
