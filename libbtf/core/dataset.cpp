#include "libbtf/core/dataset.h"

#include <cstdlib>

#include "libbtf/core/error.h"

namespace btf {

std::uint64_t MaxAllocationBytes() {
  if (const char* env = std::getenv("BTF_MAX_BYTES")) {
    char* end = nullptr;
    const unsigned long long v = std::strtoull(env, &end, 10);
    if (end != env && *end == '\0' && v > 0) return v;
  }
  return 16ull << 30;  // 16 GiB: two thirds of the reference 24 GiB machine
}

void CheckAllocation(double bytes, const std::string& what) {
  const std::uint64_t limit = MaxAllocationBytes();
  if (!(bytes <= static_cast<double>(limit)))
    ThrowBadInput("{} needs {:.3g} GiB, over the limit of {:.3g} GiB; raise it with BTF_MAX_BYTES=<bytes> if the "
                  "machine has the memory",
                  what, bytes / double(1ull << 30), double(limit) / double(1ull << 30));
}

Dataset::Dataset(Sampling views, Sampling lights, int height, int width, int channels, DatasetInfo info)
    : views_(std::move(views)), lights_(std::move(lights)), height_(height), width_(width), channels_(channels),
      info_(std::move(info)) {
  if (views_.size() < 1 || lights_.size() < 1 || height < 1 || width < 1 || channels < 1)
    ThrowBadInput("dataset shape {}x{}x{}x{}x{} (views x lights x height x width x channels) must be positive",
                  views_.size(), lights_.size(), height, width, channels);
  CheckAllocation(4.0 * views_.size() * lights_.size() * height * width * channels, "dataset");
  if (static_cast<int>(info_.channel_names.size()) != channels) {
    info_.channel_names.clear();
    for (int c = 0; c < channels; ++c)
      info_.channel_names.push_back(channels == 3 ? std::string(1, "RGB"[c]) : "C" + std::to_string(c));
  }
  const std::uint64_t n = std::uint64_t(views_.size()) * lights_.size() * height * width * channels;
  data_.assign(n, 0.0f);
}

std::span<float> Dataset::image(int v, int l) { return {data_.data() + index(v, l, 0, 0, 0), image_size()}; }
std::span<const float> Dataset::image(int v, int l) const {
  return {data_.data() + index(v, l, 0, 0, 0), image_size()};
}
std::span<float> Dataset::view_slot(int v) {
  return {data_.data() + index(v, 0, 0, 0, 0), image_size() * num_lights()};
}
std::span<const float> Dataset::view_slot(int v) const {
  return {data_.data() + index(v, 0, 0, 0, 0), image_size() * num_lights()};
}

std::vector<float> Dataset::Abrdf(int y, int x) const {
  std::vector<float> out(abrdf_size());
  std::size_t k = 0;
  for (int v = 0; v < num_views(); ++v)
    for (int l = 0; l < num_lights(); ++l)
      for (int c = 0; c < channels_; ++c) out[k++] = data_[index(v, l, y, x, c)];
  return out;
}

void Dataset::SetAbrdf(int y, int x, std::span<const float> abrdf) {
  std::size_t k = 0;
  for (int v = 0; v < num_views(); ++v)
    for (int l = 0; l < num_lights(); ++l)
      for (int c = 0; c < channels_; ++c) data_[index(v, l, y, x, c)] = abrdf[k++];
}

}  // namespace btf
