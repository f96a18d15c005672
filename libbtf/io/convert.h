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
#include "libbtf/io/image_io.h"
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
  // Image-set input (ImportImageSet): "" (INPUT is a BTF file), "ubo2003" (8-bit sRGB JPEG),
  // "atrium" (Radiance HDR) or "pattern" (file names given by `pattern`).
  std::string layout;
  // Layout "pattern": the path of each image relative to the folder, with the fields {tv} {pv}
  // {tl} {pl} (view and light theta and phi in degrees, each exactly once), e.g.
  // "tv{tv}_pv{pv}/tl{tl}_pl{pl}.exr".
  std::string pattern;
  // Missing (view, light) images are written as 0 and marked missing in the dataset (format 1.1,
  // /btf/missing) instead of refusing the set.
  bool allow_missing = false;
  // Image sets: "all" (every direction of the layout's sampling) or "present" (only the views and
  // lights that have at least one image: a partial download imports as the smaller set it is).
  std::string directions = "all";
  // Image output ("png": 8-bit sRGB of exposure x value clamped to [0, 1], as the renders show
  // it; "exr": the linear values x exposure, float): the (view, light) image, indices into the
  // input's samplings.
  int view = 0, light = 0;
  double exposure = 1;
  // Image-set input: the largest image read (ImageReadOptions::max_pixels; 0 = no limit).
  std::uint64_t max_pixels = kDefaultMaxImagePixels;
  void Check() const;
  nlohmann::json ToJson() const;
};

// The output format Convert writes for `output` ("dataset", "bdi", "png" or "exr"); throws
// btf::Error (usage) for an unknown --to or an extension it cannot map.
std::string ConvertTarget(const ConvertOptions& options, const std::filesystem::path& output);

struct ConvertSummary {
  std::string input, input_kind, output, output_format;
  int views = 0, lights = 0, height = 0, width = 0, channels = 0;
  std::uint64_t bytes_written = 0;
  std::uint64_t missing_images = 0;  // image sets: (view, light) images written as 0 (--allow-missing)
  PhaseTimes times;  // convert (read, decode and write, interleaved per view slot)
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// Writes `input` to `output` (atomically: nothing appears under `output` on failure) as a dataset
// or BDI. For "fmf", "dfmf" and "pvf" it throws btf::Error (usage): those are written by WriteFmf
// and WritePvf (libbtf/compress), which btf-convert calls.
// Writes the (view, light) image of `input` (a dataset, a codec decoded, a Bonn file) to `path`:
// .png as 8-bit sRGB of exposure x value clamped to [0, 1] (the tone mapping of the renders),
// .exr as linear float values x exposure. Throws btf::Error (usage) for indices out of range.
void WriteSampleImage(const SlotSource& input, int view, int light, double exposure, const std::filesystem::path& path);

ConvertSummary Convert(const ConvertOptions& options, const SlotSource& input, const std::filesystem::path& output,
                       const Reporter& reporter = {});

// Imports a folder of images, one per (view, light), into a dataset file (atomically, one image
// at a time; docs/btf-convert.md "Image sets"). Directions come from the file names: ubo2003 and
// atrium name Bonn 81 directions, `NNNNN tlTTT plPPP tvTTT pvPPP.jpg|.hdr` (NNNNN = 81 light +
// view) anywhere under the folder; a pattern's directions are those its names hold (the Bonn 81
// or UBO2014 sampling when they are exactly those). Images must share one size and channel count.
// Missing images, unknown directions, duplicates and unreadable images are btf::Error (bad input)
// naming the files; the output is then not written.
ConvertSummary ImportImageSet(const ConvertOptions& options, const std::filesystem::path& folder,
                              const std::filesystem::path& output, const Reporter& reporter = {});

}  // namespace btf
