#pragma once
// Pieces shared by the two renderer exports (schneider.cpp, sattler.cpp): binary files, the
// normalised u8 / f16 storage of a value t in [0, 1], and the manifest blocks both carry.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/export/export_reader.h"
#include "libbtf/io/half.h"

namespace btf::export_detail {

template <typename T>
std::uint64_t WriteBinary(const std::filesystem::path& path, const std::vector<T>& data) {
  WriteFileAtomic(path, data.data(), data.size() * sizeof(T));
  return data.size() * sizeof(T);
}

// The normalised values of one export: u8 (t = q / 255) or f16 (half floats).
class NormalisedStore {
 public:
  NormalisedStore(bool half, std::size_t n) : half_(half), u8_(half ? 0 : n), f16_(half ? n : 0) {}
  // Stores t at `at`; returns the value a GPU reads back.
  double Put(std::size_t at, double t) {
    if (half_) {
      f16_[at] = FloatToHalf(static_cast<float>(t));
      return HalfToFloat(f16_[at]);
    }
    u8_[at] = static_cast<std::uint8_t>(std::clamp(std::lround(t * 255.0), 0L, 255L));
    return u8_[at] / 255.0;
  }
  std::uint64_t Write(const std::filesystem::path& path) const {
    return half_ ? WriteBinary(path, f16_) : WriteBinary(path, u8_);
  }

 private:
  bool half_;
  std::vector<std::uint8_t> u8_;
  std::vector<std::uint16_t> f16_;
};

// "checksums" of the manifest: the CRC-32 of every file written so far into `dir` (all but the
// manifest), by name (export_reader.h VerifyExportChecksums checks them).
inline nlohmann::json ExportChecksums(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename() != "manifest.json") names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  nlohmann::json files = nlohmann::json::object();
  for (const std::string& n : names) files[n] = FileCrc32(dir / n);
  return {{"algorithm", "crc32"}, {"files", files}};
}

inline std::string WebGlFormat(bool half, int channels) {
  return half ? (channels == 1 ? "R16F / RED / HALF_FLOAT" : "RGB16F / RGB / HALF_FLOAT")
              : (channels == 1 ? "R8 / RED / UNSIGNED_BYTE" : "RGB8 / RGB / UNSIGNED_BYTE");
}

// "texture" and "values" of the manifest.
inline nlohmann::json TextureJson(const Codec& codec) {
  return {{"height", codec.height()}, {"width", codec.width()}, {"channels", codec.channels()},
          {"channel_names", codec.info().channel_names}, {"row_0", "top (v = 1)"},
          {"texel_of_uv", "x = floor(u * width), y = floor((1 - v) * height), wrapping"}};
}
inline nlohmann::json ValuesJson(const Codec& codec) {
  return {{"units", codec.info().units}, {"color_space", codec.info().color_space},
          {"cos_theta_i_included", codec.info().cos_theta_i_included}};
}

}  // namespace btf::export_detail
