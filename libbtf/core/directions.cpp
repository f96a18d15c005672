#include "libbtf/core/directions.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <Eigen/Dense>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"

namespace btf {

Vec3 DirectionFromAngles(double theta, double phi) {
  const double s = std::sin(theta);
  return {s * std::cos(phi), s * std::sin(phi), std::cos(theta)};
}

Angles AnglesFromDirection(const Vec3& d) {
  const double rxy = std::hypot(d.x(), d.y());
  Angles a;
  a.theta = std::atan2(rxy, d.z());  // stable near the pole, unlike acos(z)
  a.phi = rxy > 0 ? std::atan2(d.y(), d.x()) : 0.0;
  return a;
}

Vec3 HalfVector(const Vec3& wi, const Vec3& wo) {
  const Vec3 h = wi + wo;
  const double n = h.norm();
  if (!(n > 1e-12)) return Vec3::UnitZ();
  return h / n;
}

Vec3 DifferenceVector(const Vec3& wi, const Vec3& wo) {
  const Vec3 h = HalfVector(wi, wo);
  const Angles ah = AnglesFromDirection(h);
  // Rotate wi by -phi_h about z, then by -theta_h about y.
  const double cp = std::cos(-ah.phi), sp = std::sin(-ah.phi);
  const Vec3 a(cp * wi.x() - sp * wi.y(), sp * wi.x() + cp * wi.y(), wi.z());
  const double ct = std::cos(-ah.theta), st = std::sin(-ah.theta);
  return {ct * a.x() + st * a.z(), a.y(), -st * a.x() + ct * a.z()};
}

Vec2 ConcentricSquareToDisk(const Vec2& st) {
  const double a = 2 * st.x() - 1, b = 2 * st.y() - 1;
  if (a == 0 && b == 0) return {0, 0};
  double r, phi;
  if (std::abs(a) > std::abs(b)) {
    r = a;
    phi = (kPi / 4) * (b / a);
  } else {
    r = b;
    phi = kPi / 2 - (kPi / 4) * (a / b);
  }
  return {r * std::cos(phi), r * std::sin(phi)};
}

Vec2 ConcentricDiskToSquare(const Vec2& xy) {
  const double r = std::hypot(xy.x(), xy.y());
  if (r == 0) return {0.5, 0.5};
  double phi = std::atan2(xy.y(), xy.x());
  if (phi < -kPi / 4) phi += 2 * kPi;
  double a, b;
  if (phi < kPi / 4) {
    a = r;
    b = a * phi / (kPi / 4);
  } else if (phi < 3 * kPi / 4) {
    b = r;
    a = -b * (phi - kPi / 2) / (kPi / 4);
  } else if (phi < 5 * kPi / 4) {
    a = -r;
    b = a * (phi - kPi) / (kPi / 4);
  } else {
    b = -r;
    a = -b * (phi - 3 * kPi / 2) / (kPi / 4);
  }
  return {(a + 1) / 2, (b + 1) / 2};
}

namespace {

// Schneider 2004 section 6.1 "elevated" lift: equal-area disk <-> upper hemisphere (z = 1 - rho^2).
Vec3 HemisphereFromDisk(const Vec2& xy) {
  const double rho2 = std::min(1.0, xy.squaredNorm());
  const double s = std::sqrt(2 - rho2);
  return {xy.x() * s, xy.y() * s, 1 - rho2};
}

Vec2 DiskFromHemisphere(const Vec3& w_in) {
  // Directions below the horizon are projected onto it (documented in conventions.md).
  Vec3 w = w_in.normalized();
  if (w.z() < 0) {
    const double rxy = std::hypot(w.x(), w.y());
    w = rxy > 0 ? Vec3(w.x() / rxy, w.y() / rxy, 0) : Vec3::UnitZ();
  }
  return Vec2(w.x(), w.y()) / std::sqrt(1 + w.z());
}

}  // namespace

Vec3 HemisphereFromSquare(const Vec2& st) { return HemisphereFromDisk(ConcentricSquareToDisk(st)); }
Vec2 SquareFromHemisphere(const Vec3& w) { return ConcentricDiskToSquare(DiskFromHemisphere(w)); }

Sampling::Sampling(std::string name, std::vector<Vec3> directions)
    : name_(std::move(name)), dirs_(std::move(directions)) {
  for (auto& d : dirs_) {
    const double n = d.norm();
    if (!(n > 0) || !std::isfinite(n)) ThrowBadInput("sampling '{}': direction with zero or non-finite length", name_);
    d /= n;
  }
}

namespace {
Sampling FromRings(const std::string& name, const std::vector<double>& theta_deg, const std::vector<int>& count,
                   const std::vector<double>& offset_deg) {
  std::vector<Vec3> dirs;
  for (std::size_t r = 0; r < theta_deg.size(); ++r)
    for (int k = 0; k < count[r]; ++k)
      dirs.push_back(DirectionFromAngles(DegToRad(theta_deg[r]), DegToRad(offset_deg[r] + k * 360.0 / count[r])));
  return Sampling(name, std::move(dirs));
}
}  // namespace

Sampling Sampling::Bonn81() {
  return FromRings("bonn81", {0, 15, 30, 45, 60, 75}, {1, 6, 12, 18, 20, 24}, {0, 0, 0, 0, 0, 0});
}

Sampling Sampling::Ubo151() {
  return FromRings("ubo151", {0, 11, 23.5, 30, 37.5, 45, 52.5, 60, 67.5, 75}, {1, 6, 12, 12, 12, 18, 18, 24, 24, 24},
                   {0, 15, 0, 15, 0, 0, 7.5, 0, 7.5, 0});
}

Sampling Sampling::Single(const Vec3& direction) { return Sampling("single", {direction}); }

Sampling Sampling::FromFile(const std::filesystem::path& path) {
  std::istringstream in(ReadFileBytes(path, "direction list"));
  std::vector<Vec3> dirs;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    double t, p;
    if (!(ls >> t)) continue;  // blank or comment line
    std::string rest;
    if (!(ls >> p) || (ls >> rest))
      ThrowBadInput("direction list '{}', line {}: expected two numbers 'theta_deg phi_deg'", path.string(), line_no);
    if (!std::isfinite(t) || !std::isfinite(p) || t < 0 || t > 90)
      ThrowBadInput("direction list '{}', line {}: theta {} deg outside [0, 90]", path.string(), line_no, t);
    dirs.push_back(DirectionFromAngles(DegToRad(t), DegToRad(p)));
  }
  if (dirs.empty()) ThrowBadInput("direction list '{}' holds no directions", path.string());
  return Sampling("file:" + path.filename().string(), std::move(dirs));
}

