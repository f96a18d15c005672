#pragma once
// Header-only reading of a renderer export folder (format libbtf-schneider-export 2.x), shared by
// the reference decoders of both layouts (schneider_reference_decoder.h, sattler_reference_decoder.h).
#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/core/error.h"
#include "libbtf/io/half.h"

namespace btf::export_detail {

// CRC-32 (IEEE 802.3 polynomial, reflected: zlib's crc32) of n bytes, continuing from `crc`.
// Header-only, as the reference decoders that check exports with it.
inline std::uint32_t Crc32(const unsigned char* data, std::size_t n, std::uint32_t crc = 0) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (std::size_t i = 0; i < n; ++i) crc = table[(crc ^ data[i]) & 0xffu] ^ (crc >> 8);
  return ~crc;
}

// The CRC-32 of a file's bytes as 8 lower-case hex digits.
inline std::string FileCrc32(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowIo("cannot open '{}'", path.string());
  std::uint32_t crc = 0;
  std::vector<char> buf(1 << 16);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    crc = Crc32(reinterpret_cast<const unsigned char*>(buf.data()), static_cast<std::size_t>(in.gcount()), crc);
  }
  // A failed read() leaves the stream bad (libstdc++ turns it into badbit), not merely at its end.
  if (in.bad()) ThrowIo("cannot read '{}' (I/O error): failing disk or network file system?", path.string());
  return fmt::format("{:08x}", crc);
}

// An export's files are checked against the manifest's "checksums" (exports from 2.2.0 carry
// them: {"algorithm": "crc32", "files": {name: hex}}); a damaged file is refused naming it. An
// export without checksums (2.0, 2.1) is read as it is.
inline void VerifyExportChecksums(const std::filesystem::path& dir, const nlohmann::json& manifest) {
  if (!manifest.contains("checksums")) return;
  const nlohmann::json& c = manifest.at("checksums");
  if (!c.is_object() || c.value("algorithm", "") != "crc32" || !c.contains("files") || !c.at("files").is_object())
    ThrowBadInput("'{}': \"checksums\" must be {{\"algorithm\": \"crc32\", \"files\": {{...}}}}",
                  (dir / "manifest.json").string());
  for (const auto& [name, want] : c.at("files").items()) {
    if (!want.is_string() || name.find('/') != std::string::npos || name.find("..") != std::string::npos)
      ThrowBadInput("'{}': checksum entry '{}' is not a file name with a hex string", (dir / "manifest.json").string(), name);
    const std::string got = FileCrc32(dir / name);
    if (got != want.get<std::string>())
      ThrowBadInput("'{}': CRC-32 {} does not match the manifest's {}: the export is damaged; export it again",
                    (dir / name).string(), got, want.get<std::string>());
  }
}

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
  VerifyExportChecksums(dir, j);
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
