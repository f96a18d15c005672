#pragma once
// Counter-based hashing for reproducible pseudo-random values: the splitmix64 finalizer (Steele,
// Lea & Flood 2014), so a value depends only on its integer keys, never on evaluation order or
// thread count.
#include <cstdint>

namespace btf {

// The splitmix64 output function: a bijective 64-bit mix with full avalanche.
constexpr std::uint64_t MixBits(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Uniform in [0, 1) from a seed and two keys (53 random bits).
constexpr double HashUniform(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0) {
  std::uint64_t z = seed * 0x9E3779B97F4A7C15ull ^ (a + 0x632BE59BD9B4E019ull) * 0xBF58476D1CE4E5B9ull;
  z ^= (b + 0x94D049BB133111EBull) * 0xD6E8FEB86659FD93ull;
  return static_cast<double>(MixBits(z) >> 11) * 0x1.0p-53;
}

}  // namespace btf
