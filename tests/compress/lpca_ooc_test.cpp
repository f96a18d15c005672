// Out-of-core LPCA (--lpca-memory out-of-core): the same algorithm as in core on a different data
// layout (texel chunks and cluster waves read from the view slots), so the codec must be
// bit-identical: every GEMM block holds the same 256 rows, every cluster's PCA the same rows in
// texel order, and every sum keeps its order. Tolerance 0 is therefore the honest assertion.
#include <gtest/gtest.h>

#include <optional>

#include <cstdlib>
#include <string>

#include <fmt/ranges.h>

#include "libbtf/compress/compress.h"
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

// 2 views x 3 lights, 96^2 texels, RGB: a float texel matrix of 9216 x 18 floats = 663,552 bytes; four
// materials of rank 2 (the ground truth LPCA should find). More texels than the 8192-texel
// k-means sample (589,824 bytes), which must fit the limit: otherwise the sample is the matrix.
Dataset Input() { return test::ClusteredLowRank(test::BonnSubset(2, 13), test::BonnSubset(3, 7), 96, 96, 4, 2); }
// Between the sample and the float matrix: out of core in 3 chunks of 4352 texels (the budget,
// half of it, holds 4444 float rows; 2 chunks of 8704 texels with the half matrix). The byte
// arithmetic of these tests is for the float matrix (--lpca-matrix float) unless they say half.
constexpr std::uint64_t kLimit = 640000;

CompressOptions Lpca(int k, const std::string& memory, const std::string& matrix = "float") {
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = k;
  o.components = 3;
  o.lpca.memory = memory;
  o.lpca.matrix = matrix;
  return o;
}

TEST(LpcaOutOfCore, EqualsInCoreAndRecoversTheGroundTruth) {
  const Dataset d = Input();
  for (const std::string matrix : {"float", "half"}) {
    SCOPED_TRACE(matrix);
    CompressSummary in, out;
    const Codec a = test::CompressDataset(d, Lpca(8, "in-core", matrix), &in);
    Codec b;
    {
      const ScopedMaxBytes limit(kLimit);
      b = test::CompressDataset(d, Lpca(8, "out-of-core", matrix), &out);
    }
    EXPECT_EQ(in.lpca_memory, "in-core");
    EXPECT_EQ(out.lpca_memory, "out-of-core");
    EXPECT_EQ(out.lpca_matrix, matrix);
    test::ExpectSameCodec(a, b);
    EXPECT_EQ(in.iteration_errors, out.iteration_errors);
    EXPECT_EQ(in.relative_error, out.relative_error);
    // 4 rank-2 materials, 8 clusters of 3 components: float, exact up to float rounding (relative
    // 1e-5 is ~100 float epsilons of the 108-value ABRDFs' reconstruction). Half: fitted to the
    // half-rounded input, measured against the input: the rounding (each value within 2^-11
    // relative; the residual is within 2 x 2^-11 of the norm) stays. Measured 9.6e-5, bound 2^-11
    // = 4.9e-4 (5x margin).
    EXPECT_LT(out.relative_error, matrix == "float" ? 1e-5 : 1.0 / 2048) << matrix;
    // In core: the matrix once and the error pass. Out of core, per phase >= 2 chunk passes (norms,
    // first assignment, each reassignment), one sample pass and >= 1 wave pass per cluster fit.
    EXPECT_EQ(in.lpca_passes, 2);
    EXPECT_GE(out.lpca_passes, 2 + 1 + 2 + 1 + 1);
    EXPECT_GT(out.peak_rss_bytes, 0u);
  }
}

TEST(LpcaOutOfCore, EqualsInCoreOnTheRandomizedPath) {
  // The clusters' PCA by the randomized path (gram_limit 1; d = 2 views x 6 lights x RGB = 36
  // values, above the sketch's 2 (c + 10) = 26), which in core reads each cluster's rows from
  // the texel matrix in blocks of kPcaBlockRows (clusters of about 1152 texels: several blocks)
  // and out of core from the wave's gathered rows. Float matrix 9216 x 36 x 4 = 1,327,104 bytes,
  // the sample 1,179,648: a limit between them. The sample rounds in the full dimension (36
  // values: below 2 x the default subspace) and in a subspace of 16, whose lifted models start
  // the randomized fits.
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(2, 13), test::BonnSubset(6, 7), 96, 96, 4, 2);
  for (const std::string matrix : {"float", "half"})
    for (const int subspace : {CompressOptions().lpca.subspace, 16}) {
      SCOPED_TRACE(matrix + ", subspace " + std::to_string(subspace));
      CompressOptions in_core = Lpca(8, "in-core", matrix), out_of_core = Lpca(8, "out-of-core", matrix);
      in_core.lpca.gram_limit = out_of_core.lpca.gram_limit = 1;
      in_core.lpca.subspace = out_of_core.lpca.subspace = subspace;
      CompressSummary in, out;
      const Codec a = test::CompressDataset(d, in_core, &in);
      Codec b;
      {
        const ScopedMaxBytes limit(1250000);
        b = test::CompressDataset(d, out_of_core, &out);
      }
      EXPECT_EQ(out.lpca_memory, "out-of-core");
      test::ExpectSameCodec(a, b);
      EXPECT_EQ(in.sample_errors, out.sample_errors);
      EXPECT_EQ(in.iteration_errors, out.iteration_errors);
      EXPECT_EQ(in.relative_error, out.relative_error);
    }
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
  o = Lpca(8, "auto", "double");
  const std::string m = test::ErrorOf([&] { o.Check(); });
  EXPECT_NE(m.find("lpca_matrix"), std::string::npos) << m;
}

