#pragma once
// Corner accuracy of `btf-register detect --json` output against btf-synth's truth.
#include <cmath>
#include <cstddef>

#include <nlohmann/json.hpp>

#include "libbtf/io/rig.h"

namespace btf::test {

// RMS distance (px) of the detected tag corners (det["tags"][i]["corners_px"]) from the truth's
// corners of the same tags; *found = detected tags the truth knows; 1e9 if there are none.
inline double CornerRms(const nlohmann::json& det, const PhotoTruth& truth, int* found) {
  double ss = 0;
  int n = 0;
  *found = 0;
  for (const auto& t : det["tags"]) {
    const auto it = truth.marker_corners_px.find(t["id"].get<int>());
    if (it == truth.marker_corners_px.end()) continue;
    ++*found;
    for (int k = 0; k < 4; ++k) {
      const Vec2 p(t["corners_px"][k][0].get<double>(), t["corners_px"][k][1].get<double>());
      ss += (p - it->second[static_cast<std::size_t>(k)]).squaredNorm();
      ++n;
    }
  }
  return n ? std::sqrt(ss / n) : 1e9;
}

}  // namespace btf::test
