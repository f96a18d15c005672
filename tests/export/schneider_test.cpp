#include "libbtf/compress/compress.h"
#include "libbtf/export/schneider.h"
#include "libbtf/compress/lpca_tensor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <set>

#include "libbtf/core/error.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "tests/compress/synthetic.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// lpca, or lpca-tensor with 8-bit factors.
Codec SmallLpca(CodecMethod method = CodecMethod::kLpca) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(19), test::BonnSubset(19), 6, 5, 3, 2);
  CompressOptions o;
  o.method = method;
  o.clusters = 3;
  o.components = 2;
  o.tensor.quant_bits = 8;
  return test::CompressDataset(d, o);
}

// At grid nodes the trilinear fetch is exact, so the only difference to the codec's own
// barycentric decoder is the storage rounding: |diff| <= sum_f |terms[1 + f]| * per_t (u8: 1/510,
// f16: 2^-12), plus 1e-5 for float arithmetic in the decoders (values are O(1)).
void ExpectGridNodesWithinBound(const std::string& storage, int atlas_side, double min_used_fraction,
                                const Codec& codec = SmallLpca()) {
  const auto dir = test::TempDir() / ("export_" + storage);
  SchneiderExportOptions o;
  o.view_grid = 8;
  o.light_grid = 6;
  o.storage = storage;
  o.atlas_side = atlas_side;
  const SchneiderExportSummary s = ExportSchneider(o, codec, dir);
  EXPECT_EQ(s.functions, 3);
  EXPECT_LE(s.max_quantization_error, StorageQuantizationBound(storage) + 1e-12);
  const SchneiderReferenceDecoder ref(dir);
  EXPECT_DOUBLE_EQ(ref.quantization_bound(), StorageQuantizationBound(storage));
  double worst_ratio = 0;
  int checked = 0;
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
              const double bound = ref.ErrorBound(x, y);
              for (int c = 0; c < 3; ++c) {
                const double diff = std::abs(double(a[c]) - b[c]);
                EXPECT_LE(diff, bound + 1e-5) << storage << " texel " << x << "," << y << " channel " << c;
                worst_ratio = std::max(worst_ratio, diff / bound);
                ++checked;
              }
            }
  EXPECT_GT(checked, 1000);
  // Rounding really happens (the comparison is not vacuous): the largest error uses a visible part of the bound.
  EXPECT_GT(worst_ratio, min_used_fraction) << storage;
}

TEST(SchneiderExport, ReferenceDecoderMatchesCodecToTheQuantizationErrorU8) { ExpectGridNodesWithinBound("u8", 256, 0.1); }

// Half floats: 16x finer steps than u8; the float arithmetic margin (1e-5) is then comparable to the bound.
TEST(SchneiderExport, ReferenceDecoderMatchesCodecToTheQuantizationErrorF16) { ExpectGridNodesWithinBound("f16", 256, 0.01); }

// A small atlas side forces several tiles rows and pages: the layout formula is still what the decoder reads.
// lpca-tensor exports as the LPCA codec its terms make (ExpandToLpcaCodec): the same bound
// against its own decoder, and the expansion decodes as the tensor codec does (float rounding of
// the summed terms: 1e-5 of values O(1)).
TEST(SchneiderExport, LpcaTensorExportsAsTheLpcaItFactorises) {
  const Codec tensor = SmallLpca(CodecMethod::kLpcaTensor);
  ExpectGridNodesWithinBound("f16", 256, 0.01, tensor);
  const Dataset a = tensor.DecodeAll(), b = ExpandToLpcaCodec(tensor).DecodeAll();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a.data()[i], b.data()[i], 1e-5) << i;
}

TEST(SchneiderExport, AtlasWithSeveralPagesDecodesTheSame) { ExpectGridNodesWithinBound("u8", 36, 0.1); }

TEST(SchneiderExport, ScaleAndBiasUseTheFullEightBitRange) {
  const Codec codec = SmallLpca();
  const auto dir = test::TempDir() / "export";
  SchneiderExportOptions o;
  o.view_grid = 8;
  o.light_grid = 6;
  const SchneiderExportSummary s = ExportSchneider(o, codec, dir);
  std::ifstream in(dir / "atlas.u8", std::ios::binary);
  std::vector<unsigned char> q((std::istreambuf_iterator<char>(in)), {});
  // Every function's tile holds code 0 (its minimum) and 255 (its maximum): check over all tiles
  // of page 0 that both extreme codes occur once per function.
  const int per_tile = 8 * 8 * 36 * 3;
  ASSERT_EQ(q.size(), std::size_t(s.atlas_pages) * s.atlas_width * s.atlas_height * s.atlas_depth * 3);
  int lows = 0, highs = 0;
  for (unsigned char v : q) lows += v == 0, highs += v == 255;
  EXPECT_GE(lows, s.clusters * s.functions);
  EXPECT_GE(highs, s.clusters * s.functions);
  EXPECT_GT(per_tile, 0);
}

