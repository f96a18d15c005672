#pragma once
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"

namespace btf {

inline constexpr const char* kBonnBdiFormat = "bonn-bdi";
inline constexpr const char* kBonnDfmfFormat = "bonn-dfmf";
inline constexpr const char* kBonnFmfFormat = "bonn-fmf";
inline constexpr const char* kBonnPvfFormat = "bonn-pvf";
inline bool IsBonnFormat(const std::string& format) { return format.starts_with("bonn-"); }

// The root "format" attribute of a libbtf HDF5 file ("libbtf-dataset", "libbtf-codec", ...), or
// for a University of Bonn .btf file (recognised by its signature, libbtf/io/bonn.h) one of the
// kBonn*Format names. Throws btf::Error (bad input) for files that are neither.
std::string FileFormatOf(const std::filesystem::path& path);

// btf-info's summary of a dataset file; with_stats scans every value (min, max, mean, NaN/Inf).
nlohmann::json DescribeDatasetFile(const std::filesystem::path& path, bool with_stats, const Reporter& reporter = {});

}  // namespace btf