Sampling Sampling::Named(const std::string& name_or_path) {
  if (name_or_path == "bonn81") return Bonn81();
  if (name_or_path == "ubo151") return Ubo151();
  if (std::filesystem::exists(name_or_path)) return FromFile(name_or_path);
  ThrowUsage("unknown direction sampling '{}': use bonn81, ubo151 or the path of a 'theta_deg phi_deg' list",
             name_or_path);
}

int Sampling::Nearest(const Vec3& d) const {
  int best = 0;
  double best_dot = -2;
  for (int i = 0; i < size(); ++i) {
    const double c = dirs_[static_cast<std::size_t>(i)].dot(d);
    if (c > best_dot) best_dot = c, best = i;
  }
  return best;
}

Interpolant Sampling::Barycentric(const Vec3& d_in) const {
  Interpolant r;
  const Vec3 d = d_in.normalized();
  if (size() < 3) {
    r.index[0] = Nearest(d);
    return r;
  }
  // Three largest dot products.
  std::array<int, 3> idx{-1, -1, -1};
  std::array<double, 3> dots{-3, -3, -3};
  for (int i = 0; i < size(); ++i) {
    double c = dirs_[static_cast<std::size_t>(i)].dot(d);
    int j = i;
    for (int k = 0; k < 3; ++k)
      if (c > dots[k]) {
        std::swap(c, dots[k]);
        std::swap(j, idx[k]);
      }
  }
  Eigen::Matrix3d m;
  for (int k = 0; k < 3; ++k) m.col(k) = dirs_[static_cast<std::size_t>(idx[k])];
  // Barycentric coordinates of the ray through d on the plane of the three points:
  // solve m a = d, then normalize a to sum 1 (the ray/plane intersection).
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(m);
  Eigen::Vector3d a = lu.isInvertible() ? Eigen::Vector3d(lu.solve(d)) : Eigen::Vector3d(1, 0, 0);
  for (int k = 0; k < 3; ++k) a[k] = std::max(0.0, a[k]);
  const double sum = a.sum();
  if (!(sum > 0) || !std::isfinite(sum)) a = Eigen::Vector3d(1, 0, 0);
  else a /= sum;
  r.count = 3;
  for (int k = 0; k < 3; ++k) r.index[k] = idx[k], r.weight[k] = a[k];
  return r;
}

Sampling Sampling::Subset(const std::vector<int>& indices) const {
  std::vector<Vec3> dirs;
  std::string name = name_ + "[";
  for (std::size_t k = 0; k < indices.size(); ++k) {
    const int i = indices[k];
    if (i < 0 || i >= size()) ThrowUsage("direction index {} out of range for sampling '{}' ({} directions)", i, name_, size());
    dirs.push_back(dirs_[static_cast<std::size_t>(i)]);
    name += (k ? "," : "") + std::to_string(i);
  }
  return Sampling(name + "]", std::move(dirs));
}

}  // namespace btf
