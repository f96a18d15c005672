// LPCA's sample rounds in the sample's principal subspace (CompressOptions::lpca.subspace): k-means
// and the local-PCA rounds on the sample's coordinates in a subspace, their models lifted back to
// the full dimension for the rounds over every texel.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

#include <fmt/format.h>

#include "libbtf/compress/compress.h"
#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"

namespace btf {
namespace {

CompressOptions Lpca(int k, int c, int subspace) {
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = k;
  o.components = c;
  o.lpca.matrix = "float";
  o.lpca.subspace = subspace;
  return o;
}

// 6 views x 6 lights x RGB = 108 values a texel, 24 x 24 texels of 3 materials, each its mean plus
// 2 texel-varying components: the data spans an affine subspace of at most 3 x 3 - 1 = 8
// dimensions, so a 16-dimensional sample subspace holds all of it and the lifted models are the
// ground truth's.
Dataset ThreeMaterials() { return test::ClusteredLowRank(test::BonnSubset(6), test::BonnSubset(6, 5), 24, 24, 3, 2); }

TEST(LpcaSubspace, RecoversTheGroundTruthLikeTheFullDimension) {
  const Dataset d = ThreeMaterials();
  for (int subspace : {0, 16}) {
    SCOPED_TRACE(subspace);
    CompressSummary s;
    const Codec c = test::CompressDataset(d, Lpca(3, 2, subspace), &s);
    // Exact model: float rounding only (relative 1e-5 is ~100 float epsilons of the 108-value
    // ABRDFs).
    EXPECT_LT(s.relative_error, 1e-5);
    // The subspace phase is timed where it runs (2 x 16 <= min(108 values, 576 texels)) only.
    EXPECT_EQ(s.times.ToJson().contains("subspace"), subspace > 0);
    // Texels of one material share one cluster.
    std::map<int, std::set<int>> clusters_of_material;
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 24; ++x) clusters_of_material[(x * 7 + y * 3) % 3].insert(c.lpca().cluster_of[y * 24 + x]);
    for (const auto& [m, ks] : clusters_of_material) EXPECT_EQ(ks.size(), 1u) << "material " << m;
  }
}

// Where the subspace holds only part of the data (8 dimensions; 3 materials of rank 6 plus noise
// span far more), the sample's errors are those of the full rows: they count the energy outside the
// subspace. The sample is every texel, and the first fit over every texel reassigns them under the
// lifted models of the sample's best fit, then refits each cluster in the full dimension: both
// steps can only lower that fit's error. An outside energy left uncounted would put the sample's
// error below the full fit's.
TEST(LpcaSubspace, SampleErrorsCountTheEnergyOutsideTheSubspace) {
  Dataset d = test::ClusteredLowRank(test::BonnSubset(6), test::BonnSubset(6, 5), 24, 24, 3, 6);
  std::mt19937_64 rng(3);
  std::normal_distribution<float> noise(0, 0.01f);
  for (float& x : d.data()) x += noise(rng);
  CompressSummary full, sub;
  test::CompressDataset(d, Lpca(3, 2, 0), &full);
  test::CompressDataset(d, Lpca(3, 2, 8), &sub);
  ASSERT_FALSE(sub.sample_errors.empty());
  ASSERT_FALSE(sub.iteration_errors.empty());
  double best = sub.sample_errors.front();
  for (double e : sub.sample_errors) best = std::min(best, e);
  for (double e : sub.split_errors) best = std::min(best, e);
  // Relative 1e-6: the float rounding of the fits.
  EXPECT_LE(sub.iteration_errors.front(), best * (1 + 1e-6));
  // The rounds over every texel reach the full-dimension path's error within 5 % (measured: the
  // same, 0.076320).
  EXPECT_LT(sub.relative_error, 1.05 * full.relative_error);
  RecordProperty("relative_errors", fmt::format("sample {} first fit {} final {} (full dimension {})", best,
                                                sub.iteration_errors.front(), sub.relative_error, full.relative_error));
}

// Texels that are all the same ABRDF leave the sample no centred energy, so no subspace: the
// sample rounds run in the full dimension and the codec is exact (float rounding).
TEST(LpcaSubspace, ConstantDataFallsBackToTheFullDimension) {
  Dataset d = ThreeMaterials();
  const std::vector<float> first = d.Abrdf(0, 0);
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 24; ++x) d.SetAbrdf(y, x, first);
  CompressSummary s;
  test::CompressDataset(d, Lpca(3, 2, 16), &s);
  EXPECT_FALSE(s.times.ToJson().contains("subspace"));
  EXPECT_LT(s.relative_error, 1e-6);
}

// The subspace's PCA runs single-threaded and its coordinates in fixed blocks: the codec is the
// same bits with one and two threads.
TEST(LpcaSubspace, CodecIsIndependentOfTheThreadCount) {
  Dataset d = test::ClusteredLowRank(test::BonnSubset(6), test::BonnSubset(6, 5), 24, 24, 4, 3);
  std::mt19937_64 rng(4);
  std::normal_distribution<float> noise(0, 0.02f);
  for (float& x : d.data()) x += noise(rng);
  const int threads = omp_get_max_threads();
  CompressOptions o = Lpca(4, 3, 8);
  o.lpca.matrix = "half";
  omp_set_num_threads(1);
  CompressSummary one, two;
  const Codec a = test::CompressDataset(d, o, &one);
  omp_set_num_threads(2);
  const Codec b = test::CompressDataset(d, o, &two);
  omp_set_num_threads(threads);
  test::ExpectSameCodec(a, b, "1 against 2 threads");
  EXPECT_EQ(one.sample_errors, two.sample_errors);
  EXPECT_EQ(one.relative_error, two.relative_error);
}

}  // namespace
}  // namespace btf
