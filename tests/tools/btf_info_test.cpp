#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include "libbtf/io/dataset_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(BtfInfo, JsonReportsExactlyWhatWasWritten) {
  const auto dir = test::TempDir();
  Dataset d = test::MakeTestDataset(2, 3, 4, 5);
  d.data()[7] = std::numeric_limits<float>::quiet_NaN();
  d.info().cos_theta_i_included = true;
  WriteDataset(dir / "d.h5", d);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json " + (dir / "d.h5").string(), &out), 0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["format"], "libbtf-dataset");
  EXPECT_EQ(j["format_version"], "1.0.0");
  EXPECT_EQ(j["shape"]["views"], 2);
  EXPECT_EQ(j["shape"]["lights"], 3);
  EXPECT_EQ(j["shape"]["height"], 4);
  EXPECT_EQ(j["shape"]["width"], 5);
  EXPECT_EQ(j["shape"]["channels"], 3);
  EXPECT_EQ(j["cos_theta_i_included"], true);
  EXPECT_EQ(j["storage"], "float32");
  EXPECT_EQ(j["values"]["nan_count"], 1);
  float lo = 1e30f, hi = -1e30f;
  for (std::size_t i = 0; i < d.size(); ++i)
    if (i != 7) lo = std::min(lo, d.data()[i]), hi = std::max(hi, d.data()[i]);
  EXPECT_DOUBLE_EQ(j["values"]["min"].get<double>(), lo);
  EXPECT_DOUBLE_EQ(j["values"]["max"].get<double>(), hi);
  EXPECT_EQ(j["file_bytes"], std::filesystem::file_size(dir / "d.h5"));
  EXPECT_EQ(j["view_sampling"]["count"], 2);
}

TEST(BtfInfo, ExitCodes) {
  const auto dir = test::TempDir();
  const std::string tool = test::Tool("btf-info");
  EXPECT_EQ(test::RunCommand(tool + " --help >/dev/null"), 0);
  EXPECT_EQ(test::RunCommand(tool + " 2>/dev/null"), 2);               // missing FILE
  EXPECT_EQ(test::RunCommand(tool + " --bogus x 2>/dev/null"), 2);     // unknown flag
  EXPECT_EQ(test::RunCommand(tool + " " + (dir / "none.h5").string() + " 2>/dev/null"), 4);
  std::ofstream(dir / "junk.h5") << "junk";
  std::string err;
  EXPECT_EQ(test::RunCommand(tool + " " + (dir / "junk.h5").string() + " 2>&1", &err), 3);
  // One line naming the file.
  EXPECT_NE(err.find("junk.h5"), std::string::npos);
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  WriteDataset(dir / "ok.h5", test::MakeTestDataset(1, 1, 2, 2));
  std::filesystem::copy_file(dir / "ok.h5", dir / "trunc.h5");
  std::filesystem::resize_file(dir / "trunc.h5", std::filesystem::file_size(dir / "ok.h5") / 2);
  EXPECT_EQ(test::RunCommand(tool + " " + (dir / "trunc.h5").string() + " 2>/dev/null"), 3);
}

}  // namespace
}  // namespace btf
