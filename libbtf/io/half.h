#pragma once
// IEEE 754 binary16 ("half") <-> float32, bit exact and independent of the compiler's _Float16.
// The one conversion of libbtf: float16 dataset storage, the BDI writer, half codec rows and the
// renderer exports' HALF_FLOAT textures (header-only: the installed export reference decoders use it).
// FloatToHalf rounds to nearest, ties to even; values beyond the half range become +-infinity,
// NaN stays NaN (quiet, sign kept, payload dropped). HalfToFloat is exact (a NaN keeps sign and payload).
#include <bit>
#include <cstddef>
#include <cstdint>
#ifdef __F16C__
#include <immintrin.h>
#endif

namespace btf {

inline float HalfToFloat(std::uint16_t h) {
  const std::uint32_t sign = std::uint32_t(h & 0x8000u) << 16;
  const std::uint32_t exponent = (h >> 10) & 0x1fu;
  std::uint32_t mantissa = h & 0x3ffu;
  std::uint32_t bits;
  if (exponent == 0x1f) {
    bits = sign | 0x7f800000u | (mantissa << 13);  // Inf / NaN
  } else if (exponent != 0) {
    bits = sign | ((exponent + 112u) << 23) | (mantissa << 13);
  } else if (mantissa == 0) {
    bits = sign;  // +-0
  } else {
    // Subnormal half: normalise into a float32 normal.
    int e = -1;
    do {
      ++e;
      mantissa <<= 1;
    } while ((mantissa & 0x400u) == 0);
    bits = sign | (std::uint32_t(112 - e) << 23) | ((mantissa & 0x3ffu) << 13);
  }
  return std::bit_cast<float>(bits);
}

inline std::uint16_t FloatToHalf(float f) {
  const std::uint32_t x = std::bit_cast<std::uint32_t>(f);
  const std::uint16_t sign = std::uint16_t((x >> 16) & 0x8000u);
  const std::uint32_t abs = x & 0x7fffffffu;
  if (abs >= 0x7f800000u)  // Inf or NaN (NaN keeps a quiet payload bit)
    return std::uint16_t(sign | 0x7c00u | (abs > 0x7f800000u ? 0x200u : 0u));
  if (abs >= 0x477ff000u) return std::uint16_t(sign | 0x7c00u);  // rounds past 65504: infinity
  if (abs < 0x38800000u) {
    // Result is subnormal (or zero): value = abs_float / 2^-24, rounded to nearest even.
    if (abs < 0x33000000u) return sign;  // below half the smallest subnormal: +-0
    const std::uint32_t mant = (abs & 0x7fffffu) | 0x800000u;
    const int shift = 126 - int(abs >> 23);  // value / 2^-24 = mant * 2^(exponent - 126)
    const std::uint32_t value = mant >> shift;
    const std::uint32_t rest = mant & ((1u << shift) - 1u), halfway = 1u << (shift - 1);
    const std::uint32_t rounded = value + ((rest > halfway || (rest == halfway && (value & 1u))) ? 1u : 0u);
    return std::uint16_t(sign | rounded);
  }
  // Normal: rebias the exponent, round the 13 dropped mantissa bits to nearest even (a carry
  // into the exponent is the correct result).
  const std::uint32_t rebased = abs - 0x38000000u;
  const std::uint32_t value = rebased >> 13, rest = rebased & 0x1fffu;
  const std::uint32_t rounded = value + ((rest > 0x1000u || (rest == 0x1000u && (value & 1u))) ? 1u : 0u);
  return std::uint16_t(sign | rounded);
}

// The largest finite half.
inline constexpr float kHalfMax = 65504.0f;

// n values at once, bit-identical to FloatToHalf / HalfToFloat for every value but NaN payloads
// (F16C, 8 per instruction, where the build targets it: -march=x86-64-v3; else the functions above).
inline void FloatsToHalves(const float* in, std::uint16_t* out, std::size_t n) {
  std::size_t i = 0;
#ifdef __F16C__
  for (; i + 8 <= n; i += 8)
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i), _mm256_cvtps_ph(_mm256_loadu_ps(in + i), _MM_FROUND_TO_NEAREST_INT));
#endif
  for (; i < n; ++i) out[i] = FloatToHalf(in[i]);
}
inline void HalvesToFloats(const std::uint16_t* in, float* out, std::size_t n) {
  std::size_t i = 0;
#ifdef __F16C__
  for (; i + 8 <= n; i += 8)
    _mm256_storeu_ps(out + i, _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(in + i))));
#endif
  for (; i < n; ++i) out[i] = HalfToFloat(in[i]);
}
// Rounds n floats in place to the nearest half value (ties to even), kept as floats: the same
// values as HalfToFloat(FloatToHalf(x)), 8 at a time with F16C.
inline void RoundToHalves(float* data, std::size_t n) {
  std::size_t i = 0;
#ifdef __F16C__
  for (; i + 8 <= n; i += 8)
    _mm256_storeu_ps(data + i, _mm256_cvtph_ps(_mm256_cvtps_ph(_mm256_loadu_ps(data + i), _MM_FROUND_TO_NEAREST_INT)));
#endif
  for (; i < n; ++i) data[i] = HalfToFloat(FloatToHalf(data[i]));
}

}  // namespace btf
