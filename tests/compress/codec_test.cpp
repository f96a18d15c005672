#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cmath>
#include <limits>
#include <map>
#include <set>

#include <omp.h>

#include "libbtf/compress/pca.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"
#include "tests/compress/synthetic.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

CompressOptions PcaView(int c) {
  CompressOptions o;
  o.method = CodecMethod::kPcaView;
  o.components = c;
  return o;
}
CompressOptions Lpca(int k, int c) {
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = k;
  o.components = c;
  return o;
}
// Exact recovery of low-rank data needs the float texel matrix: the default half matrix rounds
// the input by up to 2^-11 relative (lpca_ooc_test.cpp bounds that path).
CompressOptions LpcaFloat(int k, int c) {
  CompressOptions o = Lpca(k, c);
  o.lpca.matrix = "float";
  return o;
}

// --- PCA kernel -----------------------------------------------------------------------------

// A cluster-shaped matrix: `rows` members x 2000 values, a decaying spectrum (8 strong
// directions, s_k = 2^-k, over 1 % noise) around a mean of 1, drawn with `seed`.
RowMatrixXf ClusterShaped(Eigen::Index rows, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal(0, 1);
  RowMatrixXf U(rows, 8), V(8, 2000), N(rows, 2000);
  for (Eigen::Index i = 0; i < U.size(); ++i) U.data()[i] = normal(rng);
  for (Eigen::Index i = 0; i < V.size(); ++i) V.data()[i] = normal(rng) * std::ldexp(1.0f, -int(i / 2000));
  for (Eigen::Index i = 0; i < N.size(); ++i) N.data()[i] = 0.01f * normal(rng);
  RowMatrixXf X = U * V + N;
  X.array() += 1.0f;
  return X;
}

// ||X - mean - scores basis||^2 in double.
double ReconstructionError(const RowMatrixXf& X, const PcaResult& r) {
  const Eigen::MatrixXd rec = (r.scores * r.basis).cast<double>().rowwise() + r.mean.transpose().cast<double>();
  return (X.cast<double>() - rec).squaredNorm();
}

