// Issue 15: the fused per-view PCA (WidePca), the sign convention, thread-count independence
// and half storage. All quick (small synthetic BTFs).
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <random>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/compress/pca.h"
#include "libbtf/core/error.h"
#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// n x d, rank r around a non-zero mean, plus noise.
RowMatrixXf LowRank(int n, int d, int r, float noise, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> uni(-1, 1);
  RowMatrixXf U(n, r), V(r, d);
  for (int i = 0; i < U.size(); ++i) U.data()[i] = uni(rng);
  for (int i = 0; i < V.size(); ++i) V.data()[i] = uni(rng) / float(1 + i / d);  // decaying spectrum
  RowMatrixXf X = U * V;
  for (int i = 0; i < X.size(); ++i) X.data()[i] += 1.5f + noise * uni(rng);
  return X;
}

// The largest-magnitude entry of every basis row (the first on ties) is positive.
void ExpectSignConvention(const float* basis, int c, std::size_t d) {
  for (int k = 0; k < c; ++k) {
    float best = 0, value = 0;
    for (std::size_t i = 0; i < d; ++i)
      if (std::abs(basis[k * d + i]) > best) best = std::abs(basis[k * d + i]), value = basis[k * d + i];
    EXPECT_GT(value, 0) << "component " << k;
  }
}

TEST(WidePca, MatchesTheFullSvdWithOrthonormalBasisAndProjectionWeights) {
  // d not a multiple of the tile, so the last tile is partial.
  const int n = 40, d = 3 * int(kWideTile) + 37, c = 6;
  const RowMatrixXf X = LowRank(n, d, 8, 1e-3f, 7);
  PcaRequest q;
  q.max_components = c;
  const WidePcaResult w = WidePca(X.data(), n, d, q);
  const PcaResult ref = PcaFullSvd(X, c);
  ASSERT_EQ(w.components, c);
  EXPECT_EQ(w.non_finite, -1);
  const Eigen::Map<const RowMatrixXf> B(w.basis.data(), c, d), W(w.weights.data(), n, c);
  const Eigen::Map<const Eigen::RowVectorXf> mean(w.mean.data(), d);
  // Orthonormal rows without re-orthonormalisation: measured max |B B^T - I| ~1e-7 (float
  // rounding of the rows); 1e-5 is the float-precision bound the codec promises.
  const Eigen::MatrixXd g = B.cast<double>() * B.cast<double>().transpose();
  EXPECT_LT((g - Eigen::MatrixXd::Identity(c, c)).cwiseAbs().maxCoeff(), 1e-5);
  // Eigenvalues and subspace agree with the full SVD (double vs float SVD: 1e-4 relative).
  for (int k = 0; k < c; ++k) {
    EXPECT_NEAR(w.eigenvalues[k], ref.eigenvalues[k], 1e-4 * ref.eigenvalues[0]) << k;
    // Same sign convention on both paths, so the rows themselves agree (well-separated spectrum).
    EXPECT_LT((B.row(k) - ref.basis.row(k)).cwiseAbs().maxCoeff(), 1e-3) << k;
  }
  // Weights U Lambda^(1/2) are the projections of the centred rows onto the stored basis.
  const RowMatrixXf Xc = X.rowwise() - mean;
  const RowMatrixXf proj = Xc * B.transpose();
  EXPECT_LT((proj - W).cwiseAbs().maxCoeff(), 1e-4 * std::sqrt(w.eigenvalues[0]));
  // Residual = centred energy - captured, and it is the reconstruction's squared error.
  const RowMatrixXf rec = (W * B).rowwise() + mean;
  const double err = (rec - X).cast<double>().squaredNorm();
  EXPECT_NEAR(w.residual_energy, err, 1e-3 * err + 1e-9 * w.total_energy);
  ExpectSignConvention(w.basis.data(), c, std::size_t(d));
}

