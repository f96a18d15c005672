// A Bonn .btf file through the tools: btf-convert, btf-info, btf-compress and btf-eval (CLI).
#include <gtest/gtest.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include "libbtf/io/bonn.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/half.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/slot_source.h"
#include "tests/io/bonn_test.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(BtfConvert, DatasetToBdiThroughInfoCompressEvalAndBack) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/";
  Dataset ds = test::MakeTestDataset(3, 4, 6, 5);
  ds.info().cos_theta_i_included = true;
  WriteDataset(dir / "a.h5", ds);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "a.h5 -o " + d + "a.btf --json --quiet", &out), 0);
  auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["output_format"], "bdi");
  EXPECT_EQ(j["input_kind"], "libbtf-dataset");
  EXPECT_EQ(j["bytes_written"], std::filesystem::file_size(dir / "a.btf"));

  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json --quiet " + d + "a.btf", &out), 0);
  j = nlohmann::json::parse(out);
  EXPECT_EQ(j["format"], "bonn-bdi");
  EXPECT_EQ(j["signature"], "!BDIF06R2!");
  EXPECT_EQ(j["shape"]["views"], 3);
  EXPECT_EQ(j["shape"]["lights"], 4);
  EXPECT_EQ(j["shape"]["height"], 6);
  EXPECT_EQ(j["shape"]["width"], 5);
  EXPECT_EQ(j["cos_theta_i_included"], true);
  EXPECT_EQ(j["stored_conventions"]["epsilon"], 1e-5);
  EXPECT_EQ(j["values"]["count"], 3 * 4 * 6 * 5 * 3);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " " + d + "a.btf", &out), 0);  // the text summary
  EXPECT_NE(out.find("bonn-bdi"), std::string::npos);

  // btf-compress reads the .btf file slot by slot; btf-eval compares the codec against it.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "a.btf --method pca-view -c 4 -o " + d +
                             "c.h5 --quiet >/dev/null"),
            0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + d + "a.btf " + d + "c.h5 --json --quiet", &out), 0);
  EXPECT_TRUE(nlohmann::json::parse(out).contains("seconds"));
  // DFMF with every component (12 per YUV channel): compared with the input by btf-eval.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "a.btf -o " + d + "d.btf --to dfmf -c 100 --quiet >/dev/null"), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + d + "a.btf " + d + "d.btf --json --quiet", &out), 0);
  j = nlohmann::json::parse(out);
  ASSERT_TRUE(j["rel_l2"].is_number()) << out;
  EXPECT_LT(j["rel_l2"].get<double>(), 1e-4);  // the YUV inverse's 5-6 digits (docs/format.md)
  // The pca-view codec as PVF: btf-info reads it back.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "c.h5 -o " + d + "c.btf --to pvf --quiet >/dev/null"), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json --quiet --no-stats " + d + "c.btf", &out), 0);
  j = nlohmann::json::parse(out);
  EXPECT_EQ(j["format"], "bonn-pvf");
  EXPECT_EQ(j["pvf_layout"], "stacked images");

  // Back to a dataset: the half-rounded input, exactly.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "a.btf -o " + d + "b.h5 --quiet >/dev/null"), 0);
  const Dataset back = ReadDataset(dir / "b.h5");
  ASSERT_EQ(back.size(), ds.size());
  for (std::size_t i = 0; i < ds.size(); ++i) ASSERT_EQ(back.data()[i], HalfToFloat(FloatToHalf(ds.data()[i])));
  EXPECT_TRUE(back.info().cos_theta_i_included);
}