TEST(Pca, GramCovarianceRandomizedAndFullSvdAgreeOnLowRankData) {
  // 60 x 300 matrix of exact rank 5 around a mean: every path must capture all the energy.
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<float> uni(-1, 1);
  RowMatrixXf U(60, 5), V(5, 300);
  for (int i = 0; i < U.size(); ++i) U.data()[i] = uni(rng);
  for (int i = 0; i < V.size(); ++i) V.data()[i] = uni(rng);
  RowMatrixXf X = U * V;
  X.array() += 2.0f;
  PcaRequest q;
  q.max_components = 8;
  const PcaResult gram = Pca(X, q);  // n = 60 <= d: Gram of the rows
  const RowMatrixXf Xt = X.transpose();
  const PcaResult cov = Pca(Xt.topRows(300), q);  // n = 300 > d = 60: covariance
  q.gram_limit = 10;                               // force the randomized path (min side 60 > 10)
  const PcaResult rnd = Pca(X, q);
  const PcaResult svd = PcaFullSvd(X, 5);
  EXPECT_FALSE(gram.randomized);
  EXPECT_TRUE(rnd.randomized);
  // Rank 5: components 6..8 have ~0 eigenvalue and are dropped.
  EXPECT_EQ(gram.components(), 5);
  EXPECT_EQ(rnd.components(), 5);
  EXPECT_EQ(cov.components(), 5);
  EXPECT_EQ(gram.dropped_null, 3);
  // Float data: residual below 1e-9 of the energy (float rounding ~1e-14 per element squared).
  for (const PcaResult* r : {&gram, &rnd, &svd}) EXPECT_LT(r->residual_energy, 1e-9 * r->total_energy);
  for (int k = 0; k < 5; ++k) {
    EXPECT_NEAR(gram.eigenvalues[k], svd.eigenvalues[k], 1e-4 * svd.eigenvalues[0]);
    EXPECT_NEAR(rnd.eigenvalues[k], svd.eigenvalues[k], 1e-4 * svd.eigenvalues[0]);
  }
  // Orthonormal basis to float precision.
  const Eigen::MatrixXf g = gram.basis * gram.basis.transpose();
  EXPECT_LT((g - Eigen::MatrixXf::Identity(5, 5)).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(Pca, LpcaGramLimitTakesTheRandomizedPathForLargeClustersAndItLosesLittle) {
  // A cluster-shaped matrix (ClusterShaped: 300 members x 2000 values); c = 8. LPCA's default
  // gram_limit (256) takes the randomized path for it, the limit of before (1024) the Gram.
  const RowMatrixXf X = ClusterShaped(300, 3);
  PcaRequest q;
  q.max_components = 8;
  q.gram_limit = CompressOptions{}.lpca.gram_limit;
  const PcaResult rnd = Pca(X, q);
  q.gram_limit = 1024;
  const PcaResult gram = Pca(X, q);
  EXPECT_TRUE(rnd.randomized);
  EXPECT_FALSE(gram.randomized);
  ASSERT_EQ(rnd.components(), 8);
  ASSERT_EQ(gram.components(), 8);
  // The Gram path's fit is the optimum up to rounding, so the randomized one's is not better
  // (beyond 1e-6, rounding). The reconstruction's squared error in double (residual_energy
  // subtracts the captured energy, about 1e4 times the residual here, so its float rounding
  // moves it by ~1e-4 relative: measured 1.5e-4 below the Gram's with the blocked passes, 6.8e-5
  // above with whole-matrix products); measured -3.9e-8 with one pass per subspace iteration
  // bounded at 1e-3.
  const double excess = ReconstructionError(X, rnd) / ReconstructionError(X, gram) - 1;
  EXPECT_GT(excess, -1e-6);
  EXPECT_LT(excess, 1e-3);
}

TEST(Pca, WarmStartFromAPreviousFitLosesLittle) {
  // LPCA's refit (CompressOptions::lpca_warm_start): a cluster whose members changed starts from
  // its previous basis. The cluster-shaped matrix of the test above (300 x 2000, 8 strong
  // directions over 1 % noise); the previous members: 30 of the 300 rows swapped for other draws
  // of the same model.
  const RowMatrixXf all = ClusterShaped(330, 3);
  const RowMatrixXf X = all.topRows(300);
  RowMatrixXf prev = X;
  prev.topRows(30) = all.bottomRows(30);
  PcaRequest q;
  q.max_components = 8;
  q.gram_limit = 1024;
  const PcaResult gram = Pca(X, q);  // the optimum up to rounding
  PcaRequest lpca = q;
  lpca.gram_limit = PcaRequest{}.gram_limit;  // LPCA's default: randomized for 300 rows
  const PcaResult before = Pca(prev, lpca);
  ASSERT_TRUE(before.randomized);
  ASSERT_EQ(before.components(), 8);
  // The Gram path ignores a start; the randomized path (LPCA's default limit) takes it (3 passes).
  const PcaResult gram_started = Pca(X, q, &before.basis);
  EXPECT_FALSE(gram.randomized);
  EXPECT_EQ(gram_started.basis, gram.basis);
  const PcaResult warm = Pca(X, lpca, &before.basis);
  EXPECT_TRUE(warm.randomized);
  ASSERT_EQ(warm.components(), 8);
  // The reconstruction's squared error ||X - mean - scores basis||^2 in double (residual_energy
  // subtracts the captured energy, 1e4 times the residual here, so float rounding of the basis
  // moves it by ~1e-3 relative). From the previous basis and warm_oversampling (4) Gaussian
  // columns, one subspace iteration: measured 3.1e-8 above the Gram's (the optimum up to
  // rounding, so at rounding level); bounded at 1e-5 (300x margin, 100x below the cold randomized
  // path's bound above). With 10 columns (the former default) 2.4e-8: the 4 columns
  // lose 7e-9 against them, bounded at 1e-6.
  const double excess = ReconstructionError(X, warm) / ReconstructionError(X, gram) - 1;
  EXPECT_GT(excess, -1e-6);
  EXPECT_LT(excess, 1e-5);
  PcaRequest ten = lpca;
  ten.warm_oversampling = 10;
  const double excess10 = ReconstructionError(X, Pca(X, ten, &before.basis)) / ReconstructionError(X, gram) - 1;
  EXPECT_LT(excess - excess10, 1e-6);
  // Orthonormal to float precision.
  const Eigen::MatrixXf g = warm.basis * warm.basis.transpose();
  EXPECT_LT((g - Eigen::MatrixXf::Identity(8, 8)).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(Pca, RowsInBlocksGiveTheSameBytesAndHoldOneBlockOrOneTile) {
  // LPCA's call: a cluster's member rows gathered from the texel matrix as PcaRows. The same
  // cluster-shaped matrix (8 strong directions over 1 % noise, around a mean), 300 members taken
  // from every other row of a 600-row matrix; c = 8, LPCA's default gram_limit (randomized for
  // 300 rows, the Gram for 200).
  const RowMatrixXf big = ClusterShaped(600, 5);
  const Eigen::Index d = big.cols();
  PcaRequest q;
  q.max_components = 8;
  for (const Eigen::Index n : {300, 200}) {
    RowMatrixXf X(n, d);
    for (Eigen::Index i = 0; i < n; ++i) X.row(i) = big.row(2 * i);
    // Every request: rows in row order, one block after the other; tiles of columns in order.
    Eigen::Index largest = 0, requested = 0, next = 0, widest = 0, tiles = 0, next_col = 0;
    bool in_order = true;
    PcaRows rows{n, d,
                 [&](Eigen::Index first, Eigen::Index count, float* out) {
                   in_order = in_order && first == next;
                   next = first + count == n ? 0 : first + count;
                   largest = std::max(largest, count), requested += count;
                   for (Eigen::Index i = 0; i < count; ++i)
                     Eigen::Map<Eigen::RowVectorXf>(out + i * d, d) = big.row(2 * (first + i));
                 },
                 [&](Eigen::Index c0, Eigen::Index w, float* out, Eigen::Index stride) {
                   in_order = in_order && c0 == next_col;
                   next_col = c0 + w == d ? 0 : c0 + w;
                   widest = std::max(widest, w), ++tiles;
                   for (Eigen::Index i = 0; i < n; ++i)
                     Eigen::Map<Eigen::RowVectorXf>(out + i * stride, w) = big.row(2 * i).segment(c0, w);
                 }};
    for (const bool warm : {false, true})
      for (const bool columns : {true, false}) {
        const PcaResult cold = Pca(X, q);
        const RowMatrixXf* start = warm ? &cold.basis : nullptr;
        PcaRows given = rows;
        if (!columns) given.get_columns = nullptr;
        largest = requested = next = widest = tiles = next_col = 0;
        const PcaResult whole = Pca(X, q, start), blocks = Pca(given, q, start);
        EXPECT_EQ(blocks.randomized, n == 300);
        EXPECT_EQ(blocks.basis, whole.basis) << n << " rows, warm " << warm << ", columns " << columns;
        EXPECT_EQ(blocks.scores, whole.scores);
        EXPECT_EQ(blocks.mean, whole.mean);
        EXPECT_EQ(blocks.residual_energy, whole.residual_energy);
        EXPECT_TRUE(in_order);
        if (n == 300) {
          // At most one block at a time (read in runs of a few rows); the passes: the moments with
          // Z = Xc^T Xc Omega, one per subspace iteration (2 cold, 1 warm), the final Y = Xc V.
          EXPECT_LE(largest, kPcaBlockRows);
          EXPECT_EQ(requested, n * (warm ? 3 : 4));
          EXPECT_EQ(tiles, 0);
        } else if (columns) {
          // The Gram path by tiles: no row, each tile of kWideTile columns (the last shorter) once
          // per pass (the Gram, then the basis).
          EXPECT_EQ(requested, 0);
          EXPECT_LE(widest, kWideTile);
          EXPECT_EQ(tiles, 2 * ((d + kWideTile - 1) / kWideTile));
        } else {
          EXPECT_EQ(largest, n);  // the Gram path without tiles: all rows at once, once
          EXPECT_EQ(requested, n);
        }
      }
  }
}

TEST(Pca, RandomizedPathCentresExactlyWhenTheFirstBlockIsUnrepresentative) {
  // The randomized path's first pass shifts rows by the first block's mean, not the cluster's,
  // and corrects Z and the energies in double afterwards. Make that shift wrong on purpose: the
  // cluster-shaped matrix (300 x 2000, three blocks of kPcaBlockRows = 128) far from the origin
  // (mean 101 instead of 1) with its first block's rows moved by +1 (their mean 0.57 per value
  // away from the cluster's: n |mean - m0|^2 = 2.0e5, 0.22 of the centred energy 8.7e5).
  RowMatrixXf X = ClusterShaped(300, 3);
  X.array() += 100.0f;
  X.topRows(kPcaBlockRows).array() += 1.0f;
  PcaRequest q;
  q.max_components = 8;
  const PcaResult rnd = Pca(X, q);  // LPCA's default gram_limit (256): randomized
  q.gram_limit = 1024;
  const PcaResult gram = Pca(X, q);  // centres exactly, the optimum up to rounding
  ASSERT_TRUE(rnd.randomized);
  ASSERT_EQ(rnd.components(), 8);
  // The energies from the corrected sums against the Gram path's sums of the centred rows:
  // measured 6e-15 and 2e-15 relative; bounded at 1e-8 (double sums of float rows). Without the
  // correction the centred energy would be off by n |mean - m0|^2, 0.22 relative.
  EXPECT_NEAR(rnd.total_energy, gram.total_energy, 1e-8 * gram.total_energy);
  EXPECT_NEAR(rnd.centered_energy, gram.centered_energy, 1e-8 * gram.centered_energy);
  EXPECT_LE((rnd.mean - gram.mean).cwiseAbs().maxCoeff(), 1e-5f);  // measured 0 (the same floats)
  // The fit: the reconstruction's squared error in double against the Gram's, measured 2.2e-8
  // above; bounded at 1e-5 as the warm start's. (Without Z's correction the fit stays as good,
  // the last pass works on centred rows and the offset only takes one of the sketch's columns;
  // without the energies' correction the two checks above and the residual's below fail.)
  const double excess = ReconstructionError(X, rnd) / ReconstructionError(X, gram) - 1;
  EXPECT_GT(excess, -1e-6);
  EXPECT_LT(excess, 1e-5);
  // residual_energy (centred energy minus the scores' squared norms) against that error: the
  // captured energy is 1e4 times the residual, so float rounding of the scores (~1e-7) moves it
  // by up to ~1e-3 relative; measured 6.3e-5, bounded at 1e-3.
  EXPECT_NEAR(rnd.residual_energy, ReconstructionError(X, rnd), 1e-3 * rnd.residual_energy);
  const Eigen::MatrixXf g = rnd.basis * rnd.basis.transpose();
  EXPECT_LT((g - Eigen::MatrixXf::Identity(8, 8)).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(Pca, MomentsAreTheRowSumsInDouble) {
  // The mean and total energy of both paths against plain long-double sums: 13 x 1003 (Gram) and
  // 300 x 1003 (randomized: three blocks), so the rows are not a whole number of AddMoments' runs
  // of 8 and the columns not of its 4 lanes. The means against the float of the plain mean:
  // measured equal on the Gram path (the row-order double sum over n, rounded once) and within
  // 0.66 eps |mean| on the randomized one (m0 + s0 / n); bounded at eps |mean| (about 1 ulp). Total energy: measured 2.4e-15 relative on the
  // Gram path (double sums of float squares), bounded at 1e-13; 6.9e-11 on the randomized path
  // (from the sums of the rows shifted by the first block's mean), bounded at 1e-8 as in the test
  // above.
  for (const Eigen::Index n : {13, 300}) {
    RowMatrixXf X = ClusterShaped(n, 5).leftCols(1003);
    X.array() += 2.0f;
    PcaRequest q;
    q.max_components = 4;
    const PcaResult r = Pca(X, q);
    EXPECT_EQ(r.randomized, n == 300);
    long double total = 0;
    for (Eigen::Index j = 0; j < X.cols(); ++j) {
      long double sum = 0;
      for (Eigen::Index i = 0; i < n; ++i) sum += X(i, j), total += (long double)X(i, j) * X(i, j);
      const float mean = static_cast<float>(sum / n);
      EXPECT_NEAR(r.mean[j], mean, std::abs(mean) * std::numeric_limits<float>::epsilon()) << j;
    }
    EXPECT_NEAR(r.total_energy, double(total), (n == 13 ? 1e-13 : 1e-8) * double(total)) << n;
  }
}

TEST(Pca, ConstantDataHasNoComponents) {
  // 10 x 50 takes the Gram path, 300 x 2000 the randomized one (its energies from sums of rows
  // shifted by the first block's mean: exactly zero here).
  for (const Eigen::Index n : {10, 300}) {
    RowMatrixXf X = RowMatrixXf::Constant(n, n == 10 ? 50 : 2000, 0.25f);
    const PcaResult r = Pca(X, PcaRequest{});
    EXPECT_EQ(r.components(), 0);
    EXPECT_FLOAT_EQ(r.mean[7], 0.25f);
    EXPECT_EQ(r.centered_energy, 0.0);
    EXPECT_EQ(r.residual_energy, 0.0);
  }
}

TEST(Pca, TargetErrorPicksTheSmallestSufficientCount) {
  // Rows +-s_k e_k with s = 8, 4, 2, 1, 0.5 (zero mean): relative error with c components =
  // sqrt(sum_{k>c} s_k^2 / sum s_k^2): c = 1: 0.4993, c = 2: 0.24816, c = 3: 0.1211.
  RowMatrixXf X = RowMatrixXf::Zero(10, 20);
  const float s[5] = {8, 4, 2, 1, 0.5f};
  for (int k = 0; k < 5; ++k) X(2 * k, k) = s[k], X(2 * k + 1, k) = -s[k];
  PcaRequest q;
  q.max_components = 5;
  q.target_error = 0.15;
  EXPECT_EQ(Pca(X, q).components(), 3);
  q.target_error = 0.3;
  EXPECT_EQ(Pca(X, q).components(), 2);
  q.target_error = 0.2481;  // just below c = 2's error (0.24816)
  EXPECT_EQ(Pca(X, q).components(), 3);
  q.target_error = 0;
  q.retained_energy = 0.9;  // c = 2 retains 80/85.25 = 0.938
  EXPECT_EQ(Pca(X, q).components(), 2);
}

// --- per-view PCA ---------------------------------------------------------------------------

TEST(PcaView, ExactRankRecoversTheDataAndMoreComponentsNeverHurt) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(4), test::BonnSubset(30, 2), 8, 8, 4, 1e-4);
  double previous = 1e9;
  for (int c : {1, 2, 3, 4, 6}) {
    CompressSummary s;
    const Codec codec = test::CompressDataset(d, PcaView(c), &s);
    const double e = test::RelativeError(d, codec.DecodeAll());
    // The summary's error is the decoded error (same definition, double accumulation).
    EXPECT_NEAR(s.relative_error, e, 1e-6 * std::max(e, 1e-3));
    EXPECT_LE(e, previous * (1 + 1e-6)) << "c = " << c;
    previous = e;
    if (c >= 4) {
      // Rank 4 + noise 1e-4 on values ~1: the residual is the noise minus what 2 extra
      // components fit: <= 1e-4 relative.
      EXPECT_LT(e, 1e-4) << "c = " << c;
    }
  }
  CompressSummary s;
  test::CompressDataset(d, PcaView(1), &s);
  EXPECT_GT(s.relative_error, 1e-3);  // one component cannot hold a rank-4 slot
  EXPECT_GT(s.ratio_float32, 1.0);
  EXPECT_NEAR(s.ratio_float32, 2 * s.ratio_half, 1e-9);
  EXPECT_EQ(s.psnr_peak_definition, "max |input value|");
  EXPECT_NEAR(s.psnr_db, 20 * std::log10(s.psnr_peak / s.rmse), 1e-9);
}

TEST(PcaView, DecodersAgree) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(5), test::BonnSubset(20, 3), 6, 7, 3, 1e-3);
  const Codec codec = test::CompressDataset(d, PcaView(3));
  const Dataset all = codec.DecodeAll();
  std::vector<float> img(codec.image_size());
  codec.DecodeImage(2, 5, img.data());
  const auto ref = all.image(2, 5);
  for (std::size_t i = 0; i < img.size(); ++i) EXPECT_NEAR(img[i], ref[i], 1e-5);
  const auto abrdf = codec.DecodeAbrdf(3, 4);
  const auto want = all.Abrdf(3, 4);
  for (std::size_t i = 0; i < abrdf.size(); ++i) EXPECT_NEAR(abrdf[i], want[i], 1e-5);
  // Value() at a sampled (wi, wo) pair and a texel center reproduces the sample exactly (both filters).
  float out[3];
  const Vec2 uv((4 + 0.5) / 7, 1 - (3 + 0.5) / 6);
  for (UvFilter f : {UvFilter::kNearest, UvFilter::kBilinear}) {
    codec.Value(uv, codec.lights()[5], codec.views()[2], out, f);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(out[c], all.at(2, 5, 3, 4, c), 1e-5);
  }
}

TEST(PcaView, ValueInterpolatesBarycentricallyAndBilinearly) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(19), test::BonnSubset(19), 4, 4, 2, 0);
  const Codec codec = test::CompressDataset(d, PcaView(2));
  const Dataset all = codec.DecodeAll();
  const Vec3 wo = DirectionFromAngles(DegToRad(20), DegToRad(40)), wi = DirectionFromAngles(DegToRad(10), DegToRad(-70));
  const Interpolant iv = codec.views().Barycentric(wo), il = codec.lights().Barycentric(wi);
  // Halfway between texels x = 1 and 2 of row y = 2.
  const Vec2 uv(2.0 / 4, 1 - 2.5 / 4);
  float out[3];
  codec.Value(uv, wi, wo, out, UvFilter::kBilinear);
  for (int c = 0; c < 3; ++c) {
    double want = 0;
    for (int a = 0; a < iv.count; ++a)
      for (int b = 0; b < il.count; ++b)
        for (int x : {1, 2}) want += 0.5 * iv.weight[a] * il.weight[b] * all.at(iv.index[a], il.index[b], 2, x, c);
    EXPECT_NEAR(out[c], want, 1e-5);
  }
  // uv wraps: u + 1 gives the same value.
  float wrapped[3];
  codec.Value(uv + Vec2(1, -2), wi, wo, wrapped, UvFilter::kBilinear);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(wrapped[c], out[c], 1e-6);
}

