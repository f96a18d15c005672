#pragma once
// Conversion between BTF file formats (btf-convert, docs/btf-convert.md): any view-slot source
// (dataset, codec, Bonn .btf) to a libbtf dataset or a Bonn BDI file, one view slot at a time.
#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/bonn.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/slot_source.h"

namespace btf {

struct ConvertOptions {
  // Output format: "dataset" (libbtf-dataset, .h5), "bdi" (Bonn BDI, .btf), "fmf" / "dfmf" (Bonn
  // factorisations: compress/bonn_fmf.h) or "pvf" (Bonn PVF, from a pca-view codec only:
  // compress/bonn_pvf.h); "" = from the output's extension (.h5 -> dataset, .btf -> bdi).
  std::string to;
  // Dataset output: "float32" or "float16" storage, deflate level 0-9.
  std::string storage = "float32";
  int deflate_level = 4;
  // BDI output: texture rows per chunk.
  int scan_lines_per_chunk = 4;
  void Check() const;
  nlohmann::json ToJson() const;
};

// The output format Convert writes for `output` ("dataset" or "bdi"); throws btf::Error (usage)
// for an unknown --to or an extension it cannot map.
std::string ConvertTarget(const ConvertOptions& options, const std::filesystem::path& output);

struct ConvertSummary {
  std::string input, input_kind, output, output_format;
  int views = 0, lights = 0, height = 0, width = 0, channels = 0;
  std::uint64_t bytes_written = 0;
  PhaseTimes times;  // convert (read, decode and write, interleaved per view slot)
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// Writes `input` to `output` (atomically: nothing appears under `output` on failure) as a dataset
// or BDI. For "fmf", "dfmf" and "pvf" it throws btf::Error (usage): those are written by WriteFmf
// and WritePvf (libbtf/compress), which btf-convert calls.
ConvertSummary Convert(const ConvertOptions& options, const SlotSource& input, const std::filesystem::path& output,
                       const Reporter& reporter = {});

}  // namespace btf