// One (view, light) image out, of a dataset and of a codec decoded: .exr holds the values x
// exposure exactly (float), .png the 8-bit sRGB of them clamped (as the renders), within one code.
TEST(BtfConvert, OneImageOutAsExrAndPng) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/";
  const Dataset ds = test::MakeTestDataset(3, 4, 6, 5);
  WriteDataset(dir / "a.h5", ds);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "a.h5 -o " + d + "i.exr --view 2 --light 1 --exposure 0.5 --json --quiet", &out), 0) << out;
  EXPECT_EQ(nlohmann::json::parse(out)["output_format"], "exr");
  const Image exr = ReadImage(dir / "i.exr");
  ASSERT_EQ(exr.width, 5);
  ASSERT_EQ(exr.height, 6);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 5; ++x)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(exr.at(x, y, c), ds.at(2, 1, y, x, c) * 0.5f);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "a.h5 -o " + d + "i.png --view 2 --light 1 --exposure 0.5 --quiet"), 0);
  const Image png = ReadImage(dir / "i.png");  // decoded back to linear through the sRGB curve
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 5; ++x)
      for (int c = 0; c < 3; ++c) {
        const float want = std::min(1.0f, ds.at(2, 1, y, x, c) * 0.5f);
        // Half an 8-bit sRGB code: under 0.9 % of the linear value from 0.05 up, under 1e-3 below.
        ASSERT_NEAR(png.at(x, y, c), want, 0.012f * want + 1e-3f) << x << " " << y << " " << c;
      }
  // A codec: its decoded image.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "a.h5 --method pca-view -c 3 -o " + d + "c.h5 --quiet >/dev/null"), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "c.h5 -o " + d + "c.exr --view 1 --light 3 --quiet"), 0);
  EXPECT_EQ(ReadImage(dir / "c.exr").width, 5);
  // Out of range: exit 2 naming the shape; nothing written.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "a.h5 -o " + d + "x.png --view 3 --quiet 2>&1", &out), 2);
  EXPECT_NE(out.find("3 views and 4 lights"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
}

TEST(BtfConvert, HandBuiltDfmfInBtfInfo) {
  const auto dir = test::TempDir();
  test::Layout L;
  test::Bytes f;
  f.Text("!DFMF08FCR").Append(test::CommonHeader(L, true)).U32(1).I32(11);
  for (int i = 0; i < 12; ++i) f.F32(0);
  for (int c = 0; c < 3; ++c) {
    f.U8(2).U32(1).U32(std::uint32_t(L.views * L.lights)).U32(std::uint32_t(L.texels())).U16(0x3c00);
    for (int i = 0; i < L.views * L.lights + L.texels(); ++i) f.U16(0x3800);  // 0.5
  }
  f.Save(dir / "m.btf");
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json --quiet " + (dir / "m.btf").string(), &out), 0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["format"], "bonn-dfmf");
  EXPECT_EQ(j["color_model"]["id"], 11);
  EXPECT_EQ(j["color_model"]["name"], "ylog_udivy_vdivy");
  EXPECT_EQ(j["components"], (std::vector<int>{1, 1, 1}));
  EXPECT_EQ(j["scalar_sizes"], (std::vector<int>{2, 2, 2}));
  // Y' = U' = V' = 0.25: Y = e^0.25 - 1e-5, U = V = 0.25 (Y + 1e-5); R = Y + 1.13983 V.
  const double y = std::exp(0.25) - 1e-5, v = 0.25 * (y + 1e-5);
  EXPECT_NEAR(j["values"]["max"].get<double>(), y + 2.03211 * v, 1e-6);
}

TEST(BtfConvert, BadInputAndUsageExitCodesWriteNothing) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/", tool = test::Tool("btf-convert");
  const Dataset ds = test::MakeTestDataset(2, 2, 2, 2);
  WriteDataset(dir / "a.h5", ds);
  WriteBdi(dir / "a.btf", *MemorySource(ds));
  // Truncated .btf: exit 3, one line naming the file, no output.
  std::filesystem::copy_file(dir / "a.btf", dir / "cut.btf");
  std::filesystem::resize_file(dir / "cut.btf", std::filesystem::file_size(dir / "a.btf") - 3);
  std::string err;
  EXPECT_EQ(test::RunCommand(tool + " " + d + "cut.btf -o " + d + "out.h5 2>&1", &err), 3);
  EXPECT_NE(err.find("cut.btf"), std::string::npos) << err;
  EXPECT_NE(err.find("byte"), std::string::npos) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  EXPECT_FALSE(std::filesystem::exists(dir / "out.h5"));
  // Unknown signature: exit 3 (the library tests cover every other malformed field).
  test::Bytes().Text("!NOPE0000!").U32(1).Save(dir / "sig.btf");
  EXPECT_EQ(test::RunCommand(tool + " " + d + "sig.btf -o " + d + "out.h5 2>/dev/null"), 3);
  // Usage: an extension that names no format, a format not written yet (option values:
  // tests/io BonnConvert.OptionsAndTargets).
  EXPECT_EQ(test::RunCommand(tool + " " + d + "a.h5 -o " + d + "out.txt 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(tool + " " + d + "a.h5 -o " + d + "out.btf --to svd 2>/dev/null"), 2);
  // PVF is written from a pca-view codec only: a dataset is the wrong input (exit 3).
  EXPECT_EQ(test::RunCommand(tool + " " + d + "a.h5 -o " + d + "out.btf --to pvf 2>/dev/null"), 3);
  EXPECT_EQ(test::RunCommand(tool + " " + d + "none.btf -o " + d + "out.h5 2>/dev/null"), 4);
  for (const char* name : {"out.h5", "out.txt", "out.btf"}) EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
  // An image set (tests/io ImageSet.* cover the layouts): imported, or refused with exit 3 when an
  // image is missing, nothing written.
  std::filesystem::create_directories(dir / "set");
  for (int l : {0, 30}) WriteImage(dir / "set" / fmt::format("tl{}_pl0_tv0_pv0.exr", l), Image(2, 2, 3));
  std::string out;
  ASSERT_EQ(test::RunCommand(tool + " " + d + "set -o " + d + "set.h5 --layout pattern --pattern 'tl{tl}_pl{pl}_tv{tv}_pv{pv}.exr' --json --quiet", &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["missing_images"], 0);
  EXPECT_EQ(ReadDataset(dir / "set.h5").num_lights(), 2);
  WriteImage(dir / "set" / "tl30_pl0_tv15_pv0.exr", Image(2, 2, 3));  // view 1 lacks light 0
  EXPECT_EQ(test::RunCommand(tool + " " + d + "set -o " + d + "out.h5 --layout pattern --pattern 'tl{tl}_pl{pl}_tv{tv}_pv{pv}.exr' 2>/dev/null"), 3);
  EXPECT_FALSE(std::filesystem::exists(dir / "out.h5"));
  // --to overrides the extension.
  ASSERT_EQ(test::RunCommand(tool + " " + d + "a.btf -o " + d + "x.data --to dataset --quiet"), 0);
  EXPECT_EQ(ReadDataset(dir / "x.data").num_views(), 2);
}

// btf-compress --method fmf|dfmf against btf-synth's ground truth (its dataset), then a codec
// written as a Bonn file by btf-convert (its own factors) and compared by btf-eval.
TEST(BtfCompressFmf, SynthGroundTruthThroughCompressConvertAndEval) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/";
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1,7 --lights 0,3,9,20 --resolution 8 --samples 1 "
                             "--quiet -o " + d + "a.h5"),
            0);
  auto rel = [&](const std::string& a, const std::string& b) {
    std::string out;
    EXPECT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + d + a + " " + d + b + " --json --quiet", &out), 0);
    return nlohmann::json::parse(out)["rel_l2"].get<double>();
  };
  std::string out;
  for (const char* method : {"fmf", "dfmf"}) {
    // Every component (clamped to the rank): the ground truth within 1e-3 relative, as the issue
    // asks (measured: 7e-8 fmf, 6e-7 dfmf: float32 factors, docs/btf-compress.md).
    ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "a.h5 --method " + method + " -c 1000 -o " + d +
                                   method + ".h5 --json --quiet",
                               &out),
              0);
    const auto j = nlohmann::json::parse(out);
    EXPECT_EQ(j["method"], method);
    EXPECT_TRUE(j.contains("matrix_components"));
    EXPECT_TRUE(j["seconds"].contains("factorise"));
    EXPECT_LT(j["relative_error"].get<double>(), 1e-3);
    EXPECT_LT(rel("a.h5", std::string(method) + ".h5"), 1e-3);
  }
  // Fewer components, a larger error (tests/compress FmfMethods.* check the decrease per component).
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "a.h5 --method fmf -c 3 -o " + d + "f3.h5 --quiet >/dev/null"),
            0);
  EXPECT_GT(rel("a.h5", "f3.h5"), 1e-3);
  // That codec as a .btf file: its own 3 components are written (a refactorisation would take
  // btf-convert's default 16), decoding like the codec up to float sums (1e-5).
  ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + d + "f3.h5 -o " + d + "f3.btf --to fmf --json --quiet", &out),
            0);
  EXPECT_EQ(nlohmann::json::parse(out)["input_kind"], "libbtf-codec");
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json --quiet --no-stats " + d + "f3.btf", &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["components"], nlohmann::json::array({3})) << out;
  EXPECT_LT(rel("f3.h5", "f3.btf"), 1e-5);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " --json --quiet --no-stats " + d + "dfmf.h5", &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["components_per_matrix"].size(), 3u);
  // An unknown method is a usage error; nothing is written.
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "a.h5 --method svd -o " + d + "x.h5 2>/dev/null"), 2);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.h5"));
}

}  // namespace
}  // namespace btf