TEST(PcaView, ComponentsAreClampedToLightsMinusOneWithAWarning) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(2), test::BonnSubset(5), 4, 4, 2, 1e-3);
  CompressSummary s;
  const Codec codec = test::CompressDataset(d, PcaView(16), &s);
  ASSERT_FALSE(s.warnings.empty());
  EXPECT_NE(s.warnings[0].find("clamped to 4"), std::string::npos);
  for (const auto& slot : codec.pca_view()) EXPECT_LE(slot.components, 4);
  // With all lights - 1 components the slot is reproduced to float rounding.
  EXPECT_LT(s.relative_error, 1e-6);
}

TEST(PcaView, ConstantAndRankDeficientData) {
  Dataset d(test::BonnSubset(3), test::BonnSubset(6), 4, 4, 3);
  std::fill(d.data().begin(), d.data().end(), 0.7f);
  CompressSummary s;
  const Codec codec = test::CompressDataset(d, PcaView(4), &s);
  for (const auto& slot : codec.pca_view()) EXPECT_EQ(slot.components, 0);
  EXPECT_EQ(s.relative_error, 0.0);
  EXPECT_TRUE(std::isinf(s.psnr_db));
  const Dataset back = codec.DecodeAll();
  EXPECT_EQ(back.data(), d.data());
}

