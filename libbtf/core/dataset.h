#pragma once
// An in-memory BTF: views x lights x height x width x channels, float32.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"

namespace btf {

// What the numbers mean (docs/conventions.md). Carried in every file.
struct DatasetInfo {
  // "linear_srgb" (linear values, sRGB/Rec.709 primaries, D65) unless stated otherwise.
  std::string color_space = "linear_srgb";
  // "brdf_per_sr": reflectance in 1/sr (radiance / irradiance). "relative": arbitrary linear scale.
  std::string units = "brdf_per_sr";
  // True if values are BRDF * cos(theta_i), as many measured BTFs are stored.
  bool cos_theta_i_included = false;
  std::vector<std::string> channel_names{"R", "G", "B"};
  // Physical size of the texture tile in mm (0 = unknown) and how texels were sampled.
  double texel_size_mm = 0;
  // Free-form provenance: creator tool, options, sources. Stored as a JSON dataset.
  nlohmann::json provenance = nlohmann::json::object();
};

// Upper bound on the bytes a single dataset or codec may allocate. Inputs that claim more are
// refused before allocating. Raise it with the environment variable BTF_MAX_BYTES.
std::uint64_t MaxAllocationBytes();
// Throws btf::Error (bad input) if `bytes` exceeds MaxAllocationBytes(); `what` names the item.
// Callers compute `bytes` in double: a crafted header's dimensions (each up to 2^20 or 2^31) can
// multiply past 2^64, and a wrapped-around integer product would pass the check.
void CheckAllocation(double bytes, const std::string& what);

class Dataset {
 public:
  Dataset() = default;
  Dataset(Sampling views, Sampling lights, int height, int width, int channels, DatasetInfo info = {});

  int num_views() const { return views_.size(); }
  int num_lights() const { return lights_.size(); }
  int height() const { return height_; }
  int width() const { return width_; }
  int channels() const { return channels_; }
  const Sampling& views() const { return views_; }
  const Sampling& lights() const { return lights_; }
  const DatasetInfo& info() const { return info_; }
  DatasetInfo& info() { return info_; }

  std::size_t image_size() const { return static_cast<std::size_t>(height_) * width_ * channels_; }
  std::size_t abrdf_size() const { return static_cast<std::size_t>(num_views()) * num_lights() * channels_; }
  std::size_t num_texels() const { return static_cast<std::size_t>(height_) * width_; }
  std::size_t size() const { return data_.size(); }

  // One image (view v, light l): height x width x channels, row-major, channel fastest.
  std::span<float> image(int v, int l);
  std::span<const float> image(int v, int l) const;
  // All images of view v (lights x height x width x channels), contiguous.
  std::span<float> view_slot(int v);
  std::span<const float> view_slot(int v) const;

  float& at(int v, int l, int y, int x, int c) { return data_[index(v, l, y, x, c)]; }
  float at(int v, int l, int y, int x, int c) const { return data_[index(v, l, y, x, c)]; }

  // The texel's apparent BRDF: views x lights x channels (channel fastest).
  std::vector<float> Abrdf(int y, int x) const;
  void SetAbrdf(int y, int x, std::span<const float> abrdf);

  std::vector<float>& data() { return data_; }
  const std::vector<float>& data() const { return data_; }

 private:
  std::size_t index(int v, int l, int y, int x, int c) const {
    return (((static_cast<std::size_t>(v) * num_lights() + l) * height_ + y) * width_ + x) * channels_ + c;
  }

  Sampling views_, lights_;
  int height_ = 0, width_ = 0, channels_ = 0;
  DatasetInfo info_;
  std::vector<float> data_;
};

}  // namespace btf
