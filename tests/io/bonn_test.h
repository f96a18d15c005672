#pragma once
// Hand-built Bonn .btf files for the tests: written byte by byte from the layout in
// docs/format.md ("Bonn .btf files"), independently of libbtf's writer.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace btf::test {

class Bytes {
 public:
  template <typename T>
  Bytes& Put(T v) {
    const std::size_t at = b.size();
    b.resize(at + sizeof v);
    std::memcpy(b.data() + at, &v, sizeof v);
    return *this;
  }
  Bytes& U8(std::uint8_t v) { return Put(v); }
  Bytes& U16(std::uint16_t v) { return Put(v); }
  Bytes& U32(std::uint32_t v) { return Put(v); }
  Bytes& I32(std::int32_t v) { return Put(v); }
  Bytes& F32(float v) { return Put(v); }
  Bytes& F64(double v) { return Put(v); }
  Bytes& Text(const std::string& s) {
    b.insert(b.end(), s.begin(), s.end());
    return *this;
  }
  Bytes& Padded(const std::string& s, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) b.push_back(i < s.size() ? s[i] : '\0');
    return *this;
  }
  Bytes& Append(const Bytes& o) {
    b.insert(b.end(), o.b.begin(), o.b.end());
    return *this;
  }
  std::size_t size() const { return b.size(); }
  void Save(const std::filesystem::path& p) const {
    std::ofstream f(p, std::ios::binary);
    f.write(b.data(), std::streamsize(b.size()));
  }
  std::vector<char> b;
};

// Shape and meta data of a hand-built file.
struct Layout {
  int views = 2, lights = 3, width = 3, height = 2;
  int meta_version = 4;
  std::vector<std::string> channels{"R", "G", "B"};
  bool cosine = false;
  int rotations = 0;  // written only for signatures with the rotations flag
  float ppmm = 0;
  int nc() const { return int(channels.size()); }
  int texels() const { return width * height; }
  // Sampling angles (radians): distinct per view and light.
  static float ViewTheta(int v) { return 0.1f * float(v); }
  static float ViewPhi(int v) { return 0.5f * float(v) - 1.0f; }
  static float LightTheta(int l) { return 0.2f + 0.15f * float(l); }
  static float LightPhi(int l) { return -2.0f + 0.7f * float(l); }
};

inline Bytes Meta(const Layout& L) {
  Bytes m;
  m.U32(0).U32(std::uint32_t(L.meta_version));
  m.Padded("hand-built setup", 80).Padded("sensor", 80).Padded("light", 80);
  m.F32(L.ppmm).F32(1).F32(1).F32(1);
  if (L.meta_version > 1) m.U32(L.cosine ? 1 : 0);
  if (L.meta_version > 2) m.U32(5).Text("<x/>\n");
  if (L.meta_version > 3) {
    m.U32(std::uint32_t(L.channels.size()));
    for (const auto& c : L.channels) m.U32(std::uint32_t(c.size())).Text(c);
  }
  const auto size = std::uint32_t(m.size());
  std::memcpy(m.b.data(), &size, 4);
  return m;
}

inline Bytes SamplingBlock(const Layout& L) {
  Bytes s;
  s.U32(std::uint32_t(L.views));
  for (int v = 0; v < L.views; ++v) {
    s.F32(Layout::ViewTheta(v)).F32(Layout::ViewPhi(v)).U32(std::uint32_t(L.lights));
    for (int l = 0; l < L.lights; ++l) s.F32(Layout::LightTheta(l)).F32(Layout::LightPhi(l));
  }
  return s;
}

// Meta block, sampling, width, height (and rotations when `rotations`).
inline Bytes CommonHeader(const Layout& L, bool rotations) {
  Bytes h;
  h.Append(Meta(L)).Append(SamplingBlock(L)).U32(std::uint32_t(L.width)).U32(std::uint32_t(L.height));
  if (rotations) {
    h.U32(std::uint32_t(L.rotations));
    for (int r = 0; r < L.rotations; ++r)
      for (int i = 0; i < 9; ++i) h.F32(float(r * 10 + i));
  }
  return h;
}

// Factor values with distinct, small entries: U over directions, SxV over texels.
inline double FactorU(int c, int row, int k) { return 0.05 * (row + 1) + 0.02 * k - 0.03 * c; }
inline double FactorV(int c, int texel, int k) { return 0.3 + 0.07 * texel - 0.04 * k + 0.01 * c; }

}  // namespace btf::test
