#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include <Eigen/LU>

#include "libbtf/core/error.h"
#include "libbtf/register/lattice.h"

namespace btf {
namespace {

// Periodic test pattern on lattice (a1, a2): harmonics m k1 + n k2 (|m|, |n| <= 2) with fixed
// phases and 1/(1 + m^2 + n^2) amplitudes, plus an illumination gradient and Gaussian noise.
Image PeriodicImage(int n, const Vec2& a1, const Vec2& a2, double noise, unsigned seed) {
  Eigen::Matrix2d A;
  A << a1, a2;
  const Eigen::Matrix2d K = A.inverse().transpose();
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, noise);
  Image im(n, n, 1);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      double v = 1 + 0.002 * x;
      for (int m = -2; m <= 2; ++m)
        for (int q = 0; q <= 2; ++q) {
          if (q == 0 && m <= 0) continue;
          const Vec2 k = m * K.col(0) + q * K.col(1);
          v += 0.3 / (1 + m * m + q * q) * std::cos(2 * kPi * k.dot(Vec2(x, y)) + 0.7 * m + 1.3 * q);
        }
      im.at(x, y, 0) = static_cast<float>(v + (noise > 0 ? g(rng) : 0));
    }
  return im;
}

TEST(Lattice, RecoversAnObliqueLatticeToFiveThousandthsOfATexel) {
  // 256^2, about 20 x 16 periods, noise 0.05 against harmonics of 0.3..0.03. Notes 6.3 measure
  // 0.008 px at 512^2 with FFT bins + harmonics; our DTFT peak refinement does better. Bound 0.005
  // texel per vector: 0.1 texel of drift over 20 periods, negligible blur when averaging.
  const Vec2 a1(12.37, 0.41), a2(-0.23, 15.81);
  const Image im = PeriodicImage(256, a1, a2, 0.05, 1);
  const Lattice L = EstimateLattice(im.pixels, 256, 256);
  std::printf("lattice vector errors %.5f %.5f texels\n", (L.a1 - a1).norm(), (L.a2 - a2).norm());  // docs
  EXPECT_LT((L.a1 - a1).norm(), 0.005) << L.ToJson().dump();
  EXPECT_LT((L.a2 - a2).norm(), 0.005) << L.ToJson().dump();
  EXPECT_EQ(L.yarn_cells_per_repeat, 1);
  EXPECT_GE(L.peaks_used, 4);
  EXPECT_NEAR(L.k1.dot(L.a1), 1, 1e-12);
  EXPECT_NEAR(L.k1.dot(L.a2), 0, 1e-12);
}

// 3-yarn twill-like pattern: strong yarn periods p along x and y, a weak diagonal at 1/3 of the
// yarn frequency. The repeat is the twill's, 3 yarn cells, not the yarn spacing.
double Twill(double x, double y, double p) {
  return 1 + 0.4 * std::cos(2 * kPi * x / p) + 0.4 * std::cos(2 * kPi * y / p) +
         0.12 * std::cos(2 * kPi * (x - y) / (3 * p) + 0.4);
}

TEST(Lattice, FindsTheTwillRepeatNotTheYarnSpacing) {
  const double p = 8.3;
  const int n = 256;
  Image im(n, n, 1);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) im.at(x, y, 0) = static_cast<float>(Twill(x, y, p));
  const Lattice L = EstimateLattice(im.pixels, n, n);
  EXPECT_EQ(L.yarn_cells_per_repeat, 3) << L.ToJson().dump();
  // Same lattice as the truth basis p(1, 1), p(1, -2): integer change of basis with |det| = 1.
  Eigen::Matrix2d T, E;
  T << Vec2(p, p), Vec2(p, -2 * p);
  E << L.a1, L.a2;
  const Eigen::Matrix2d M = T.inverse() * E;
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(M.data()[i], std::round(M.data()[i]), 0.01) << M;
  EXPECT_NEAR(std::abs(M.determinant()), 1, 0.02);

  // Averaging on the repeat keeps the diagonal; averaging on the yarn lattice would erase it.
  const AveragedTile tile = AverageTiles(im, L);
  const Image retiled = TileImage(tile, L, n, n);
  Lattice yarn = L;
  yarn.a1 = Vec2(p, 0);
  yarn.a2 = Vec2(0, p);
  const Image wrong = TileImage(AverageTiles(im, yarn), yarn, n, n);
  double e_ok = 0, e_wrong = 0;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      e_ok += std::pow(retiled.at(x, y, 0) - Twill(x, y, p), 2);
      e_wrong += std::pow(wrong.at(x, y, 0) - Twill(x, y, p), 2);
    }
  e_ok = std::sqrt(e_ok / (n * n));
  e_wrong = std::sqrt(e_wrong / (n * n));
  std::printf("twill re-tiling RMS %.4f on the repeat, %.4f on the yarn spacing\n", e_ok, e_wrong);  // docs
  // The erased diagonal has RMS 0.12/sqrt(2) = 0.085. Two bicubic resamplings on the right lattice
  // cost 0.0016 (measured); bound 0.005.
  EXPECT_LT(e_ok, 0.005);
  EXPECT_GT(e_wrong, 0.07);
}

