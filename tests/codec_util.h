#pragma once
// Test shorthands for the compression entry point (Compress writes the codec to an out-parameter).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <vector>

#include "libbtf/compress/codec.h"
#include "libbtf/io/slot_source.h"

namespace btf::test {

// max |a - b| / max |a| over every value of two view-slot sources.
inline double MaxRelativeError(const SlotSource& a, const SlotSource& b) {
  std::vector<float> x(a.slot_size()), y(b.slot_size());
  double err = 0, peak = 0;
  for (int v = 0; v < a.views().size(); ++v) {
    a.ReadViewSlot(v, x.data());
    b.ReadViewSlot(v, y.data());
    for (std::size_t i = 0; i < x.size(); ++i) {
      err = std::max(err, double(std::abs(x[i] - y[i])));
      peak = std::max(peak, double(std::abs(x[i])));
    }
  }
  return err / peak;
}

inline Codec CompressDataset(const Dataset& d, const CompressOptions& o, CompressSummary* summary = nullptr) {
  Codec codec;
  const CompressSummary s = Compress(o, *MemorySource(d), &codec);
  if (summary) *summary = s;
  return codec;
}

inline Codec CompressPath(const std::filesystem::path& path, const CompressOptions& o,
                          CompressSummary* summary = nullptr) {
  Codec codec;
  const CompressSummary s = Compress(o, *OpenDatasetSource(path), &codec);
  if (summary) *summary = s;
  return codec;
}

}  // namespace btf::test