TEST(PcaView, NonFiniteInputIsRefusedNamingTheItem) {
  Dataset d = test::PerViewLowRank(test::BonnSubset(2), test::BonnSubset(5), 4, 4, 2, 1e-3);
  d.at(1, 3, 2, 1, 0) = std::numeric_limits<float>::quiet_NaN();
  try {
    test::CompressDataset(d, PcaView(2));
    FAIL() << "NaN accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("view 1, light 3, texel (y 2, x 1)"), std::string::npos) << e.what();
  }
  // LPCA's half texel matrix finds NaN and Inf in its range check (no separate scan of the
  // slot), and must name them as the float matrix's finiteness check does, not as out of range.
  d.at(1, 3, 2, 1, 0) = std::numeric_limits<float>::infinity();
  for (const char* matrix : {"half", "float"}) {
    CompressOptions o = Lpca(2, 2);
    o.lpca.matrix = matrix;
    try {
      test::CompressDataset(d, o);
      ADD_FAILURE() << "Inf accepted, " << matrix;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput);
      const std::string what = e.what();
      EXPECT_NE(what.find("holds Inf at view 1, light 3, texel (y 2, x 1), channel 0: values must be finite"),
                std::string::npos) << matrix << ": " << what;
    }
  }
}

TEST(PcaView, LogTransformIsRecordedAndInverted) {
  // HDR: values spanning 1e-3 .. 1e3 (multiplicative structure, exactly rank 1 in the log domain).
  Dataset d(test::BonnSubset(2), test::BonnSubset(8), 4, 4, 3);
  for (int v = 0; v < 2; ++v)
    for (int l = 0; l < 8; ++l)
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x)
          for (int c = 0; c < 3; ++c)
            d.at(v, l, y, x, c) = float(std::pow(10.0, (l - 4) * 0.75) * (1 + 0.1 * x + 0.05 * y + 0.2 * c));
  CompressOptions o = PcaView(1);
  o.log_transform = true;
  o.log_epsilon = 1e-6;
  CompressSummary s;
  const Codec codec = test::CompressDataset(d, o, &s);
  EXPECT_EQ(codec.transform(), ValueTransform::kLog);
  // log(x + eps) is rank 1 up to eps / x <= 1e-3 relative: each value within 0.2 %.
  const Dataset back = codec.DecodeAll();
  for (std::size_t i = 0; i < d.size(); ++i) EXPECT_NEAR(back.data()[i], d.data()[i], 2e-3 * d.data()[i]);
  const auto path = test::TempDir() / "log.h5";
  WriteCodec(path, codec);
  const Codec r = ReadCodec(path);
  EXPECT_EQ(r.transform(), ValueTransform::kLog);
  EXPECT_DOUBLE_EQ(r.log_epsilon(), 1e-6);
  EXPECT_EQ(r.DecodeAll().data(), back.data());
  // Values at or below -epsilon cannot be log-transformed.
  d.at(0, 0, 0, 0, 0) = -1;
  EXPECT_THROW(test::CompressDataset(d, o), Error);
}

