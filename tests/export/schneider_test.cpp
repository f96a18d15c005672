#include "libbtf/export/schneider.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "libbtf/core/error.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "tests/compress/synthetic.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

Codec SmallLpca() {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(19), test::BonnSubset(19), 6, 5, 3, 2);
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = 3;
  o.components = 2;
  return test::CompressDataset(d, o);
}

TEST(SchneiderExport, ReferenceDecoderMatchesCodecToTheQuantizationError) {
  const Codec codec = SmallLpca();
  const auto dir = test::TempDir() / "export";
  SchneiderExportOptions o;
  o.view_grid = 8;
  o.light_grid = 6;
  const SchneiderExportSummary s = ExportSchneider(o, codec, dir);
  EXPECT_EQ(s.functions, 3);
  EXPECT_LE(s.max_quantization_error, 1.0 / 255 + 1e-12);  // half a step of 2/255
  const SchneiderReferenceDecoder ref(dir);
  double worst_ratio = 0;
  int checked = 0;
  // At grid nodes the trilinear fetch is exact, so the only difference to the codec's own
  // barycentric decoder is 8-bit rounding: |diff| <= sum_f |weight_f| / 255 (weights carry the scales).
  for (int y = 0; y < codec.height(); y += 2)
    for (int x = 0; x < codec.width(); x += 2)
      for (int tv : {0, 3, 7})
        for (int sv : {1, 4, 6})
          for (int tl : {0, 2, 5})
            for (int sl : {0, 3, 5}) {
              const Vec3 wo = HemisphereFromSquare(Vec2(GridCoordinate(sv, 8), GridCoordinate(tv, 8)));
              const Vec3 wi = HemisphereFromSquare(Vec2(GridCoordinate(sl, 6), GridCoordinate(tl, 6)));
              float a[3], b[3];
              ref.Value(x, y, wi, wo, a);
              codec.Value(Vec2((x + 0.5) / codec.width(), 1 - (y + 0.5) / codec.height()), wi, wo, b, UvFilter::kNearest);
              double bound = 0;
              for (int f = 0; f < ref.functions(); ++f) bound += std::abs(ref.weights(y, x)[f]) / 255.0;
              for (int c = 0; c < 3; ++c) {
                const double diff = std::abs(double(a[c]) - b[c]);
                EXPECT_LE(diff, bound + 1e-5) << "texel " << x << "," << y << " channel " << c;
                worst_ratio = std::max(worst_ratio, diff / bound);
                ++checked;
              }
            }
  EXPECT_GT(checked, 1000);
  // Rounding really happens (the comparison is not vacuous): the largest error uses a visible part of the bound.
  EXPECT_GT(worst_ratio, 0.05);
}

TEST(SchneiderExport, FilesHaveTheManifestShapes) {
  const Codec codec = SmallLpca();
  const auto dir = test::TempDir() / "export";
  ExportSchneider({}, codec, dir);
  std::ifstream in(dir / "manifest.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["format"], "libbtf-schneider-export");
  const auto shape = j["eigen_abrdfs"]["shape"];
  std::uint64_t n = 1;
  for (const auto& v : shape) n *= v.get<std::uint64_t>();
  EXPECT_EQ(std::filesystem::file_size(dir / "eigen_abrdfs.u8"), n);
  EXPECT_EQ(shape[2], 16 * 16);
  EXPECT_EQ(std::filesystem::file_size(dir / "weights.f32"), 6u * 5 * 3 * 4);
  EXPECT_EQ(std::filesystem::file_size(dir / "cluster_index.u16"), 6u * 5 * 2);
  // A truncated file is refused by the reference decoder.
  std::filesystem::resize_file(dir / "weights.f32", 8);
  EXPECT_THROW(SchneiderReferenceDecoder{dir}, Error);
}

TEST(SchneiderExport, RefusesPerViewPcaAndLogCodecs) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(5), 4, 4, 2, 1e-3);
  CompressOptions o;
  o.components = 2;
  try {
    ExportSchneider({}, test::CompressDataset(d, o), test::TempDir() / "x");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
    EXPECT_NE(std::string(e.what()).find("--method lpca"), std::string::npos);
  }
  o.method = CodecMethod::kLpca;
  o.clusters = 2;
  o.log_transform = true;
  EXPECT_THROW(ExportSchneider({}, test::CompressDataset(d, o), test::TempDir() / "y"), Error);
}

}  // namespace
}  // namespace btf
