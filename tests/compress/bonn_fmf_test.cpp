// FMF and DFMF written by the streaming randomised SVD and read back by the Bonn readers.
#include "libbtf/compress/bonn_fmf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {


Dataset RandomDataset(int views, int lights, int h, int w, int channels) {
  Dataset d = test::MakeTestDataset(views, lights, h, w, channels);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  for (auto& x : d.data()) x = 0.2f + u(rng);
  return d;
}

TEST(BonnFmfWriter, AllComponentsRoundTrip) {
  const Dataset d = RandomDataset(3, 4, 5, 6, 3);  // FMF: 36 x 30, DFMF: 12 x 30 per channel
  const auto dir = test::TempDir();
  FmfWriteOptions o;
  o.components = 64;  // clamped to min(rows, texels): every component
  const ConvertSummary s = WriteFmf(o, *MemorySource(d), dir / "f.btf");
  EXPECT_EQ(s.output_format, "fmf");
  const auto fmf = OpenBonnSource(dir / "f.btf");
  EXPECT_EQ(fmf->kind(), "bonn-fmf");
  CheckCompatible(*MemorySource(d), *fmf);
  // float32 factors of a double SVD: a few float ulps of the largest value.
  EXPECT_LT(test::MaxRelativeError(*MemorySource(d), *fmf), 1e-5);
  o.decorrelate = true;
  WriteFmf(o, *MemorySource(d), dir / "d.btf");
  const BonnReader r(dir / "d.btf");
  EXPECT_EQ(r.header().color_model, 1);
  EXPECT_EQ(r.header().components, (std::vector<int>{12, 12, 12}));
  // The YUV inverse the reader applies has 5-6 significant digits (docs/format.md): its product
  // with the forward matrix differs from the identity by up to about 2e-5.
  EXPECT_LT(test::MaxRelativeError(*MemorySource(d), *OpenBonnSource(dir / "d.btf")), 1e-4);
}

TEST(BonnFmfWriter, FewerComponentsGiveLargerErrorsAndLowRankDataIsExact) {
  const Dataset d = RandomDataset(2, 5, 4, 4, 3);
  const auto dir = test::TempDir();
  double previous = 1e30;
  for (int k : {1, 3, 8}) {
    FmfWriteOptions o;
    o.components = k;
    WriteFmf(o, *MemorySource(d), dir / "f.btf");
    const double e = test::MaxRelativeError(*MemorySource(d), *OpenBonnSource(dir / "f.btf"));
    EXPECT_LT(e, previous) << k;
    previous = e;
  }
  // MakeTestDataset is v + 0.01 l + 1e-3 y + 1e-5 x + 0.3 c: rank 3 over texels (1, y, x).
  const Dataset low = test::MakeTestDataset(2, 5, 4, 4, 3);
  FmfWriteOptions o;
  o.components = 3;
  WriteFmf(o, *MemorySource(low), dir / "low.btf");
  EXPECT_LT(test::MaxRelativeError(*MemorySource(low), *OpenBonnSource(dir / "low.btf")), 1e-5);
}

TEST(BonnFmfWriter, DfmfNeedsThreeChannelsAndNothingIsWritten) {
  const Dataset d = RandomDataset(1, 2, 2, 2, 4);
  FmfWriteOptions o;
  o.decorrelate = true;
  const auto dir = test::TempDir();
  try {
    WriteFmf(o, *MemorySource(d), dir / "d.btf");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
  }
  Dataset bad = RandomDataset(1, 2, 2, 2, 3);
  bad.data()[3] = std::numeric_limits<float>::infinity();
  o.decorrelate = false;
  try {
    WriteFmf(o, *MemorySource(bad), dir / "f.btf");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

}  // namespace
}  // namespace btf