// --- local PCA ------------------------------------------------------------------------------

TEST(Lpca, RecoversClusteredLowRankDataDeterministically) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(6), test::BonnSubset(6, 5), 12, 12, 3, 2);
  CompressSummary s1, s2;
  const Codec a = test::CompressDataset(d, LpcaFloat(3, 2), &s1);
  const Codec b = test::CompressDataset(d, LpcaFloat(3, 2), &s2);
  EXPECT_EQ(a.lpca().cluster_of, b.lpca().cluster_of);
  EXPECT_EQ(a.lpca().weights, b.lpca().weights);
  // Exact model: float rounding only.
  EXPECT_LT(s1.relative_error, 1e-5) << nlohmann::json(s1.iteration_errors).dump();
  // Each iteration's error is recorded and the kept fit is the best one.
  ASSERT_FALSE(s1.iteration_errors.empty());
  EXPECT_LE(s1.iteration_errors.back(), s1.iteration_errors.front() + 1e-12);
  // Texels of one material share one cluster.
  std::map<int, std::set<int>> clusters_of_material;
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 12; ++x) clusters_of_material[(x * 7 + y * 3) % 3].insert(a.lpca().cluster_of[y * 12 + x]);
  for (const auto& [m, ks] : clusters_of_material) EXPECT_EQ(ks.size(), 1u) << "material " << m;
}

