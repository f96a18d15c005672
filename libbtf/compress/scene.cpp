#include "libbtf/compress/scene.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>
#include <set>

#include <Eigen/Geometry>
#include <fmt/ranges.h>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"

namespace btf {

namespace {

DirectionCone ParseCone(const nlohmann::json& j, const std::string& where) {
  if (!j.is_object()) ThrowBadInput("{}: must be an object {{\"theta_deg\", \"phi_deg\", \"cone_deg\"}}", where);
  for (const auto& [key, value] : j.items())
    if (key != "theta_deg" && key != "phi_deg" && key != "cone_deg")
      ThrowBadInput("{}: unknown key '{}' (allowed: theta_deg, phi_deg, cone_deg)", where, key);
  auto number = [&](const char* key, double fallback) {
    if (!j.contains(key)) return fallback;
    if (!j[key].is_number()) ThrowBadInput("{}: '{}' must be a number", where, key);
    const double v = j[key].get<double>();
    if (!std::isfinite(v)) ThrowBadInput("{}: '{}' must be finite", where, key);
    return v;
  };
  if (!j.contains("theta_deg")) ThrowBadInput("{}: 'theta_deg' is required", where);
  const double theta = number("theta_deg", 0), phi = number("phi_deg", 0), cone = number("cone_deg", 0);
  if (theta < 0 || theta > 90) ThrowBadInput("{}: theta_deg {} is outside [0, 90]", where, theta);
  if (cone < 0 || cone > 180) ThrowBadInput("{}: cone_deg {} is outside [0, 180]", where, cone);
  return {DirectionFromAngles(DegToRad(theta), DegToRad(phi)), DegToRad(cone)};
}

std::vector<DirectionCone> ParseCones(const nlohmann::json& j, const std::string& where) {
  if (j.is_string() && j.get<std::string>() == "all") return {};
  if (!j.is_array() || j.empty()) ThrowBadInput("{}: must be \"all\" or a non-empty array of cones", where);
  std::vector<DirectionCone> cones;
  for (std::size_t i = 0; i < j.size(); ++i) cones.push_back(ParseCone(j[i], fmt::format("{}[{}]", where, i)));
  return cones;
}

nlohmann::json ConesJson(const std::vector<DirectionCone>& cones) {
  if (cones.empty()) return "all";
  nlohmann::json a = nlohmann::json::array();
  for (const auto& c : cones) {
    const Angles an = AnglesFromDirection(c.direction);
    a.push_back({{"theta_deg", RadToDeg(an.theta)}, {"phi_deg", RadToDeg(an.phi)}, {"cone_deg", RadToDeg(c.half_angle)}});
  }
  return a;
}

}  // namespace

SceneSpec SceneSpec::FromJson(const nlohmann::json& j, const std::string& source) {
  if (!j.is_object()) ThrowBadInput("scene '{}': must be a JSON object", source);
  SceneSpec s;
  for (const auto& [key, value] : j.items()) {
    const std::string where = fmt::format("scene '{}': '{}'", source, key);
    if (key == "format" || key == "comment") continue;
    if (key == "views") {
      s.views = ParseCones(value, where);
    } else if (key == "lights") {
      s.lights = ParseCones(value, where);
    } else if (key == "mip_level") {
      if (!value.is_number_integer() || value.get<int>() < 0 || value.get<int>() > 16)
        ThrowBadInput("{}: must be an integer 0..16", where);
      s.mip_level = value.get<int>();
    } else if (key == "channels") {
      if (value.is_string() && value.get<std::string>() == "all") continue;
      if (!value.is_array() || value.empty()) ThrowBadInput("{}: must be \"all\" or a non-empty array of names", where);
      for (const auto& c : value) {
        if (!c.is_string()) ThrowBadInput("{}: channel names must be strings", where);
        s.channels.push_back(c.get<std::string>());
      }
    } else if (key == "max_relative_error") {
      if (!value.is_number() || !(value.get<double>() >= 0) || value.get<double>() >= 1)
        ThrowBadInput("{}: must be a number in [0, 1)", where);
      s.max_relative_error = value.get<double>();
    } else {
      ThrowBadInput("{}: unknown key (allowed: views, lights, mip_level, channels, max_relative_error, comment)",
                    where);
    }
  }
  return s;
}

SceneSpec SceneSpec::Load(const std::filesystem::path& path) {
  const nlohmann::json j = nlohmann::json::parse(ReadFileBytes(path, "scene file"), nullptr, false);
  if (j.is_discarded()) ThrowBadInput("scene '{}' is not valid JSON", path.string());
  return FromJson(j, path.string());
}

nlohmann::json SceneSpec::ToJson() const {
  nlohmann::json j;
  j["views"] = ConesJson(views);
  j["lights"] = ConesJson(lights);
  j["mip_level"] = mip_level;
  j["channels"] = channels.empty() ? nlohmann::json("all") : nlohmann::json(channels);
  j["max_relative_error"] = max_relative_error;
  return j;
}

std::vector<int> NeededDirections(const Sampling& sampling, const std::vector<DirectionCone>& cones) {
  std::vector<int> all(static_cast<std::size_t>(sampling.size()));
  for (int i = 0; i < sampling.size(); ++i) all[static_cast<std::size_t>(i)] = i;
  if (cones.empty()) return all;
  std::set<int> used;
  auto add = [&](const Vec3& d) {
    if (d.z() < 0) return;  // below the horizon: not a direction the BTF describes
    const Interpolant ip = sampling.Barycentric(d);
    for (int k = 0; k < ip.count; ++k)
      if (ip.count == 1 || ip.weight[static_cast<std::size_t>(k)] > 0) used.insert(ip.index[static_cast<std::size_t>(k)]);
  };
  for (const auto& cone : cones) {
    const Vec3 axis = cone.direction.normalized();
    add(axis);
    if (cone.half_angle <= 0) continue;
    // Orthonormal frame around the axis.
    const Vec3 helper = std::abs(axis.z()) < 0.9 ? Vec3(0, 0, 1) : Vec3(1, 0, 0);
    const Vec3 a = axis.cross(helper).normalized(), b = axis.cross(a);
    for (int ring = 1; ring <= 4; ++ring) {
      const double t = cone.half_angle * ring / 4.0;
      for (int k = 0; k < 24; ++k) {
        const double p = 2 * kPi * k / 24.0;
        add(std::cos(t) * axis + std::sin(t) * (std::cos(p) * a + std::sin(p) * b));
      }
    }
  }
  return {used.begin(), used.end()};
}

namespace {

// Keeps only what the scene uses: view/light subsets, a mip level (box filter over 2^m x 2^m
// texels; trailing rows/columns that do not fill a block are dropped), a channel subset.
class SceneSlotSource final : public SlotSource {
 public:
  SceneSlotSource(const SlotSource& in, const SceneSpec& scene)
      : in_(in),
        view_index_(NeededDirections(in.views(), scene.views)),
        light_index_(NeededDirections(in.lights(), scene.lights)),
        block_(1 << scene.mip_level) {
    const DatasetInfo in_info = in.info();
    if (scene.channels.empty()) {
      channel_index_.resize(static_cast<std::size_t>(in.channels()));
      std::iota(channel_index_.begin(), channel_index_.end(), 0);
    } else {
      for (const auto& name : scene.channels) {
        const auto it = std::find(in_info.channel_names.begin(), in_info.channel_names.end(), name);
        if (it == in_info.channel_names.end())
          ThrowBadInput("scene names channel '{}', which '{}' does not have (channels: {})", name, in.name(),
                        fmt::join(in_info.channel_names, ","));
        channel_index_.push_back(static_cast<int>(it - in_info.channel_names.begin()));
      }
    }
    if (in.height() < block_ || in.width() < block_)
      ThrowBadInput("scene mip level {} needs at least {} x {} texels; '{}' has {} x {}", scene.mip_level, block_,
                    block_, in.name(), in.width(), in.height());
    views_ = in.views().Subset(view_index_);
    lights_ = in.lights().Subset(light_index_);
    info_ = in_info;
    info_.channel_names.clear();
    for (int c : channel_index_) info_.channel_names.push_back(in_info.channel_names[static_cast<std::size_t>(c)]);
    info_.texel_size_mm = in_info.texel_size_mm * block_;
  }
  const std::string& name() const override { return in_.name(); }
  std::string kind() const override { return in_.kind(); }
  const Sampling& views() const override { return views_; }
  const Sampling& lights() const override { return lights_; }
  int height() const override { return in_.height() / block_; }
  int width() const override { return in_.width() / block_; }
  int channels() const override { return static_cast<int>(channel_index_.size()); }
  DatasetInfo info() const override { return info_; }
  void ReadViewSlot(int v, float* dst) const override {
    std::vector<float> buf(in_.slot_size());
    in_.ReadViewSlot(view_index_[static_cast<std::size_t>(v)], buf.data());
    const int b = block_, H = height(), W = width(), C = channels(), iW = in_.width(), iC = in_.channels();
    const double norm = 1.0 / (double(b) * b);
    for (std::size_t l = 0; l < light_index_.size(); ++l) {
      const float* img = &buf[std::size_t(light_index_[l]) * in_.image_size()];
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          for (int c = 0; c < C; ++c) {
            double s = 0;
            for (int dy = 0; dy < b; ++dy)
              for (int dx = 0; dx < b; ++dx)
                s += img[(std::size_t(y * b + dy) * iW + (x * b + dx)) * iC +
                         channel_index_[static_cast<std::size_t>(c)]];
            dst[((l * H + y) * std::size_t(W) + x) * C + c] = static_cast<float>(s * norm);
          }
    }
  }

 private:
  const SlotSource& in_;
  std::vector<int> view_index_, light_index_, channel_index_;
  int block_;
  Sampling views_, lights_;
  DatasetInfo info_;
};

}  // namespace

std::unique_ptr<SlotSource> MakeSceneSource(const SlotSource& input, const SceneSpec& scene) {
  return std::make_unique<SceneSlotSource>(input, scene);
}

}  // namespace btf
