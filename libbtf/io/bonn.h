#pragma once
// University of Bonn `.btf` files (normative as we read and write them: docs/format.md, "Bonn
// .btf files"): BDI (uncompressed, full or sparse mask), DFMF (decorrelated full-matrix
// factorisation), FMF (full-matrix factorisation) and PVF (per-view factorisation, current and
// legacy header). Readers decode one view slot at a time from the stored factors and never hold
// the whole BTF; every malformed item is refused with btf::Error (bad input) naming the file, the
// field and its byte offset.
#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/dataset.h"
#include "libbtf/core/progress.h"
#include "libbtf/io/slot_source.h"

namespace btf {

enum class BonnFormat { kBdi, kDfmf, kFmf, kPvf };

// The epsilon of the logarithmic colour models and of FMF's dynamic-range reduction. No file
// stores it; every public reader assumes this value.
inline constexpr double kBonnEpsilon = 1e-5;

// The signature at the start of `path` if it is a Bonn file ("!DFMF08FCR", ...), else "". A file
// that starts with '!' followed by an unknown signature throws btf::Error (bad input).
std::string BonnSignatureOf(const std::filesystem::path& path);
bool IsBonnFile(const std::filesystem::path& path);

// Everything in a Bonn file except the factor and texel values.
struct BonnHeader {
  std::string path, signature;
  BonnFormat format = BonnFormat::kBdi;
  std::uint64_t file_bytes = 0;
  // Meta block (absent in legacy PVF: has_meta false, defaults below).
  bool has_meta = true;
  std::uint32_t meta_version = 0;
  std::string measurement_setup, image_sensor, light_source, xml;
  float ppmm = 0;
  std::array<float, 3> rgb_scale_factor{1, 1, 1};
  bool cosine_flag = false;
  std::vector<std::string> channel_names{"R", "G", "B"};
  // Sampling and texture size.
  Sampling views, lights;
  int width = 0, height = 0;
  // Local-frame rotations, 9 floats each (tangent, binormal, normal), read and reported, not applied.
  std::vector<std::array<float, 9>> rotations;
  // DFMF: colour model, mean, transform (row-major); components and scalar size per channel.
  int color_model = 0;
  std::uint32_t header_components = 0;
  std::array<float, 3> color_mean{0, 0, 0};
  std::array<float, 9> color_transform{1, 0, 0, 0, 1, 0, 0, 0, 1};
  // Components actually decoded: per channel (DFMF), one entry (FMF), per view slot (PVF).
  std::vector<int> components;
  std::vector<int> scalar_sizes;  // bytes per stored factor value, per block as `components`
  // DFMF/FMF: true if the file stores the transposed layout (U over texels, SxV over directions).
  bool transposed = false;
  // FMF.
  int fmf_header_version = 0;
  std::uint32_t dynamic_range_reduction = 0;  // 0 none, else log: decode exp(x) - epsilon
  int height_map_width = 0, height_map_height = 0;
  // PVF.
  bool pvf_legacy = false;
  bool pvf_images = false;  // true: stacked images (weights per light), false: light fields
  // BDI.
  std::uint32_t scan_lines_per_chunk = 0;
  std::uint8_t compression = 0;  // 0 full, 2 sparse (1 bzip2 is refused)
  std::uint64_t stored_texels = 0;
  // ABRDFs of padding after the last stored one: btflib writes its last chunk padded to full scan
  // lines (W x scan_lines_per_chunk ABRDFs); the padding is never read.
  std::uint64_t padding_abrdfs = 0;

  int channels() const { return int(channel_names.size()); }
  // Conventions as libbtf applies them (units "relative", cos flag carried, not divided out).
  DatasetInfo Info() const;
};

// Opens and validates a Bonn file. With header_only, DFMF/FMF factors are not loaded (their
// sizes are still checked against the file length); ReadViewSlot then throws (internal).
class BonnReader {
 public:
  explicit BonnReader(const std::filesystem::path& path, bool header_only = false);
  ~BonnReader();
  BonnReader(BonnReader&&) noexcept;
  const BonnHeader& header() const;
  // lights x height x width x channels floats, decoded (colour model and dynamic-range
  // reduction undone; values as stored otherwise). Thread-safe.
  void ReadViewSlot(int view, float* out) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// "bdi", "dfmf", "fmf", "pvf".
const char* BonnFormatName(BonnFormat format);
// The name of DFMF colour model `id`: "rgb", "yuv", "lab", "pca", "ycocg", "spectral",
// "spectral_linear", "ylog_uv", "ylog_ulog_vlog", "ylog_udivy_vdivy", "log_rgb", or "unknown".
std::string BonnColorModelName(int id);

// A Bonn file as a view-slot source (kind "bonn-bdi", "bonn-dfmf", "bonn-fmf", "bonn-pvf").
std::unique_ptr<SlotSource> OpenBonnSource(const std::filesystem::path& path);

// btf-info's summary: format, signature, shape, samplings, components, colour model, stored
// conventions and meta data; with_stats scans every decoded value (one view slot at a time).
nlohmann::json DescribeBonnFile(const std::filesystem::path& path, bool with_stats, const Reporter& reporter = {});

// The bytes libbtf's writers put right after a signature: the meta block (version 4:
// measurement_setup, empty sensor and light source, ppmm = 1/texel_size_mm or 0,
// rgb_scale_factor 1, cosine_flag = cos_theta_i_included, no XML, the channel names) and the
// sampling block (every view repeating the light list; float32 radians).
std::string EncodeBonnMetaAndSampling(const Sampling& views, const Sampling& lights, const DatasetInfo& info,
                                      const std::string& measurement_setup);

// Writes `source` as a BDI file (`!BDIF06R2!`, meta version 4, half data, sparse flag with a
// full mask so that btflib reads it, no rotations), one view slot at a time. Values must be
// finite and within the half range (|x| <= 65504), else btf::Error (bad input) naming the item.
// The file appears under `path` only when complete (atomic).
struct BdiWriteOptions {
  int scan_lines_per_chunk = 4;  // texture rows per chunk (btflib's default)
  std::string measurement_setup = "libbtf";  // stored in the meta block (at most 79 bytes)
  void Check() const;
};
// Returns the bytes written.
std::uint64_t WriteBdi(const std::filesystem::path& path, const SlotSource& source, const BdiWriteOptions& options = {},
                       const Reporter& reporter = {});

}  // namespace btf
