#pragma once
#include <cstdint>
#include <limits>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// Value statistics of a dataset file, computed one view slot at a time (bounded memory).
struct ValueStats {
  double min = std::numeric_limits<double>::infinity();
  double max = -std::numeric_limits<double>::infinity();
  double mean = 0;
  std::uint64_t count = 0, nan_count = 0, inf_count = 0, negative_count = 0;
  nlohmann::json ToJson() const;
};
ValueStats ComputeValueStats(const DatasetReader& reader, const Reporter& reporter = {});
// The same over any view-slot source (e.g. a Bonn .btf file, decoded slot by slot).
ValueStats ComputeValueStats(const SlotSource& source, const Reporter& reporter = {});

// {"name", "count", "theta_phi_deg": [[theta, phi], ...]} as btf-info prints samplings.
nlohmann::json DescribeSampling(const Sampling& sampling);

// Summary of a dataset file for btf-info: shape, samplings, conventions, storage, size on disk.
nlohmann::json DescribeDatasetHeader(const DatasetHeader& header);

}  // namespace btf
