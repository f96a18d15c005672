// Synthetic latent-dependent lobes for the neural codec's tests and benchmark: per texel a
// diffuse colour, a specular strength, a roughness and a tilted normal (7 numbers, hashed from
// the texel index), f_c = kd_c + ks exp(-(1 - h.n) / alpha^2) (h: the half vector), target
// log(f_c + 1e-3). Smooth in the directions, so a small decoder with an 8-value latent fits it.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

#include "libbtf/compress/neural_net.h"

namespace btf::test {

inline double LobeHash(std::uint64_t x) {  // [0, 1)
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  x ^= x >> 31;
  return double(x >> 11) * 0x1.0p-53;
}

// A unit direction in the upper hemisphere, z >= z_min, from two hashes.
inline void LobeDirection(std::uint64_t key, double z_min, float* w) {
  const double z = z_min + (1 - z_min) * LobeHash(key), phi = 2 * std::numbers::pi * LobeHash(key ^ 0x5555);
  const double r = std::sqrt(std::max(0.0, 1 - z * z));
  w[0] = float(r * std::cos(phi));
  w[1] = float(r * std::sin(phi));
  w[2] = float(z);
}

// The log-domain value of channel c at texel t for (wi, wo).
inline double LobeValue(std::int64_t t, int c, const float* wi, const float* wo) {
  const auto p = [&](int k) { return LobeHash(std::uint64_t(t) * 16 + k); };
  const double kd = 0.02 + 0.38 * p(c), ks = 0.1 + 2.9 * p(3), alpha = 0.15 + 0.35 * p(4);
  double n[3] = {0.5 * (p(5) - 0.5), 0.5 * (p(6) - 0.5), 1};
  double h[3] = {double(wi[0]) + wo[0], double(wi[1]) + wo[1], double(wi[2]) + wo[2]};
  const double nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  const double hn = std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
  const double cosine = hn > 0 ? (h[0] * n[0] + h[1] * n[1] + h[2] * n[2]) / (hn * nn) : 0;
  return std::log(kd + ks * std::exp(-(1 - cosine) / (alpha * alpha)) + 1e-3);
}

// per_texel samples for each of `texels` texels, directions from `stream` (another stream: held-out
// directions for the same texels).
inline NeuralSamples LobeSamples(std::int64_t texels, int per_texel, std::uint64_t stream, double z_min = 0.02) {
  NeuralSamples s;
  s.texels = texels;
  s.channels = 3;
  const std::int64_t n = texels * per_texel;
  s.texel.resize(n);
  s.wi.resize(3 * n);
  s.wo.resize(3 * n);
  s.target.resize(3 * n);
  for (std::int64_t i = 0; i < n; ++i) {
    s.texel[i] = std::int32_t(i % texels);
    const std::uint64_t key = (stream << 40) ^ std::uint64_t(i) * 2654435761u;
    LobeDirection(key * 2 + 1, z_min, &s.wi[3 * i]);
    LobeDirection(key * 2 + 2, z_min, &s.wo[3 * i]);
    for (int c = 0; c < 3; ++c) s.target[3 * i + c] = float(LobeValue(s.texel[i], c, &s.wi[3 * i], &s.wo[3 * i]));
  }
  return s;
}

// Root mean square of (model - target) over all of s's values, log domain.
inline double LobeRmse(const NeuralModel& m, const NeuralSamples& s) {
  Eigen::MatrixXf out;
  m.Evaluate(s.texel.data(), s.wi.data(), s.wo.data(), s.size(), &out);
  double sum = 0;
  for (std::int64_t i = 0; i < s.size(); ++i)
    for (int c = 0; c < s.channels; ++c) {
      const double r = double(out(c, i)) - s.target[std::size_t(i) * s.channels + c];
      sum += r * r;
    }
  return std::sqrt(sum / double(s.target.size()));
}

// Root mean square of the targets about their mean (what a constant predictor leaves).
inline double LobeSpread(const NeuralSamples& s) {
  double mean = 0, sq = 0;
  for (const float v : s.target) mean += v;
  mean /= double(s.target.size());
  for (const float v : s.target) sq += (v - mean) * (v - mean);
  return std::sqrt(sq / double(s.target.size()));
}

}  // namespace btf::test
