// The benchmarks' synthetic BTF (not a material model): per view slot rank 12 in light plus 1 %
// noise, and 8 texel materials, so LPCA and per-view PCA have structure to find. Cheap to make
// (a hash per value), so a UBO2014-size input can be written slot by slot (bench/ubo2014_ooc.sh).
#pragma once

#include <cmath>
#include <cstdint>

#include "libbtf/core/directions.h"

namespace btf::bench {

// Deterministic cheap noise in [-1, 1).
inline float Hash(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  x ^= x >> 31;
  return float(double(x >> 11) * 0x1.0p-53 * 2 - 1);
}

// View slot v (lights x n x n x 3 floats, the dataset's slot layout) into out.
inline void SyntheticViewSlot(const Sampling& lights, int n, int v, float* out) {
  const int L = lights.size(), rank = 12, materials = 8;
  const std::size_t T = std::size_t(n) * n;
  for (int l = 0; l < L; ++l) {
    float* img = out + std::size_t(l) * T * 3;
    float a[rank];
    for (int r = 0; r < rank; ++r)
      a[r] = std::cos(float(r + 1) * float(lights[l].x() + 0.5 * lights[l].y()) + 0.1f * v) / float(r + 1);
    for (std::size_t t = 0; t < T; ++t) {
      const int m = int((t * 2654435761u) >> 7) % materials;
      for (int c = 0; c < 3; ++c) {
        float x = 1.0f + 0.2f * m + 0.1f * c;
        for (int r = 0; r < rank; ++r)
          x += 0.2f * a[r] * Hash((std::uint64_t(v) * 64 + r) * 1315423911u + m * 7 + c) * (1 + 0.3f * Hash(t * 977 + r));
        img[t * 3 + c] = x * (1 + 0.01f * Hash((std::uint64_t(v) * L + l) * T * 3 + t * 3 + c));
      }
    }
  }
}

}  // namespace btf::bench
