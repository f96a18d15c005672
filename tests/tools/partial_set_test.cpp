// A partial image set (a real UBO2003 download is often one tvTTT_pvPPP folder): imported with
// --directions present it is the smaller set it is; with --allow-missing the absent images are
// marked missing in the dataset (format 1.1, /btf/missing), btf-info reports them, compress and
// render refuse them naming what to do, and compare leaves them out of every figure.
#include <gtest/gtest.h>

#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/io/dataset_io.h"
#include "libbtf/io/image_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

TEST(PartialSet, ImportsPresentDirectionsOrMarksTheMissingOnes) {
  const fs::path dir = test::TempDir(), set = dir / "tv015_pv060";
  fs::create_directories(set);
  // Bonn 81 view 2 = (15, 60); lights 0 = (0, 0) and 7 = (30, 0): 2 of the 6561 images.
  for (const int l : {0, 7}) {
    Image img(8, 8, 3);
    for (auto& p : img.pixels) p = 0.2f + 0.1f * float(l);
    WriteImage(set / fmt::format("{:05d} tl{:03d} pl000 tv015 pv060.jpg", 81 * l + 2, l == 0 ? 0 : 30), img);
  }
  const std::string convert = test::Tool("btf-convert") + " " + set.string() + " --layout ubo2003 --quiet --json ";
  std::string out;
  // Only the directions present: one view, two lights, nothing missing, and it compresses.
  ASSERT_EQ(test::RunCommand(convert + "--directions present -o " + (dir / "present.h5").string(), &out), 0) << out;
  EXPECT_EQ(json::parse(out)["missing_images"], 0);
  const DatasetHeader present = DatasetReader(dir / "present.h5").header();
  EXPECT_EQ(present.num_views, 1);
  EXPECT_EQ(present.num_lights, 2);
  EXPECT_TRUE(present.missing.empty());
  EXPECT_EQ(present.format_version, "1.0.0");
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + (dir / "present.h5").string() +
                             " --method pca-view -c 1 --quiet -o " + (dir / "c.h5").string()),
            0);
  // Every direction, the absent images marked missing.
  const std::string all = (dir / "all.h5").string();
  ASSERT_EQ(test::RunCommand(convert + "--allow-missing -o " + all, &out), 0) << out;
  const DatasetHeader h = DatasetReader(all).header();
  EXPECT_EQ(h.format_version, "1.1.0");
  EXPECT_EQ(h.missing.size(), 6559u);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json --quiet --no-stats " + all, &out), 0) << out;
  EXPECT_EQ(json::parse(out)["missing_images"].size(), 6559u);
  // compress and render refuse it, saying what to do (exit 3, nothing written).
  for (const std::string cmd : {test::Tool("btf-compress") + " " + all + " --method pca-view -c 1 -o " + (dir / "x.h5").string(),
                                test::Tool("btf-eval") + " render " + all + " -o " + (dir / "x.png").string()}) {
    EXPECT_EQ(test::RunCommand(cmd + " --quiet 2>&1", &out), 3) << cmd << "\n" << out;
    EXPECT_NE(out.find("6559 of 6561 images missing"), std::string::npos) << out;
    EXPECT_NE(out.find("--directions present"), std::string::npos) << out;
  }
  EXPECT_FALSE(fs::exists(dir / "x.h5"));
  // compare leaves them out: against a copy whose missing images hold other values, the error is 0.
  Dataset filled = ReadDataset(all);
  for (const auto& [v, l] : h.missing)
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x)
        for (int c = 0; c < 3; ++c) filled.at(v, l, y, x, c) = 5.0f;
  WriteDataset(dir / "filled.h5", filled);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + all + " " + (dir / "filled.h5").string() +
                                 " --json --quiet",
                             &out),
            0)
      << out;
  const json j = json::parse(out);
  EXPECT_EQ(j["skipped_images"], 6559);
  EXPECT_EQ(j["rmse"], 0.0);
  EXPECT_EQ(j["values"], 2 * 8 * 8 * 3);
}

}  // namespace
}  // namespace btf