TEST(Lattice, TrimmedTileAverageSuppressesNoiseAndOutlierTiles) {
  const Vec2 a1(10.6, 0), a2(0, 12.2);
  const int n = 200;
  const Image clean = PeriodicImage(n, a1, a2, 0, 0);
  Image noisy = PeriodicImage(n, a1, a2, 0.1, 7);
  for (int y = 40; y < 70; ++y)
    for (int x = 40; x < 75; ++x) noisy.at(x, y, 0) += 3;  // a stain over about 3 x 3 tiles
  Lattice L;
  L.a1 = a1;
  L.a2 = a2;
  TileAverageOptions trimmed, mean;
  mean.trim_fraction = 0;
  const AveragedTile t1 = AverageTiles(noisy, L, trimmed);
  const AveragedTile t0 = AverageTiles(noisy, L, mean);
  // Complete tiles from origin (-0.5, -0.5) within [0, 199]^2: i = 1..17 along a1, j = 1..15 along a2.
  EXPECT_EQ(t1.tiles_used, 17 * 15);
  const Image r1 = TileImage(t1, L, n, n), r0 = TileImage(t0, L, n, n);
  // The mean also lacks the illumination gradient 0.002 x: compare against the clean tile
  // re-tiled the same way, so only noise and outliers count.
  const Image ref = TileImage(AverageTiles(clean, L, mean), L, n, n);
  double e1 = 0, e0 = 0;
  for (std::size_t i = 0; i < ref.pixels.size(); ++i) {
    e1 += std::pow(r1.pixels[i] - ref.pixels[i], 2);
    e0 += std::pow(r0.pixels[i] - ref.pixels[i], 2);
  }
  e1 = std::sqrt(e1 / ref.pixels.size());
  e0 = std::sqrt(e0 / ref.pixels.size());
  // Noise 0.1 / sqrt(~150 kept tiles) = 0.008; the stain (3 x ~9 tiles of 255) biases the plain mean by ~0.1.
  EXPECT_LT(e1, 0.015);
  EXPECT_GT(e0, 3 * e1);
}

TEST(Lattice, MaskedTexelsAreLeftOutOfTheTileAverage) {
  // A clean periodic image with a strip of "marker print" (value 5) along one edge, as a raised
  // marker hides at grazing views. Masked, the strip leaves the plain mean (no trimming) equal to
  // the clean image's average up to float rounding; unmasked, it biases every sample it covers.
  const Vec2 a1(10.6, 0), a2(0, 12.2);
  const int n = 200;
  const Image clean = PeriodicImage(n, a1, a2, 0, 0);
  Image stained = clean;
  std::vector<std::uint8_t> mask(std::size_t(n) * n, 0);
  for (int y = n - 12; y < n; ++y)
    for (int x = 0; x < n; ++x) stained.at(x, y, 0) = 5, mask[std::size_t(y) * n + x] = 1;
  Lattice L;
  L.a1 = a1;
  L.a2 = a2;
  TileAverageOptions mean;
  mean.trim_fraction = 0;
  const AveragedTile ref = AverageTiles(clean, L, mean);
  // Leaving samples out changes which tiles enter each sample's mean: the clean image's tiles
  // differ by its illumination gradient (0.002 per texel), so compare against the clean average
  // over the same tiles, i.e. the clean image with the same mask.
  const AveragedTile ref_masked = AverageTiles(clean, L, mean, &mask);
  const AveragedTile with = AverageTiles(stained, L, mean, &mask), without = AverageTiles(stained, L, mean);
  EXPECT_EQ(with.samples_without_valid_tile, 0);
  double e_with = 0, e_without = 0;
  for (std::size_t i = 0; i < ref.tile.pixels.size(); ++i) {
    e_with = std::max<double>(e_with, std::abs(with.tile.pixels[i] - ref_masked.tile.pixels[i]));
    e_without = std::max<double>(e_without, std::abs(without.tile.pixels[i] - ref.tile.pixels[i]));
  }
  EXPECT_EQ(e_with, 0.0);       // the same samples, summed in the same order
  EXPECT_GT(e_without, 0.1);    // the strip (1 of ~15 tile rows) shifts the mean by about 5/15
  // A mask over everything: each sample falls back to all tiles (counted), as without a mask.
  std::vector<std::uint8_t> all(mask.size(), 1);
  const AveragedTile fallback = AverageTiles(stained, L, mean, &all);
  EXPECT_EQ(fallback.samples_without_valid_tile, fallback.tile.width * fallback.tile.height);
  EXPECT_EQ(fallback.tile.pixels, without.tile.pixels);
}

TEST(Lattice, NonPeriodicAndStripedImagesAreRejected) {
  const int n = 128;
  std::mt19937 rng(3);
  std::normal_distribution<float> g(0, 1);
  Image noise(n, n, 1), stripes(n, n, 1);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      noise.at(x, y, 0) = g(rng);
      stripes.at(x, y, 0) = static_cast<float>(std::cos(2 * kPi * x / 9.0));
    }
  EXPECT_THROW(EstimateLattice(noise.pixels, n, n), Error);
  EXPECT_THROW(EstimateLattice(stripes.pixels, n, n), Error);
  Lattice L;
  L.a1 = Vec2(100, 0);
  L.a2 = Vec2(0, 100);
  EXPECT_THROW(AverageTiles(noise, L), Error);  // a 128^2 image holds one 100^2 tile: refused
}

}  // namespace
}  // namespace btf
