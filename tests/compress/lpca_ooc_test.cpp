// Out-of-core LPCA (--lpca-memory out-of-core): the same algorithm as in core on a different data
// layout (texel chunks and cluster waves read from the view slots), so the codec must be
// bit-identical: every GEMM block holds the same 256 rows, every cluster's PCA the same rows in
// texel order, and every sum keeps its order. Tolerance 0 is therefore the honest assertion.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "libbtf/compress/bonn_fmf.h"
#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// BTF_MAX_BYTES for one scope.
struct ScopedMaxBytes {
  explicit ScopedMaxBytes(std::uint64_t bytes) { setenv("BTF_MAX_BYTES", std::to_string(bytes).c_str(), 1); }
  ~ScopedMaxBytes() { unsetenv("BTF_MAX_BYTES"); }
};

// 2 views x 3 lights, 96^2 texels, RGB: a texel matrix of 9216 x 18 floats = 663,552 bytes; four
// materials of rank 2 (the ground truth LPCA should find). More texels than the 8192-texel
// k-means sample (589,824 bytes), which must fit the limit: otherwise the sample is the matrix.
Dataset Input() { return test::ClusteredLowRank(test::BonnSubset(2, 13), test::BonnSubset(3, 7), 96, 96, 4, 2); }
// Between the sample and the matrix: out of core in 3 chunks of 4352 texels (the budget, half of
// it, holds 4444 rows).
constexpr std::uint64_t kLimit = 640000;

CompressOptions Lpca(int k, const std::string& memory) {
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = k;
  o.components = 3;
  o.lpca_memory = memory;
  return o;
}

TEST(LpcaOutOfCore, EqualsInCoreAndRecoversTheGroundTruth) {
  const Dataset d = Input();
  CompressSummary in, out;
  const Codec a = test::CompressDataset(d, Lpca(8, "in-core"), &in);
  Codec b;
  {
    const ScopedMaxBytes limit(kLimit);
    b = test::CompressDataset(d, Lpca(8, "out-of-core"), &out);
  }
  EXPECT_EQ(in.lpca_memory, "in-core");
  EXPECT_EQ(out.lpca_memory, "out-of-core");
  test::ExpectSameCodec(a, b);
  EXPECT_EQ(in.iteration_errors, out.iteration_errors);
  EXPECT_EQ(in.relative_error, out.relative_error);
  // 4 rank-2 materials, 8 clusters of 3 components: exact up to float rounding (relative 1e-5
  // is ~100 float epsilons of the 108-value ABRDFs' reconstruction).
  EXPECT_LT(out.relative_error, 1e-5);
  // In core: the matrix once and the error pass. Out of core, per phase 3 chunk passes (norms,
  // first assignment, each reassignment), one sample pass and >= 1 wave pass per cluster fit.
  EXPECT_EQ(in.lpca_passes, 2);
  EXPECT_GE(out.lpca_passes, 3 + 1 + 3 + 1 + 1);
  EXPECT_GT(out.peak_rss_bytes, 0u);
}

TEST(LpcaOutOfCore, AutoStreamsWhereInCoreIsRefused) {
  const Dataset d = Input();
  CompressSummary s;
  test::CompressDataset(d, Lpca(8, "auto"), &s);
  EXPECT_EQ(s.lpca_memory, "in-core");  // 664 KB: far below the default 16 GiB
  const ScopedMaxBytes limit(kLimit);
  test::CompressDataset(d, Lpca(8, "auto"), &s);
  EXPECT_EQ(s.lpca_memory, "out-of-core");
  EXPECT_LT(s.relative_error, 1e-5);
  ExitCode code{};
  const std::string e = test::ErrorOf([&] { test::CompressDataset(d, Lpca(8, "in-core")); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput) << e;
  EXPECT_NE(e.find("texel-major copy"), std::string::npos) << e;
  EXPECT_NE(e.find("BTF_MAX_BYTES"), std::string::npos) << e;
}

TEST(LpcaOutOfCore, RefusesAClusterLargerThanTheWaveBudget) {
  const Dataset d = Input();  // made before the limit, which it exceeds itself
  const ScopedMaxBytes limit(kLimit);
  // k = 1: the one cluster has all 9216 texels (663,552 bytes of rows > the 320,000-byte budget).
  ExitCode code{};
  const std::string e = test::ErrorOf([&] { test::CompressDataset(d, Lpca(1, "out-of-core")); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput) << e;
  EXPECT_NE(e.find("cluster 0 has 9216 texels"), std::string::npos) << e;
  EXPECT_NE(e.find("more clusters"), std::string::npos) << e;
  EXPECT_NE(e.find("BTF_MAX_BYTES"), std::string::npos) << e;
}

TEST(LpcaOutOfCore, StreamsABonnBtfFile) {
  const auto dir = test::TempDir();
  FmfWriteOptions w;
  w.components = 64;  // every component: the .btf holds the dataset up to float rounding
  WriteFmf(w, *MemorySource(Input()), dir / "in.btf");
  const auto src = OpenBonnSource(dir / "in.btf");
  Codec a, b;
  const CompressSummary in = Compress(Lpca(8, "in-core"), *src, &a);
  CompressSummary out;
  {
    const ScopedMaxBytes limit(kLimit);
    out = Compress(Lpca(8, "auto"), *src, &b);
  }
  EXPECT_EQ(out.lpca_memory, "out-of-core");
  test::ExpectSameCodec(a, b);
  EXPECT_LT(out.relative_error, 1e-4);  // FMF's float SVD of the input adds rounding (bonn_fmf_test: 1e-4)
}

TEST(LpcaOutOfCore, CheckNamesTheField) {
  CompressOptions o = Lpca(8, "swap");
  const std::string e = test::ErrorOf([&] { o.Check(); });
  EXPECT_NE(e.find("lpca_memory"), std::string::npos) << e;
}

}  // namespace
}  // namespace btf