TEST(Lpca, DecodersAgreeAndValueMatchesSamples) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(5), test::BonnSubset(7, 3), 6, 5, 2, 2);
  const Codec codec = test::CompressDataset(d, Lpca(3, 1));
  const Dataset all = codec.DecodeAll();
  std::vector<float> img(codec.image_size());
  codec.DecodeImage(4, 6, img.data());
  const auto ref = all.image(4, 6);
  for (std::size_t i = 0; i < img.size(); ++i) EXPECT_NEAR(img[i], ref[i], 1e-5);
  const auto abrdf = codec.DecodeAbrdf(5, 4);
  const auto want = all.Abrdf(5, 4);
  for (std::size_t i = 0; i < abrdf.size(); ++i) EXPECT_NEAR(abrdf[i], want[i], 1e-5);
  float out[3];
  codec.Value(Vec2((4 + 0.5) / 5, 1 - (5 + 0.5) / 6), codec.lights()[6], codec.views()[4], out, UvFilter::kNearest);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(out[c], all.at(4, 6, 5, 4, c), 1e-5);
}

TEST(Lpca, MoreClustersThanTexelsAreClampedAndEmptyClustersReseeded) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(3), test::BonnSubset(4), 2, 3, 2, 1);
  CompressSummary s;
  const Codec codec = test::CompressDataset(d, LpcaFloat(10, 2), &s);
  EXPECT_EQ(codec.lpca().clusters, 6);
  bool warned = false;
  for (const auto& w : s.warnings) warned |= w.find("clamped to the number of texels 6") != std::string::npos;
  EXPECT_TRUE(warned);
  // One texel per cluster: every cluster is non-empty and the data is reproduced exactly.
  std::set<int> used(codec.lpca().cluster_of.begin(), codec.lpca().cluster_of.end());
  EXPECT_EQ(used.size(), 6u);
  EXPECT_LT(s.relative_error, 1e-6);
}

TEST(Lpca, DuplicateTexelsLeaveNoClusterEmpty) {
  // 16 texels with only 2 distinct ABRDFs and k = 4: seeding picks duplicate centers, and the
  // empty clusters are re-seeded from other texels.
  Dataset d(test::BonnSubset(2), test::BonnSubset(3), 4, 4, 3);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x)
      for (int v = 0; v < 2; ++v)
        for (int l = 0; l < 3; ++l)
          for (int c = 0; c < 3; ++c) d.at(v, l, y, x, c) = (x < 2 ? 1.0f : 2.0f) + 0.1f * (v + l + c);
  CompressSummary s;
  const Codec codec = test::CompressDataset(d, LpcaFloat(4, 1), &s);
  std::set<int> used(codec.lpca().cluster_of.begin(), codec.lpca().cluster_of.end());
  EXPECT_EQ(used.size(), 4u);
  EXPECT_LT(s.relative_error, 1e-6);
}

