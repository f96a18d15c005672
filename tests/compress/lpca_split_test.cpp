// LPCA's split/merge trials (CompressOptions::lpca_splits) on a case built so that k-means lands
// in a bad minimum for local PCA: k-means spends its clusters on the longest extent of the data,
// local PCA on what a subspace cannot capture.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"

namespace btf {
namespace {

// 20 x 20 texels, 2 views x 3 lights x RGB (18 values), on four affine lines (rank 1 each) plus
// Gaussian noise of 0.01: 200 texels on a long line (length 20, t uniform in [-10, 10]) far from
// three short ones (length 1, 200 texels between them) whose centres are 3 apart. The k-means
// objective prefers two centres on the long line and two for the three short lines (about 2100
// against 6700 for one centre on it); with k = 4, c = 1 local PCA is exact up to the noise with
// one cluster per line. truth: the known answer's relative error, that of the generating lines
// (the noise's energy over the data's).
Dataset FourLines(double& truth) {
  Dataset d(test::BonnSubset(2, 13), test::BonnSubset(3, 7), 20, 20, 3);
  const std::size_t A = d.abrdf_size();
  std::mt19937_64 rng(11);
  std::normal_distribution<double> gauss(0, 1);
  std::uniform_real_distribution<double> uni(-0.5, 0.5);
  auto unit = [&] {
    std::vector<double> u(A);
    double n = 0;
    for (double& x : u) x = gauss(rng), n += x * x;
    for (double& x : u) x /= std::sqrt(n);
    return u;
  };
  std::vector<std::vector<double>> centre(4, std::vector<double>(A, 5.0)), dir(4);
  const std::vector<double> apart = unit(), far = unit();
  for (std::size_t i = 0; i < A; ++i) {
    centre[0][i] += 20 * far[i];
    for (int g = 1; g < 4; ++g) centre[std::size_t(g)][i] += 3.0 * (g - 2) * apart[i];
  }
  for (auto& u : dir) u = unit();
  double noise = 0, energy = 0;
  std::vector<float> abrdf(A);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 20; ++x) {
      const int t = y * 20 + x, line = t < 200 ? 0 : 1 + (t - 200) % 3;
      const double along = (line == 0 ? 20.0 : 1.0) * uni(rng);
      for (std::size_t i = 0; i < A; ++i) {
        const double e = 0.01 * gauss(rng);
        abrdf[i] = float(centre[std::size_t(line)][i] + along * dir[std::size_t(line)][i] + e);
        noise += e * e;
        energy += double(abrdf[i]) * abrdf[i];
      }
      d.SetAbrdf(y, x, abrdf);
    }
  truth = std::sqrt(noise / energy);
  return d;
}

TEST(LpcaSplitMerge, LeavesTheKMeansMinimumForOneClusterPerLine) {
  double truth = 0;
  const Dataset d = FourLines(truth);
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = 4;
  o.components = 1;
  o.lpca.matrix = "float";
  for (std::uint64_t seed : {1, 2, 3}) {
    o.seed = seed;
    o.lpca.splits = 0;
    CompressSummary plain, split;
    test::CompressDataset(d, o, &plain);
    o.lpca.splits = CompressOptions().lpca.splits;
    test::CompressDataset(d, o, &split);
    std::printf("seed %d: truth %.6f, without split/merge %.6f, with %.6f (%zu trials)\n", int(seed), truth,
                plain.relative_error, split.relative_error, split.split_errors.size());
    EXPECT_TRUE(plain.split_errors.empty());
    // Measured (seeds 1, 2, 3): truth 0.001911; without split/merge 0.008645,
    // 0.007001, 0.008645 (3.7-4.5x the truth: a cluster holds two short lines); with it 0.001841
    // for each (0.96x: the fitted lines also take a little of the noise), after 2-3 trials. The
    // bounds: without above 3x the truth, with at most 1.1x it (10 % over the noise floor).
    EXPECT_GT(plain.relative_error, 3 * truth) << "seed " << seed << ": k-means did not land in the bad minimum";
    EXPECT_LE(split.relative_error, 1.1 * truth) << "seed " << seed;
    EXPECT_GE(split.split_errors.size(), 1u);
  }
}

}  // namespace
}  // namespace btf
