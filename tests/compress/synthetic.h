#pragma once
// Synthetic test BTFs with a known structure, so codec errors have a known answer.
#include <cmath>
#include <cstdint>
#include <random>

#include "libbtf/core/dataset.h"

namespace btf::test {

// Per view slot exactly `rank` light-varying components around a mean image, plus Gaussian
// noise of standard deviation `noise`. Values are around 0.5 .. 1.5 (positive).
inline Dataset PerViewLowRank(const Sampling& views, const Sampling& lights, int height, int width, int rank,
                              double noise, std::uint64_t seed = 3) {
  Dataset d(views, lights, height, width, 3);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(-1, 1);
  std::normal_distribution<double> gauss(0, 1);
  const std::size_t D = d.image_size();
  for (int v = 0; v < d.num_views(); ++v) {
    std::vector<double> mean(D), basis(D * rank);
    for (auto& m : mean) m = 1.0 + 0.3 * uni(rng);
    for (auto& b : basis) b = 0.1 * uni(rng);
    for (int l = 0; l < d.num_lights(); ++l) {
      const Vec3& wi = lights[l];
      float* img = d.image(v, l).data();
      for (std::size_t t = 0; t < D; ++t) {
        double x = mean[t];
        for (int r = 0; r < rank; ++r) x += std::cos((r + 1) * 2.0 * wi.x() + r * wi.y() + 0.3 * v) * basis[t * rank + r];
        img[t] = static_cast<float>(x + noise * gauss(rng));
      }
    }
  }
  return d;
}

// Texels of `materials` kinds; each kind's ABRDF is its mean plus `rank` texel-varying
// components. LPCA with k = materials and c = rank reproduces it exactly (up to float rounding).
inline Dataset ClusteredLowRank(const Sampling& views, const Sampling& lights, int height, int width, int materials,
                                int rank, std::uint64_t seed = 5) {
  Dataset d(views, lights, height, width, 3);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(-1, 1);
  const std::size_t A = d.abrdf_size();
  std::vector<std::vector<double>> mean(materials, std::vector<double>(A)), basis(materials, std::vector<double>(A * rank));
  for (int m = 0; m < materials; ++m) {
    for (auto& x : mean[m]) x = 1.0 + 0.5 * m + 0.2 * uni(rng);
    for (auto& x : basis[m]) x = 0.2 * uni(rng);
  }
  std::vector<float> abrdf(A);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const int m = (x * 7 + y * 3) % materials;
      std::vector<double> z(rank);
      for (auto& zz : z) zz = uni(rng);
      for (std::size_t i = 0; i < A; ++i) {
        double val = mean[m][i];
        for (int r = 0; r < rank; ++r) val += z[r] * basis[m][i * rank + r];
        abrdf[i] = static_cast<float>(val);
      }
      d.SetAbrdf(y, x, abrdf);
    }
  return d;
}

// Relative Frobenius error between two equally shaped datasets (double accumulation).
inline double RelativeError(const Dataset& ref, const Dataset& test) {
  double e = 0, n = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const double diff = double(test.data()[i]) - ref.data()[i];
    e += diff * diff;
    n += double(ref.data()[i]) * ref.data()[i];
  }
  return std::sqrt(e / n);
}

// A few directions of the Bonn sampling (keeps tests fast).
inline Sampling BonnSubset(int count, int stride = 1) {
  std::vector<int> idx;
  for (int i = 0; i < count; ++i) idx.push_back((i * stride) % 81);
  return Sampling::Bonn81().Subset(idx);
}

}  // namespace btf::test