// --- files ----------------------------------------------------------------------------------

TEST(CodecFile, RoundTripIsExactForBothMethods) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(4), test::BonnSubset(5, 2), 5, 6, 2, 2);
  for (const CompressOptions& o : {PcaView(3), Lpca(2, 2)}) {
    const auto path = test::TempDir() / "c.h5";
    const Codec codec = test::CompressDataset(d, o);
    WriteCodec(path, codec);
    const Codec r = ReadCodec(path);
    EXPECT_EQ(r.method(), o.method);
    EXPECT_EQ(r.StoredBytes(), codec.StoredBytes());
    EXPECT_EQ(r.views().name(), codec.views().name());
    EXPECT_EQ(r.DecodeAll().data(), codec.DecodeAll().data());
    EXPECT_EQ(r.provenance()["options"]["method"], MethodName(o.method));
    // decode -> dataset file round trip.
    const auto out = test::TempDir() / "decoded.h5";
    DecodeToDatasetFile(r, out);
    EXPECT_EQ(ReadDataset(out).data(), codec.DecodeAll().data());
  }
}

// CompressToFile writes per-view PCA slot by slot while it decomposes (the others compress, then
// write): the file must read back as Compress + WriteCodec's, for both storages and thread counts,
// and a run cancelled half way must leave neither the output nor its temporary behind.
TEST(CodecFile, CompressToFileEqualsCompressThenWriteAndACancelLeavesNothing) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(9), test::BonnSubset(6, 2), 6, 5, 2, 2);
  const auto dir = test::TempDir();
  const int threads = omp_get_max_threads();
  CompressOptions half = PcaView(3);
  half.storage = CodecStorage::kHalf;
  for (const CompressOptions& o : {PcaView(3), half, Lpca(2, 2)}) {
    CompressSummary want;
    const Codec ref = test::CompressDataset(d, o, &want);
    WriteCodec(dir / "ref.h5", ref);
    for (int t : {1, 2}) {
      omp_set_num_threads(t);
      AtomicOutput out(dir / "streamed.h5");
      const CompressSummary got = CompressToFile(o, *MemorySource(d), &out, "test");
      omp_set_num_threads(threads);
      const std::string what = fmt::format("{} {} {} threads", MethodName(o.method), StorageName(o.storage), t);
      EXPECT_EQ(got.codec_bytes, want.codec_bytes) << what;
      EXPECT_EQ(got.relative_error, want.relative_error) << what;
      const Codec a = ReadCodec(dir / "streamed.h5"), b = ReadCodec(dir / "ref.h5");
      test::ExpectSameCodec(a, b, what);
      EXPECT_EQ(a.StoredBytes(), got.codec_bytes) << what;
      EXPECT_EQ(a.provenance()["summary"]["relative_error"], b.provenance()["summary"]["relative_error"]) << what;
      EXPECT_TRUE(got.times.ToJson().contains("write")) << what;
    }
  }
  // Cancelled after the second of nine slots, with the first already in the temporary file (one
  // thread: with two, the caller's thread, which reports progress, may get fewer slots).
  std::size_t calls = 0;
  const Reporter stop_early({}, [&](std::size_t, std::size_t, std::string_view) { return ++calls < 2; });
  omp_set_num_threads(1);
  {
    AtomicOutput out(dir / "cancelled.h5");
    EXPECT_THROW(CompressToFile(PcaView(3), *MemorySource(d), &out, "test", stop_early), Cancelled);
  }
  omp_set_num_threads(threads);
  for (const auto& e : std::filesystem::directory_iterator(dir))
    EXPECT_TRUE(e.path().filename() == "ref.h5" || e.path().filename() == "streamed.h5") << e.path();
}

void SetStringAttr(const std::filesystem::path& path, const char* name, const std::string& value) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  H5Adelete(f, name);
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, value.size());
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t a = H5Acreate2(f, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(a, type, value.c_str());
  H5Aclose(a);
  H5Sclose(space);
  H5Tclose(type);
  H5Fclose(f);
}

TEST(CodecFile, RefusesNewerMajorMissingItemsAndDatasets) {
  const Dataset d = test::ClusteredLowRank(test::BonnSubset(3), test::BonnSubset(4), 4, 4, 2, 1);
  const auto dir = test::TempDir();
  const Codec codec = test::CompressDataset(d, Lpca(2, 1));
  WriteCodec(dir / "new.h5", codec);
  SetStringAttr(dir / "new.h5", "format_version", "2.0.0");
  try {
    ReadCodec(dir / "new.h5");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("newer"), std::string::npos) << e.what();
  }
  WriteCodec(dir / "missing.h5", codec);
  {
    const hid_t f = H5Fopen((dir / "missing.h5").c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    H5Ldelete(f, "/codec/lpca/weights", H5P_DEFAULT);
    H5Fclose(f);
  }
  try {
    ReadCodec(dir / "missing.h5");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("/codec/lpca/weights"), std::string::npos) << e.what();
  }
  WriteDataset(dir / "dataset.h5", d);
  try {
    ReadCodec(dir / "dataset.h5");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
  }
}

