#include "libbtf/compress/compress.h"
#include "libbtf/export/sattler.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "libbtf/core/error.h"
#include "libbtf/export/sattler_reference_decoder.h"
#include "libbtf/export/schneider.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "tests/compress/synthetic.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// 19 views x 19 lights of 6 x 5 texels; per-view PCA with c = 18 (all 19 lights' images, centred)
// reproduces every view slot up to float rounding, so the export is compared with the truth.
const Dataset& Truth() {
  static const Dataset d = test::ClusteredLowRank(test::BonnSubset(19), test::BonnSubset(19, 4), 6, 5, 3, 2);
  return d;
}
Codec PcaViewCodec(int components = 18) {
  CompressOptions o;
  o.method = CodecMethod::kPcaView;
  o.components = components;
  return test::CompressDataset(Truth(), o);
}

// The reference decoder against Codec::Value (nearest texel) at random (uv, wi, wo): both blend
// the same three views and lights, so they differ by the storage rounding only:
// |diff| <= ErrorBound(wi, wo) (sum_a bv_a sum_f |blended weight_f| * per_t) + 1e-5 for float
// arithmetic (values are O(1)). And at the sampled directions against btf-synth's truth, with
// the codec's own (float rounding) error on top: + 1e-4.
void ExpectWithinTheQuantizationBound(const std::string& storage, int atlas_side, int expected_layers, double min_used) {
  const Codec codec = PcaViewCodec();
  const auto dir = test::TempDir() / ("export_" + storage);
  SattlerExportOptions o;
  o.storage = storage;
  o.atlas_side = atlas_side;
  const SattlerExportSummary s = ExportSattler(o, codec, dir);
  EXPECT_EQ(s.functions, 19);
  EXPECT_EQ(s.layers, expected_layers);
  EXPECT_LE(s.max_quantization_error, StorageQuantizationBound(storage) + 1e-12);
  const SattlerReferenceDecoder ref(dir);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u01(0, 1);
  double worst = 0;
  for (int i = 0; i < 3000; ++i) {
    const int x = int(u01(rng) * 5) % 5, y = int(u01(rng) * 6) % 6;
    const Vec3 wi = HemisphereFromSquare(Vec2(u01(rng), u01(rng))), wo = HemisphereFromSquare(Vec2(u01(rng), u01(rng)));
    float a[3], b[3];
    ref.Value(x, y, wi, wo, a);
    codec.Value(Vec2((x + 0.5) / 5, 1 - (y + 0.5) / 6), wi, wo, b, UvFilter::kNearest);
    const double bound = ref.ErrorBound(wi, wo);
    for (int c = 0; c < 3; ++c) {
      const double diff = std::abs(double(a[c]) - b[c]);
      ASSERT_LE(diff, bound + 1e-5) << storage << " query " << i << " channel " << c;
      worst = std::max(worst, diff / bound);
    }
  }
  // Rounding really happens (the comparison is not vacuous).
  EXPECT_GT(worst, min_used) << storage;
  const Dataset& d = Truth();
  for (int v = 0; v < d.num_views(); v += 3)
    for (int l = 0; l < d.num_lights(); l += 2)
      for (int y = 0; y < 6; ++y)
        for (int x = 0; x < 5; ++x) {
          float a[3];
          ref.Value(x, y, d.lights()[l], d.views()[v], a);
          for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(a[c], d.image(v, l)[(std::size_t(y) * 5 + x) * 3 + c], ref.ErrorBound(d.lights()[l], d.views()[v]) + 1e-4)
                << "view " << v << " light " << l;
        }
}

TEST(SattlerExport, ReferenceDecoderMatchesCodecAndTruthToTheQuantizationErrorU8) {
  ExpectWithinTheQuantizationBound("u8", 256, 1, 0.1);
}
// Half floats: 16x finer steps; the float margin (1e-5) is then comparable to the bound.
TEST(SattlerExport, ReferenceDecoderMatchesCodecAndTruthToTheQuantizationErrorF16) {
  ExpectWithinTheQuantizationBound("f16", 256, 1, 0.01);
}
// 16-texel layers: 3 x 2 images of 5 x 6 per layer, 19 x 19 images on 61 layers.
TEST(SattlerExport, SeveralLayersDecodeTheSame) { ExpectWithinTheQuantizationBound("u8", 16, 61, 0.1); }

