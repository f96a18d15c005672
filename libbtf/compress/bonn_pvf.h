#pragma once
// A per-view PCA codec written as a Bonn PVF file (`!PVF06FCR`; docs/format.md, "PVF", "Writing
// PVF"): each view slot's mean image, eigen-images and per-light weights map one to one onto
// PVF's stacked-images layout.
#include <filesystem>

#include "libbtf/compress/codec.h"
#include "libbtf/io/convert.h"

namespace btf {

// Writes `codec` (method pca-view, no log transform; else btf::Error, usage) as PVF with float32
// factors, atomically. `input_name` is what the summary calls the codec.
ConvertSummary WritePvf(const Codec& codec, const std::string& input_name, const std::filesystem::path& path,
                        const Reporter& reporter = {});

}  // namespace btf
