#pragma once
// What a scene needs from a BTF (scene.json, docs/btf-compress.md "Scene file"): the view and
// light directions (or cones of directions) that occur, the texel resolution (mip level) and the
// channels. Compression keeps only the sampled directions whose barycentric support reaches a
// used direction, the mip level's texels and the named channels.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"
#include "libbtf/io/slot_source.h"

namespace btf {

struct DirectionCone {
  Vec3 direction{0, 0, 1};  // unit, upper hemisphere
  double half_angle = 0;    // radians; 0 = just this direction
};

struct SceneSpec {
  std::vector<DirectionCone> views;   // empty = every view direction
  std::vector<DirectionCone> lights;  // empty = every light direction
  int mip_level = 0;                  // 0 = full resolution; m = 2^m x 2^m box-filtered texels
  std::vector<std::string> channels;  // empty = every channel; else names from the dataset
  double max_relative_error = 0;      // > 0: components are chosen for this relative RMS error

  // Parses the scene JSON; `source` names it in errors (bad input).
  static SceneSpec FromJson(const nlohmann::json& j, const std::string& source);
  static SceneSpec Load(const std::filesystem::path& path);
  nlohmann::json ToJson() const;
};

// Sorted indices of the sampled directions that interpolating any direction of the cones can
// touch (Sampling::Barycentric support of the cone's center and of points on rings at 1/4, 1/2,
// 3/4 and 1 of its half angle, 24 per ring, clipped to the upper hemisphere). Empty cones = all.
std::vector<int> NeededDirections(const Sampling& sampling, const std::vector<DirectionCone>& cones);

// `input` seen through a scene: only the views and lights it needs, at its mip level (a box
// filter over 2^m x 2^m texels; trailing rows and columns that do not fill a block are dropped),
// its channels. Refuses (bad input) channels the input lacks and a mip level it is too small for.
std::unique_ptr<SlotSource> MakeSceneSource(const SlotSource& input, const SceneSpec& scene);

}  // namespace btf
