#pragma once
// Directions on the upper hemisphere and the angular samplings a BTF is measured on.
//
// Frame (docs/conventions.md): z = surface normal, x = weft direction (texture u), y = warp
// direction (texture v); theta = polar angle from +z, phi = azimuth from +x counter-clockwise,
// both in radians. Direction = (sin t cos p, sin t sin p, cos t).
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace btf {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
constexpr double DegToRad(double d) { return d * kPi / 180.0; }
constexpr double RadToDeg(double r) { return r * 180.0 / kPi; }

struct Angles {
  double theta = 0;  // radians, [0, pi]
  double phi = 0;    // radians, (-pi, pi]
};

Vec3 DirectionFromAngles(double theta, double phi);
Angles AnglesFromDirection(const Vec3& d);  // d need not be normalized; phi = 0 at the poles

// Half vector (wi + wo) / |wi + wo|; returns +z when wi = -wo (undefined case, documented).
Vec3 HalfVector(const Vec3& wi, const Vec3& wo);
// Rusinkiewicz difference vector: wi expressed in the frame where the half vector is the pole.
Vec3 DifferenceVector(const Vec3& wi, const Vec3& wo);

// Shirley-Chiu concentric map between the unit square [0,1]^2 and the unit disk (equal area).
Vec2 ConcentricSquareToDisk(const Vec2& st);
Vec2 ConcentricDiskToSquare(const Vec2& xy);
// The concentric map composed with Schneider 2004 section 6.1 "elevated" lift, an equal-area map
// of the disk onto the upper hemisphere (z = 1 - rho^2): each square cell covers 2*pi*ds*dt sr.
Vec3 HemisphereFromSquare(const Vec2& st);
Vec2 SquareFromHemisphere(const Vec3& w);

// Up to three sampled directions and weights (>= 0, summing to 1) that interpolate a query.
struct Interpolant {
  std::array<int, 3> index{0, 0, 0};
  std::array<double, 3> weight{1, 0, 0};
  int count = 1;
};

// An ordered list of unit directions with a name ("bonn81", "ubo151" or "file:<path>").
class Sampling {
 public:
  Sampling() = default;
  Sampling(std::string name, std::vector<Vec3> directions);

  // "bonn81", "ubo151", or a path to a text file with one "theta_deg phi_deg" pair per line
  // ('#' starts a comment). Throws btf::Error (bad input / I/O) naming the file and line.
  static Sampling Named(const std::string& name_or_path);
  static Sampling Bonn81();
  static Sampling Ubo151();
  static Sampling FromFile(const std::filesystem::path& path);
  static Sampling Single(const Vec3& direction);

  const std::string& name() const { return name_; }
  int size() const { return static_cast<int>(dirs_.size()); }
  const Vec3& operator[](int i) const { return dirs_[static_cast<std::size_t>(i)]; }
  const std::vector<Vec3>& directions() const { return dirs_; }
  Angles angles(int i) const { return AnglesFromDirection(dirs_[static_cast<std::size_t>(i)]); }

  // Index of the sampled direction with the smallest angle to d.
  int Nearest(const Vec3& d) const;
  // The three nearest sampled directions with barycentric weights of d's projection onto their
  // plane, clamped to >= 0 and renormalized (weights sum to 1; exact at sampled directions).
  Interpolant Barycentric(const Vec3& d) const;

  // A subset (in the given order), named "<name>[i,j,...]".
  Sampling Subset(const std::vector<int>& indices) const;

 private:
  std::string name_;
  std::vector<Vec3> dirs_;
};

}  // namespace btf
