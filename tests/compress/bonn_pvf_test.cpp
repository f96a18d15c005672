// A per-view PCA codec written as Bonn PVF and read back by the PVF reader.
#include "libbtf/compress/compress.h"
#include "libbtf/compress/bonn_pvf.h"

#include <gtest/gtest.h>

#include <cmath>

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(BonnPvfWriter, PcaViewCodecToPvfDecodesLikeTheCodec) {
  Dataset d = test::MakeTestDataset(3, 6, 4, 5);
  d.info().cos_theta_i_included = true;
  CompressOptions o;
  o.components = 3;
  Codec codec;
  Compress(o, *MemorySource(d), &codec);
  const auto dir = test::TempDir();
  const ConvertSummary s = WritePvf(codec, "codec", dir / "p.btf");
  EXPECT_EQ(s.bytes_written, std::filesystem::file_size(dir / "p.btf"));
  const auto src = OpenBonnSource(dir / "p.btf");
  EXPECT_EQ(src->kind(), "bonn-pvf");
  EXPECT_TRUE(src->info().cos_theta_i_included);
  CheckCompatible(*MemorySource(d), *src);
  std::vector<float> a(src->slot_size()), b(src->slot_size());
  for (int v = 0; v < codec.num_views(); ++v) {
    codec.DecodeViewSlot(v, a.data());
    src->ReadViewSlot(v, b.data());
    // float32 factors stored as they are; the sums run in another order (Eigen's products of a
    // transposed matrix): a few float ulps of values up to about 3.
    for (std::size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], b[i], 2e-6f * (1 + std::abs(a[i]))) << v << " " << i;
  }
}

TEST(BonnPvfWriter, RefusesLpcaAndLogCodecs) {
  const Dataset d = test::MakeTestDataset(2, 4, 3, 3);
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = 2;
  o.components = 1;
  Codec codec;
  Compress(o, *MemorySource(d), &codec);
  const auto dir = test::TempDir();
  EXPECT_THROW(WritePvf(codec, "c", dir / "p.btf"), Error);
  o = CompressOptions();
  o.components = 2;
  o.log_transform = true;
  Compress(o, *MemorySource(d), &codec);
  try {
    WritePvf(codec, "c", dir / "p.btf");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

}  // namespace
}  // namespace btf
