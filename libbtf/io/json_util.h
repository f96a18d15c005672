#pragma once
// Eigen vectors and matrices as JSON arrays (rig files, registration reports).
#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace btf {

inline nlohmann::json ToJson(const Eigen::Vector2d& v) { return nlohmann::json::array({v.x(), v.y()}); }
inline nlohmann::json ToJson(const Eigen::Vector3d& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }
// Row-major: [[m00, m01, m02], ...].
inline nlohmann::json ToJson(const Eigen::Matrix3d& m) {
  nlohmann::json j = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) j.push_back(nlohmann::json::array({m(r, 0), m(r, 1), m(r, 2)}));
  return j;
}

}  // namespace btf
