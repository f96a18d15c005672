#pragma once
// Header-only reading of a renderer export folder (format libbtf-schneider-export 2.x), shared by
// the reference decoders of both layouts (schneider_reference_decoder.h, sattler_reference_decoder.h).
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/error.h"
#include "libbtf/io/half.h"

namespace btf::export_detail {

// manifest.json of `dir`, checked to be a 2.x export of `layout` (a 2.0.0 manifest has no
// "layout": it is schneider-2004).
inline nlohmann::json ReadExportManifest(const std::filesystem::path& dir, const std::string& layout) {
  const std::filesystem::path path = dir / "manifest.json";
  std::ifstream in(path);
  if (!in) ThrowIo("cannot open '{}'", path.string());
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.is_object() || j.value("format", "") != "libbtf-schneider-export")
    ThrowBadInput("'{}' is not a libbtf renderer export manifest", path.string());
  if (j.value("format_version", "").rfind("2.", 0) != 0)
    ThrowBadInput("'{}': unsupported export version '{}' (this decoder reads 2.x)", path.string(),
                  j.value("format_version", ""));
  const std::string got = j.value("layout", "schneider-2004");
  if (got != layout)
    ThrowBadInput("'{}': the export's layout is '{}', not {} (read it with the decoder of its layout)", path.string(),
                  got, layout);
  return j;
}

// Exactly `count` values of T from `path`.
template <typename T>
std::vector<T> LoadExportFile(const std::filesystem::path& path, std::size_t count) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowIo("cannot open '{}'", path.string());
  std::vector<T> v(count);
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(count * sizeof(T)));
  if (in.gcount() != static_cast<std::streamsize>(count * sizeof(T)) || in.peek() != EOF)
    ThrowBadInput("'{}' does not hold exactly {} values of {} bytes", path.string(), count, sizeof(T));
  return v;
}

// Normalised values t as a GPU samples them from a u8 (q / 255) or f16 file.
inline std::vector<float> LoadNormalised(const std::filesystem::path& path, const std::string& storage, std::size_t count) {
  std::vector<float> t(count);
  if (storage == "u8") {
    const auto q = LoadExportFile<std::uint8_t>(path, count);
    for (std::size_t i = 0; i < count; ++i) t[i] = q[i] / 255.0f;
  } else if (storage == "f16") {
    const auto q = LoadExportFile<std::uint16_t>(path, count);
    for (std::size_t i = 0; i < count; ++i) t[i] = HalfToFloat(q[i]);
  } else {
    ThrowBadInput("'{}': unknown storage '{}' (u8 or f16)", path.string(), storage);
  }
  return t;
}

inline bool JsonFlag(const nlohmann::json& v) { return v.is_boolean() ? v.get<bool>() : v.get<int>() != 0; }

}  // namespace btf::export_detail
