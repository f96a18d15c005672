// btf-compress command line: compress, decode, export, btf-info on codecs, exit codes.
#include <gtest/gtest.h>

#include <fstream>

#include "libbtf/compress/codec.h"
#include "libbtf/io/dataset_io.h"
#include "tests/compress/synthetic.h"
#include "tests/test_util.h"

namespace btf {
namespace {

std::string Q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

TEST(BtfCompressTool, CompressDecodeExportAndInfo) {
  const auto dir = test::TempDir();
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(5), test::BonnSubset(6, 2), 8, 8, 2, 2);
  WriteDataset(dir / "d.h5", d);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + Q(dir / "d.h5") +
                                 " --method lpca --lpca-matrix float -k 2 -c 2 -o " + Q(dir / "c.h5") + " --json --quiet",
                             &out),
            0)
      << out;
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["method"], "lpca");
  EXPECT_LT(j["relative_error"].get<double>(), 1e-5);  // exact model, float texel matrix: float rounding only
  EXPECT_EQ(j["lpca_memory"]["matrix"], "float");
  EXPECT_EQ(j["psnr_peak_definition"], "max |input value|");
  EXPECT_TRUE(j["seconds"].contains("iterate"));
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " decode " + Q(dir / "c.h5") + " -o " + Q(dir / "back.h5") +
                             " --quiet"),
            0);
  const Dataset back = ReadDataset(dir / "back.h5");
  EXPECT_LT(test::RelativeError(d, back), 1e-5);
  EXPECT_EQ(back.views().name(), d.views().name());
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " export " + Q(dir / "c.h5") +
                                 " --format schneider --view-grid 4 --light-grid 4 -o " + Q(dir / "exp") + " --json --quiet",
                             &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir / "exp" / "manifest.json"));
  EXPECT_EQ(nlohmann::json::parse(out)["functions_per_cluster"], 3);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " " + Q(dir / "c.h5") + " --json", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  EXPECT_EQ(info["method"], "lpca");
  EXPECT_EQ(info["clusters"], 2);
  EXPECT_EQ(info["view_sampling"]["count"], 5);
}

TEST(BtfCompressTool, SceneAndPerViewPca) {
  const auto dir = test::TempDir();
  const Dataset d = test::PerViewLowRank(Sampling::Bonn81(), test::BonnSubset(7), 4, 4, 2, 1e-3);
  WriteDataset(dir / "d.h5", d);
  {
    std::ofstream s(dir / "scene.json");
    s << R"({"views": [{"theta_deg": 0, "cone_deg": 10}], "lights": "all", "channels": ["R", "B"]})";
  }
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + Q(dir / "d.h5") + " -c 2 --scene " +
                                 Q(dir / "scene.json") + " -o " + Q(dir / "c.h5") + " --json --quiet",
                             &out),
            0)
      << out;
  const auto j = nlohmann::json::parse(out);
  EXPECT_LT(j["shape"]["views"].get<int>(), 81);
  EXPECT_EQ(j["shape"]["channels"], 2);
  EXPECT_GT(j["scene"]["bytes_saved"].get<double>(), 0);
  // Human summary states the PSNR peak.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + Q(dir / "d.h5") + " -c 2 -o " + Q(dir / "c2.h5") +
                                 " --quiet",
                             &out),
            0);
  EXPECT_NE(out.find("peak = max |input value|"), std::string::npos) << out;
  // pca-view exports in the sattler-2003 layout by default; --format schneider and the schneider
  // grid options are usage errors (2) for it.
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " export " + Q(dir / "c2.h5") + " -o " + Q(dir / "e") +
                             " --quiet"),
            0);
  EXPECT_EQ(nlohmann::json::parse(test::Slurp(dir / "e" / "manifest.json"))["layout"], "sattler-2003");
  EXPECT_TRUE(std::filesystem::exists(dir / "e" / "btf_sattler.glsl"));
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " export " + Q(dir / "c2.h5") + " --format schneider -o " +
                             Q(dir / "e2") + " 2>&1", &out),
            2);
  EXPECT_NE(out.find("--format sattler"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " export " + Q(dir / "c2.h5") + " --view-grid 8 -o " +
                             Q(dir / "e3") + " 2>&1", &out),
            2);
  EXPECT_NE(out.find("--view-grid"), std::string::npos) << out;
}

TEST(BtfCompressTool, ExitCodes) {
  const auto dir = test::TempDir();
  const std::string tool = test::Tool("btf-compress");
  WriteDataset(dir / "d.h5", test::PerViewLowRank(test::BonnSubset(2), test::BonnSubset(3), 2, 2, 1, 0));
  // Usage: unknown method, missing output, bad option values.
  EXPECT_EQ(test::RunCommand(tool + " " + Q(dir / "d.h5") + " --method jpeg -o " + Q(dir / "c.h5") + " 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(tool + " " + Q(dir / "d.h5") + " 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(tool + " " + Q(dir / "d.h5") + " -c 0 -o " + Q(dir / "c.h5") + " 2>/dev/null"), 2);
  // Bad input: a file that is not HDF5, a codec given where a dataset is expected.
  {
    std::ofstream f(dir / "junk.h5");
    f << "not hdf5";
  }
  EXPECT_EQ(test::RunCommand(tool + " " + Q(dir / "junk.h5") + " -o " + Q(dir / "c.h5") + " 2>/dev/null"), 3);
  EXPECT_EQ(test::RunCommand(tool + " decode " + Q(dir / "d.h5") + " -o " + Q(dir / "x.h5") + " 2>/dev/null"), 3);
  // I/O: missing input file.
  EXPECT_NE(test::RunCommand(tool + " " + Q(dir / "missing.h5") + " -o " + Q(dir / "c.h5") + " 2>/dev/null"), 0);
  EXPECT_FALSE(std::filesystem::exists(dir / "c.h5"));  // nothing half-written
  // I/O: output folder missing. The output is claimed before compressing, so this fails at once.
  std::string err;
  EXPECT_EQ(test::RunCommand(tool + " " + Q(dir / "d.h5") + " -o " + Q(dir / "no" / "c.h5") + " 2>&1", &err), 4);
  EXPECT_NE(err.find("does not exist: create it first"), std::string::npos) << err;
}

}  // namespace
}  // namespace btf
