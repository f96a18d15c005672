#include "libbtf/io/dataset_stats.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <vector>

#include "libbtf/core/progress.h"

namespace btf {

nlohmann::json ValueStats::ToJson() const {
  auto finite_or_null = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"min", finite_or_null(min)},         {"max", finite_or_null(max)},     {"mean", mean},
          {"count", count},                     {"nan_count", nan_count},         {"inf_count", inf_count},
          {"negative_count", negative_count}};
}

namespace {

template <typename ReadSlot>
ValueStats ScanValues(std::size_t slot_size, int views, ReadSlot read, const Reporter& reporter) {
  std::vector<float> slot(slot_size);
  ValueStats s;
  double sum = 0;  // double: up to 10^9 values are summed
  for (int v = 0; v < views; ++v) {
    read(v, slot.data());
    for (float x : slot) {
      if (std::isnan(x)) {
        ++s.nan_count;
        continue;
      }
      if (std::isinf(x)) {
        ++s.inf_count;
        continue;
      }
      s.min = std::min<double>(s.min, x);
      s.max = std::max<double>(s.max, x);
      s.negative_count += x < 0;
      sum += x;
      ++s.count;
    }
    reporter.Progress(std::size_t(v + 1), std::size_t(views), "scanning values");
  }
  s.mean = s.count ? sum / double(s.count) : 0.0;
  return s;
}

}  // namespace

ValueStats ComputeValueStats(const DatasetReader& reader, const Reporter& reporter) {
  const auto& h = reader.header();
  return ScanValues(
      std::size_t(h.num_lights) * h.height * h.width * h.channels, h.num_views,
      [&](int v, float* out) { reader.ReadViewSlot(v, out); }, reporter);
}

ValueStats ComputeValueStats(const SlotSource& source, const Reporter& reporter) {
  return ScanValues(
      source.slot_size(), source.views().size(), [&](int v, float* out) { source.ReadViewSlot(v, out); }, reporter);
}

nlohmann::json DescribeSampling(const Sampling& s) {
  nlohmann::json dirs = nlohmann::json::array();
  for (int i = 0; i < s.size(); ++i) {
    const Angles a = s.angles(i);
    dirs.push_back({RadToDeg(a.theta), RadToDeg(a.phi)});
  }
  return {{"name", s.name()}, {"count", s.size()}, {"theta_phi_deg", dirs}};
}

nlohmann::json DescribeDatasetHeader(const DatasetHeader& h) {
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(h.path, ec);
  nlohmann::json missing = nlohmann::json::array();
  for (const auto& [v, l] : h.missing) missing.push_back({{"view", v}, {"light", l}});
  return {{"path", h.path},
          {"missing_images", missing},
          {"format", kDatasetFormat},
          {"format_version", h.format_version},
          {"creator", h.creator},
          {"creation_time", h.creation_time},
          {"storage", h.storage},
          {"shape",
           {{"views", h.num_views}, {"lights", h.num_lights}, {"height", h.height}, {"width", h.width},
            {"channels", h.channels}}},
          {"view_sampling", DescribeSampling(h.views)},
          {"light_sampling", DescribeSampling(h.lights)},
          {"color_space", h.info.color_space},
          {"units", h.info.units},
          {"cos_theta_i_included", h.info.cos_theta_i_included},
          {"channel_names", h.info.channel_names},
          {"texel_size_mm", h.info.texel_size_mm},
          {"file_bytes", ec ? 0 : bytes},
          {"provenance", h.info.provenance}};
}

}  // namespace btf