TEST(WidePca, SinkSeesTheReconstructionOfEveryColumnOnce) {
  const int n = 12, d = int(kWideTile) + 5;
  const RowMatrixXf X = LowRank(n, d, 3, 0, 2);
  PcaRequest q;
  q.max_components = 3;
  std::vector<int> seen(std::size_t(d), 0);
  RowMatrixXf rec(n, d);
  const WidePcaResult w = WidePca(X.data(), n, d, q, false, [&](Eigen::Index c0, const Eigen::Ref<const RowMatrixXf>& t) {
    for (Eigen::Index j = 0; j < t.cols(); ++j) ++seen[std::size_t(c0 + j)];
    rec.middleCols(c0, t.cols()) = t;
  });
  for (int s : seen) EXPECT_EQ(s, 1);
  // Exact rank 3: the reconstruction is the data to float rounding (values ~1.5, 1e-5).
  EXPECT_LT((rec - X).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_EQ(w.components, 3);
}

TEST(WidePca, ReportsANonFiniteValue) {
  RowMatrixXf X = LowRank(5, 600, 2, 0, 3);
  X(3, 400) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(WidePca(X.data(), 5, 600, PcaRequest{}).non_finite, 3 * 600 + 400);
  X(4, 10) = std::numeric_limits<float>::infinity();  // in an earlier tile: found first
  EXPECT_EQ(WidePca(X.data(), 5, 600, PcaRequest{}).non_finite, 4 * 600 + 10);
}

TEST(SignConvention, BothMethodsStoreTheLargestEntryOfEachComponentPositive) {
  const Dataset pv = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(12), 6, 6, 3, 1e-3);
  CompressOptions o;
  o.components = 3;
  const Codec a = test::CompressDataset(pv, o);
  for (const auto& s : a.pca_view()) ExpectSignConvention(s.basis.data(), s.components, a.image_size());
  const Dataset cl = test::ClusteredLowRank(test::BonnSubset(4), test::BonnSubset(4), 8, 8, 3, 2);
  o.method = CodecMethod::kLpca;
  o.clusters = 3;
  o.components = 2;
  const Codec b = test::CompressDataset(cl, o);
  const LpcaModel& m = b.lpca();
  for (int k = 0; k < m.clusters; ++k)
    ExpectSignConvention(&m.basis[std::size_t(k) * m.components * b.abrdf_size()], m.cluster_components[k],
                         b.abrdf_size());
}

Codec CompressWithThreads(const Dataset& d, const CompressOptions& o, int threads, CompressSummary* s) {
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  Codec c = test::CompressDataset(d, o, s);
  omp_set_num_threads(before);
  return c;
}

TEST(Determinism, OneAndTwoThreadsGiveIdenticalCodecs) {
  // pca-view: 5 views (odd: the last batch of 2 threads has one slot); lpca: 24 x 24 texels (three
  // blocks of 256 texels), several rounds.
  const Dataset pv = test::PerViewLowRank(test::BonnSubset(5), test::BonnSubset(15), 10, 10, 4, 1e-2);
  // One compression on 1 and on 2 threads: the same codec and the same error figures (every
  // list: the rounds', the sample's, the trials'); returns the 1-thread summary.
  auto same = [](const Dataset& d, const CompressOptions& o) {
    CompressSummary s1, s2;
    const Codec a = CompressWithThreads(d, o, 1, &s1), b = CompressWithThreads(d, o, 2, &s2);
    test::ExpectSameCodec(a, b);
    EXPECT_EQ(s1.relative_error, s2.relative_error);
    EXPECT_EQ(s1.iteration_errors, s2.iteration_errors);
    EXPECT_EQ(s1.sample_errors, s2.sample_errors);
    EXPECT_EQ(s1.split_errors, s2.split_errors);
    return s1;
  };
  CompressOptions o;
  o.components = 4;
  same(pv, o);
  // Texels without a clear clustering, so the local-PCA rounds move texels. 576 texels, all in
  // the default 8192-texel sample: local-PCA rounds and split/merge trials on it, then rounds
  // over all texels.
  const Dataset cl = test::PerViewLowRank(test::BonnSubset(4), test::BonnSubset(5), 24, 24, 6, 0.05);
  o.method = CodecMethod::kLpca;
  o.clusters = 5;
  o.components = 2;
  CompressSummary s = same(cl, o);
  EXPECT_GE(s.iteration_errors.size(), 2u) << s.ToJson().dump();
  EXPECT_GE(s.split_errors.size(), 1u) << s.ToJson().dump();
  // Mini-batch local-PCA rounds on a 300-texel sample (two blocks of 256, the second partial),
  // then rounds over all texels.
  o.lpca.sample = 300;
  s = same(cl, o);
  EXPECT_GE(s.sample_errors.size(), 2u) << s.ToJson().dump();
  // The same through the randomized path (gram_limit 1; d = 60 values per texel), whose refits
  // and first fit over all texels are warm-started (CompressOptions::lpca_warm_start).
  o.lpca.gram_limit = 1;
  s = same(cl, o);
  EXPECT_GE(s.iteration_errors.size(), 2u) << s.ToJson().dump();
}