TEST(CodecFile, CompressFileStreamsTheSameResultAsInMemory) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(9), 5, 5, 2, 1e-3);
  const auto path = test::TempDir() / "d.h5";
  WriteDataset(path, d);
  CompressSummary s;
  const Codec a = test::CompressPath(path, PcaView(2), &s), b = test::CompressDataset(d, PcaView(2));
  EXPECT_EQ(a.DecodeAll().data(), b.DecodeAll().data());
  EXPECT_EQ(s.input, path.string());
}

// --- scene ----------------------------------------------------------------------------------

TEST(Scene, KeepsOnlyNeededDirectionsMipAndChannels) {
  const Dataset d = test::PerViewLowRank(Sampling::Bonn81(), test::BonnSubset(19), 8, 8, 3, 1e-4);
  SceneSpec scene = SceneSpec::FromJson(nlohmann::json::parse(R"({
      "views": [{"theta_deg": 30, "phi_deg": 0, "cone_deg": 5}],
      "lights": "all", "mip_level": 1, "channels": ["G"]})"),
                                        "test");
  CompressOptions o = PcaView(3);
  o.scene = scene;
  CompressSummary s;
  const Codec codec = test::CompressDataset(d, o, &s);
  EXPECT_TRUE(s.scene_used);
  // A 5-degree cone around a sampled direction touches it and its neighbors only.
  EXPECT_LT(codec.num_views(), 12);
  EXPECT_GE(codec.num_views(), 3);
  EXPECT_EQ(codec.num_lights(), 19);
  EXPECT_EQ(codec.height(), 4);
  EXPECT_EQ(codec.channels(), 1);
  EXPECT_EQ(codec.info().channel_names, std::vector<std::string>{"G"});
  EXPECT_GT(s.bytes_saved, 0u);
  EXPECT_EQ(s.full_codec_bytes - s.bytes_saved, s.codec_bytes);
  // The scene direction decodes to the box-filtered green of the full data (mip 1 = 2x2 mean).
  const Vec3 wo = DirectionFromAngles(DegToRad(30), 0);
  const int v = Sampling::Bonn81().Nearest(wo);
  float out[1];
  codec.Value(Vec2(0.5 / 4, 1 - 0.5 / 4), d.lights()[2], wo, out, UvFilter::kNearest);
  const double want = 0.25 * (d.at(v, 2, 0, 0, 1) + d.at(v, 2, 0, 1, 1) + d.at(v, 2, 1, 0, 1) + d.at(v, 2, 1, 1, 1));
  EXPECT_NEAR(out[0], want, 1e-3);  // rank 3 + noise 1e-4, averaged: well within 1e-3
}

TEST(Scene, BadSceneFilesAreRefused) {
  EXPECT_THROW(SceneSpec::FromJson(nlohmann::json::parse(R"({"views": [{"theta_deg": 95}]})"), "s"), Error);
  EXPECT_THROW(SceneSpec::FromJson(nlohmann::json::parse(R"({"colour": 1})"), "s"), Error);
  const Dataset d = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(4), 4, 4, 1, 0);
  CompressOptions o = PcaView(1);
  o.scene = SceneSpec::FromJson(nlohmann::json::parse(R"({"channels": ["X"]})"), "s");
  try {
    test::CompressDataset(d, o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("'X'"), std::string::npos);
  }
}

TEST(Options, CheckRejectsBadValues) {
  CompressOptions o;
  o.components = 0;
  EXPECT_THROW(o.Check(), Error);
  o = CompressOptions{};
  o.target_error = 0.1;
  o.retained_energy = 0.9;
  EXPECT_THROW(o.Check(), Error);
  o = CompressOptions{};
  o.lpca.splits = -1;
  EXPECT_THROW(o.Check(), Error);
  EXPECT_THROW(ParseMethod("jpeg"), Error);
}

// --error with the component cap winning: every method says so (a warning naming the cap) instead
// of returning the capped codec silently; met targets warn nothing.
TEST(Targets, AMissedErrorTargetIsWarnedNamingTheLimit) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(4), test::BonnSubset(5), 12, 12, 4, 0.05);
  for (const CodecMethod m : {CodecMethod::kPcaView, CodecMethod::kLpca, CodecMethod::kFmf, CodecMethod::kDfmf}) {
    SCOPED_TRACE(MethodName(m));
    CompressOptions o;
    o.method = m;
    o.clusters = 2;
    o.components = 1;
    o.target_error = 0.001;  // far below what one component reaches on rank-4 data with 5 % noise
    CompressSummary s;
    test::CompressDataset(d, o, &s);
    ASSERT_GT(s.relative_error, o.target_error);
    ASSERT_EQ(s.warnings.size(), 1u);
    for (const std::string part : {std::string("above --error 0.001"), std::string("-c 1"), std::string("raise -c")})
      EXPECT_NE(s.warnings[0].find(part), std::string::npos) << s.warnings[0];
    o.components = 4;       // pca-view's most here (lights - 1): no clamping warning
    o.target_error = 0.5;  // met: no warning
    test::CompressDataset(d, o, &s);
    EXPECT_LE(s.relative_error, 0.5);
    EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
  }
}

}  // namespace
}  // namespace btf
