#pragma once
// Test shorthands for the compression entry point (Compress writes the codec to an out-parameter).
#include <filesystem>

#include "libbtf/compress/codec.h"

namespace btf::test {

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
