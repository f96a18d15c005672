#pragma once
// Checked reads of codec-file items, shared by the codec readers (lpca_tensor.cpp,
// neural_codec.cpp): a missing item, a wrong shape, a non-finite float or an integer out of its
// range is refused (btf::Error, bad input) naming the file and the item.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "libbtf/core/error.h"
#include "libbtf/io/hdf5.h"

namespace btf::codec_items {

// "4x3", or "scalar" for no dimension.
inline std::string Shape(const std::vector<hsize_t>& dims) {
  std::string s;
  for (auto x : dims) s += fmt::format("{}{}", s.empty() ? "" : "x", x);
  return s.empty() ? "scalar" : s;
}

inline void CheckDims(const h5::File& f, const std::string& name, const std::vector<hsize_t>& dims) {
  if (!f.Exists(name)) ThrowBadInput("'{}': required item '{}' is missing", f.path(), name);
  const auto got = f.Dims(name);
  if (got != dims) ThrowBadInput("'{}': '{}' has shape {}, expected {}", f.path(), name, Shape(got), Shape(dims));
}

inline std::vector<float> Floats(const h5::File& f, const std::string& name, const std::vector<hsize_t>& dims) {
  CheckDims(f, name, dims);
  auto v = f.ReadFloats(name);
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) ThrowBadInput("'{}': '{}' holds a non-finite value at element {}", f.path(), name, i);
  return v;
}

inline std::vector<std::int32_t> Ints(const h5::File& f, const std::string& name, const std::vector<hsize_t>& dims,
                                      std::int64_t lo, std::int64_t hi) {
  CheckDims(f, name, dims);
  auto v = f.ReadInts(name);
  for (std::size_t i = 0; i < v.size(); ++i)
    if (v[i] < lo || v[i] > hi)
      ThrowBadInput("'{}': '{}' element {} is {}, outside [{}, {}]", f.path(), name, i, v[i], lo, hi);
  return v;
}

}  // namespace btf::codec_items