// The half texel matrix halves LPCA's largest allocation; its rounding (2^-11 relative at most)
// must cost little against LPCA's own error. Clusters without a clean structure (noise 5 %), so
// that the error is LPCA's, not the rounding's.
TEST(LpcaHalfMatrix, ErrorStaysWithinTheRoundingOfTheFloatPath) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(4), test::BonnSubset(5), 24, 24, 6, 0.05);
  CompressOptions o = Lpca(5, "in-core", "float");
  o.components = 2;
  CompressSummary f, h;
  test::CompressDataset(d, o, &f);
  o.lpca.matrix = "half";
  test::CompressDataset(d, o, &h);
  EXPECT_EQ(f.lpca_matrix, "float");
  EXPECT_EQ(h.lpca_matrix, "half");
  // The residuals of the two fits differ by the rounding, at most 2^-11 of the norm each way, plus
  // what a different clustering of the rounded input changes. Measured: float 0.166846, half
  // 0.166862 (difference 1.6e-5); bound 2^-11 = 4.9e-4 of the norm (30x margin).
  EXPECT_NEAR(h.relative_error, f.relative_error, 1.0 / 2048) << f.relative_error << " " << h.relative_error;
}

// A transformed value beyond the half range (65504) cannot be held: refused, naming the value and
// the float matrix; the float matrix takes it.
TEST(LpcaHalfMatrix, RefusesAValueBeyondTheHalfRangeAndFloatTakesIt) {
  Dataset d = Input();
  d.at(1, 2, 5, 7, 1) = 70000;
  ExitCode code{};
  const std::string e = test::ErrorOf([&] { test::CompressDataset(d, Lpca(8, "in-core", "half")); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput) << e;
  for (const char* part : {"70000", "view 1, light 2, texel (y 5, x 7), channel 1", "65504", "--lpca-matrix float"})
    EXPECT_NE(e.find(part), std::string::npos) << part << ": " << e;
  CompressSummary s;
  test::CompressDataset(d, Lpca(8, "in-core", "float"), &s);
  EXPECT_EQ(s.lpca_matrix, "float");
  // Out of core (2 texel chunks: each pass reads whole slots but writes rows of one chunk): the
  // same refusal, word for word, also for a value in the second chunk only (y 95: texel 9127).
  const ScopedMaxBytes limit(kLimit);
  const std::string o = test::ErrorOf([&] { test::CompressDataset(d, Lpca(8, "out-of-core", "half")); });
  EXPECT_EQ(o, e);
  d.at(1, 2, 5, 7, 1) = 0;
  d.at(1, 2, 95, 7, 1) = 70000;
  const std::string late = test::ErrorOf([&] { test::CompressDataset(d, Lpca(8, "in-core", "half")); });
  EXPECT_NE(late.find("view 1, light 2, texel (y 95, x 7), channel 1"), std::string::npos) << late;
  EXPECT_EQ(test::ErrorOf([&] { test::CompressDataset(d, Lpca(8, "out-of-core", "half")); }), late);
}

// Values below half's normal range would be stored as subnormals or zeros (a dataset scaled to
// 1e-30 would decode as all zero): the run switches to a float matrix, says so, and its error is
// the float run's, measured on the codec as stored. In core and out of core alike.
TEST(LpcaHalfMatrix, ValuesBelowTheHalfRangeSwitchToFloat) {
  Dataset d = test::PerViewLowRank(test::BonnSubset(4), test::BonnSubset(5), 24, 24, 6, 0.05);
  for (float& x : d.data()) x *= 1e-30f;
  for (const char* memory : {"in-core", "out-of-core"}) {
    std::optional<ScopedMaxBytes> limit;
    if (std::string(memory) == "out-of-core") limit.emplace(kLimit);
    CompressOptions o = Lpca(5, memory, "float");
    o.components = 2;
    CompressSummary f, h;
    test::CompressDataset(d, o, &f);
    o.lpca.matrix = "half";
    test::CompressDataset(d, o, &h);
    EXPECT_EQ(h.lpca_matrix, "float") << memory;
    // The float run's warnings and one more: the switch.
    ASSERT_EQ(h.warnings.size(), f.warnings.size() + 1) << memory << ": " << fmt::format("{}", fmt::join(h.warnings, " | "));
    EXPECT_NE(h.warnings[0].find("--lpca-matrix float"), std::string::npos) << h.warnings[0];
    EXPECT_TRUE(std::equal(f.warnings.begin(), f.warnings.end(), h.warnings.begin() + 1)) << memory;
    // The same run as the float one: the same error (of the decoded codec against the input),
    // well below 1 (an all-zero decode).
    EXPECT_EQ(h.relative_error, f.relative_error) << memory;
    EXPECT_LT(h.relative_error, 0.5) << memory;
  }
}

}  // namespace
}  // namespace btf
