#pragma once
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"

namespace btf {

// The root "format" attribute of a libbtf HDF5 file ("libbtf-dataset", "libbtf-codec", ...).
// Throws btf::Error (bad input) for files that are not libbtf files.
std::string FileFormatOf(const std::filesystem::path& path);

// btf-info's summary of a dataset file; with_stats scans every value (min, max, mean, NaN/Inf).
nlohmann::json DescribeDatasetFile(const std::filesystem::path& path, bool with_stats, const Reporter& reporter = {});

}  // namespace btf