TEST(SattlerExport, ManifestAndFilesFollowTheLayout) {
  const auto dir = test::TempDir() / "export";
  const SattlerExportSummary s = ExportSattler({}, PcaViewCodec(4), dir);
  std::ifstream in(dir / "manifest.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["format_version"], "2.2.0");
  EXPECT_EQ(j["layout"], "sattler-2003");
  EXPECT_EQ(j["views"]["directions"].size(), 19u);
  // 19 views x 5 images of 5 x 6 texels: 51 tiles per row of 256, one layer.
  EXPECT_EQ(j["images"]["tiles_x"], 51);
  EXPECT_EQ(j["images"]["layers"], 1);
  EXPECT_EQ(std::filesystem::file_size(dir / "images.u8"), 1u * 6 * (51 * 5) * 2 * 3);
  EXPECT_EQ(std::filesystem::file_size(dir / "terms.f32"), 19u * 19 * 6 * 4);
  EXPECT_EQ(s.weight_bytes, 19u * 19 * 6 * 4);
  EXPECT_TRUE(std::filesystem::exists(dir / "btf_sattler.glsl"));
  // The other layout's decoder refuses it, naming the layout.
  try {
    SchneiderReferenceDecoder{dir};
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("sattler-2003"), std::string::npos);
  }
  std::filesystem::resize_file(dir / "terms.f32", 8);
  EXPECT_THROW(SattlerReferenceDecoder{dir}, Error);
}

TEST(SattlerExport, RefusesOtherCodecsLogCodecsAndLayoutsBeyondWebGl2) {
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = 3;
  o.components = 2;
  try {
    ExportSattler({}, test::CompressDataset(Truth(), o), test::TempDir() / "x");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
    EXPECT_NE(std::string(e.what()).find("--format schneider"), std::string::npos);
  }
  o.method = CodecMethod::kPcaView;
  o.log_transform = true;
  EXPECT_THROW(ExportSattler({}, test::CompressDataset(Truth(), o), test::TempDir() / "y"), Error);
  SattlerExportOptions e;
  e.atlas_side = 4;  // below the 5 x 6 image
  EXPECT_THROW(ExportSattler(e, PcaViewCodec(2), test::TempDir() / "z"), Error);
  e.atlas_side = 16;
  e.storage = "f32";
  EXPECT_THROW(e.Check(), Error);
}

// A 1 x 1 texel, 1-channel export built byte by byte from docs/format.md (layout sattler-2003):
// 3 views and 3 lights (the axes), F = 1 (mean images only), u8 images 3 x 1 x 1 layer.
TEST(SattlerExport, HandBuiltExportDecodesAsDocumented) {
  const auto dir = test::TempDir() / "hand";
  std::filesystem::create_directories(dir);
  const nlohmann::json axes = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  nlohmann::json m = {
      {"format", "libbtf-schneider-export"}, {"format_version", "2.1.0"}, {"layout", "sattler-2003"},
      {"texture", {{"width", 1}, {"height", 1}, {"channels", 1}}},
      {"values", {{"units", "brdf_per_sr"}, {"cos_theta_i_included", false}}},
      {"views", {{"count", 3}, {"directions", axes}}}, {"lights", {{"count", 3}, {"directions", axes}}},
      {"functions", {{"count_per_view", 1}}},
      {"images", {{"file", "images.u8"}, {"storage", "u8"}, {"width", 3}, {"height", 1}, {"layers", 1},
                  {"tiles_x", 3}, {"tiles_y", 1}}},
      {"terms", {{"file", "terms.f32"}}},
      {"quantisation_error_bound", {{"per_t", 0.5 / 255}}}};
  std::ofstream(dir / "manifest.json") << m.dump();
  const unsigned char images[3] = {0, 51, 255};  // t = 0, 0.2, 1 for views 0, 1, 2
  std::ofstream(dir / "images.u8", std::ios::binary).write(reinterpret_cast<const char*>(images), 3);
  float terms[3][3][2];
  for (int v = 0; v < 3; ++v)
    for (int l = 0; l < 3; ++l) terms[v][l][0] = float(10 * v + l), terms[v][l][1] = float(l + 1);
  std::ofstream(dir / "terms.f32", std::ios::binary).write(reinterpret_cast<const char*>(terms), sizeof(terms));
  const SattlerReferenceDecoder ref(dir);
  float out = 0;
  // At view 1 and light 2 exactly: terms[1][2][0] + terms[1][2][1] * 0.2 = 12 + 3 * 0.2.
  ref.Value(0, 0, Vec3(0, 0, 1), Vec3(0, 1, 0), &out);
  EXPECT_NEAR(out, 12.6, 1e-5);
  // Between views 1 and 2 (equal weights), at light 0: 0.5 (10 + 0.2) + 0.5 (20 + 1).
  ref.Value(0, 0, Vec3(1, 0, 0), Vec3(0, 1, 1), &out);
  EXPECT_NEAR(out, 0.5 * 10.2 + 0.5 * 21.0, 1e-5);
}

}  // namespace
}  // namespace btf