TEST(SchneiderExport, FilesHaveTheManifestShapes) {
  const Codec codec = SmallLpca();
  const auto dir = test::TempDir() / "export";
  const SchneiderExportSummary s = ExportSchneider({}, codec, dir);
  std::ifstream in(dir / "manifest.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["format"], "libbtf-schneider-export");
  EXPECT_EQ(j["format_version"], "2.2.0");
  EXPECT_EQ(j["layout"], "schneider-2004");
  const auto shape = j["atlas"]["shape"];
  std::uint64_t n = 1;
  for (const auto& v : shape) n *= v.get<std::uint64_t>();
  EXPECT_EQ(std::filesystem::file_size(dir / "atlas.u8"), n);
  // 3 clusters x 3 functions of 16 x 16 texels: one page, 9 tiles in a row, depth 16 x 16 = 256.
  EXPECT_EQ(j["atlas"]["depth"], 256);
  EXPECT_EQ(j["atlas"]["pages"], 1);
  EXPECT_EQ(j["atlas"]["width"], 9 * 16);
  EXPECT_LE(j["atlas"]["width"].get<int>(), 256);
  EXPECT_EQ(s.atlas_width, 9 * 16);
  EXPECT_EQ(std::filesystem::file_size(dir / "terms.f32"), 6u * 5 * 4 * 4);
  EXPECT_EQ(std::filesystem::file_size(dir / "cluster_index.u16"), 6u * 5 * 2);
  EXPECT_TRUE(std::filesystem::exists(dir / "btf_schneider.glsl"));
  // A truncated file is refused by the reference decoder.
  std::filesystem::resize_file(dir / "terms.f32", 8);
  EXPECT_THROW(SchneiderReferenceDecoder{dir}, Error);
}

// Every file of an export carries its CRC-32 in the manifest: a flipped bit anywhere in any of
// them (each byte of each file in turn) is refused by the reference decoder naming the file; the
// intact export reads.
TEST(SchneiderExport, AFlippedBitInAnyFileIsRefused) {
  const auto dir = test::TempDir() / "export";
  SchneiderExportOptions o;
  o.view_grid = o.light_grid = 2;  // a small atlas (about 1 kB): every byte of every file is flipped
  ExportSchneider(o, SmallLpca(), dir);
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "manifest.json"));
  ASSERT_EQ(j["checksums"]["algorithm"], "crc32");
  std::set<std::string> listed;
  for (const auto& [name, crc] : j["checksums"]["files"].items()) listed.insert(name);
  EXPECT_EQ(listed, (std::set<std::string>{"atlas.u8", "btf_schneider.glsl", "cluster_index.u16", "scale_bias.f32",
                                           "terms.f32"}));
  EXPECT_NO_THROW(SchneiderReferenceDecoder{dir});
  int refused = 0, flips = 0;
  for (const std::string& name : listed) {
    std::string bytes = test::Slurp(dir / name);
    for (std::size_t i = 0; i < bytes.size(); ++i) {
      bytes[i] = char(bytes[i] ^ (1 << (i % 8)));
      std::ofstream(dir / name, std::ios::binary | std::ios::trunc) << bytes;
      ++flips;
      try {
        SchneiderReferenceDecoder ref(dir);
      } catch (const Error& e) {
        refused += std::string(e.what()).find(name) != std::string::npos;
      }
      bytes[i] = char(bytes[i] ^ (1 << (i % 8)));
    }
    std::ofstream(dir / name, std::ios::binary | std::ios::trunc) << bytes;
  }
  EXPECT_EQ(refused, flips);
  EXPECT_NO_THROW(SchneiderReferenceDecoder{dir});
}

// The checksum is zlib's CRC-32 (docs/format.md): its standard check value.
TEST(SchneiderExport, ChecksumIsTheStandardCrc32) {
  const std::string check = "123456789";
  EXPECT_EQ(export_detail::Crc32(reinterpret_cast<const unsigned char*>(check.data()), check.size()), 0xCBF43926u);
}

TEST(SchneiderExport, RefusesAtlasDepthOverTheLimit) {
  SchneiderExportOptions o;
  o.light_grid = 17;  // 289 > 256
  EXPECT_THROW(o.Check(), Error);
  o.light_grid = 16;
  o.storage = "f32";
  EXPECT_THROW(o.Check(), Error);
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