TEST(HalfStorage, HalvesTheFloatArraysWithinTheRoundingBound) {
  const Dataset pv = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(12), 8, 8, 3, 1e-3);
  const Dataset cl = test::ClusteredLowRank(test::BonnSubset(4), test::BonnSubset(4), 8, 8, 3, 2);
  for (const CodecMethod method : {CodecMethod::kPcaView, CodecMethod::kLpca}) {
    const Dataset& d = method == CodecMethod::kPcaView ? pv : cl;
    CompressOptions o;
    o.method = method;
    o.components = 3;
    o.clusters = 3;
    CompressSummary sf, sh;
    const Codec f = test::CompressDataset(d, o, &sf);
    o.storage = CodecStorage::kHalf;
    const Codec h = test::CompressDataset(d, o, &sh);
    EXPECT_EQ(sh.storage, "half");
    EXPECT_EQ(h.storage(), CodecStorage::kHalf);
    // Floats at 2 bytes, int32 indices (lpca) unchanged.
    const std::uint64_t ints = method == CodecMethod::kLpca ? 4 * (64 + 3) : 0;
    EXPECT_EQ(sh.codec_bytes - ints, (sf.codec_bytes - ints) / 2);
    // Every decoded value within the rounding bound of the float codec's: each stored value is
    // rounded to 11 significant bits (relative 2^-11), so |mean + sum w b| moves by at most
    // 2^-11 (|mean| + 2 sum |w| |b|) (+ 2^-22 terms); bound 1.1 x that, plus 1e-6 float slop.
    const Dataset df = f.DecodeAll(), dh = h.DecodeAll();
    double worst = 0;
    for (int v = 0; v < d.num_views(); ++v)
      for (int y = 0; y < d.height(); ++y)
        for (int x = 0; x < d.width(); ++x) {
          const std::size_t t = std::size_t(y) * d.width() + x;
          for (int l = 0; l < d.num_lights(); ++l)
            for (int ch = 0; ch < 3; ++ch) {
              double mag = 0;
              if (method == CodecMethod::kPcaView) {
                const PcaViewSlot& s = f.pca_view()[v];
                const std::size_t i = t * 3 + ch;
                mag = std::abs(s.mean[i]);
                for (int k = 0; k < s.components; ++k)
                  mag += 2 * std::abs(s.weights[l * s.components + k] * s.basis[k * f.image_size() + i]);
              } else {
                const LpcaModel& m = f.lpca();
                const int k = m.cluster_of[t];
                const std::size_t i = (std::size_t(v) * d.num_lights() + l) * 3 + ch, A = f.abrdf_size();
                mag = std::abs(m.means[k * A + i]);
                for (int j = 0; j < m.cluster_components[k]; ++j)
                  mag += 2 * std::abs(m.weights[t * m.components + j] * m.basis[(k * m.components + j) * A + i]);
              }
              const double diff = std::abs(double(dh.at(v, l, y, x, ch)) - df.at(v, l, y, x, ch));
              EXPECT_LE(diff, 1.1 * mag / 2048 + 1e-6);
              worst = std::max(worst, diff / mag);
            }
        }
    EXPECT_GT(worst, 0);  // the rounding did happen
    // The summary's error is the stored (rounded) codec's and stays close to the float one.
    EXPECT_NEAR(sh.relative_error, test::RelativeError(d, dh), 1e-6);
    EXPECT_LE(sh.relative_error, sf.relative_error + 1e-3);
    // File round trip: float16 on disk, the same values back.
    const auto path = test::TempDir() / "half.h5";
    WriteCodec(path, h);
    const Codec r = ReadCodec(path);
    EXPECT_EQ(r.storage(), CodecStorage::kHalf);
    EXPECT_EQ(r.DecodeAll().data(), dh.data());
    EXPECT_EQ(r.StoredBytes(), h.StoredBytes());
  }
  EXPECT_THROW(ParseStorage("bf16"), Error);
}

}  // namespace
}  // namespace btf
