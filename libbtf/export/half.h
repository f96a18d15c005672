#pragma once
// IEEE 754 binary16 ("half") conversion, as WebGL2/OpenGL HALF_FLOAT textures store it: round to
// nearest even, overflow to infinity, subnormals kept. Header-only (the reference decoder uses it).
#include <cmath>
#include <cstdint>
#include <cstring>

namespace btf {

inline std::uint16_t FloatToHalf(float value) {
  std::uint32_t x;
  std::memcpy(&x, &value, 4);
  const std::uint32_t sign = (x >> 16) & 0x8000u;
  const std::uint32_t abs = x & 0x7fffffffu;
  if (abs >= 0x7f800000u) return static_cast<std::uint16_t>(sign | (abs > 0x7f800000u ? 0x7e00u : 0x7c00u));
  if (abs >= 0x477ff000u) return static_cast<std::uint16_t>(sign | 0x7c00u);  // rounds to >= 65520: infinity
  if (abs < 0x38800000u) {  // below the smallest normal half (2^-14): subnormal or zero
    const std::uint32_t shift = 113u - (abs >> 23);  // 126 - exponent, >= 1
    if (shift > 24) return static_cast<std::uint16_t>(sign);
    const std::uint32_t mant = (abs & 0x7fffffu) | 0x800000u;
    const std::uint32_t q = mant >> (shift + 13), rest = mant & ((1u << (shift + 13)) - 1), half = 1u << (shift + 12);
    return static_cast<std::uint16_t>(sign | (q + (rest > half || (rest == half && (q & 1u)))));
  }
  const std::uint32_t e = ((abs >> 23) - 112u) << 10, m = (abs >> 13) & 0x3ffu, rest = abs & 0x1fffu;
  const std::uint32_t h = e | m;
  return static_cast<std::uint16_t>(sign | (h + (rest > 0x1000u || (rest == 0x1000u && (h & 1u)))));
}

inline float HalfToFloat(std::uint16_t h) {
  const int e = (h >> 10) & 0x1f, m = h & 0x3ff;
  float v;
  if (e == 0)
    v = std::ldexp(static_cast<float>(m), -24);
  else if (e == 31)
    v = m ? NAN : INFINITY;
  else
    v = std::ldexp(static_cast<float>(m | 0x400), e - 25);
  return (h & 0x8000) ? -v : v;
}

}  // namespace btf
