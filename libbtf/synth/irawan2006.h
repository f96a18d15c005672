#pragma once
// Irawan & Marschner 2006 (Cornell PCG-06-01) ellipse BTF model, with its exact analytic BRDF.
//
//   L(p, wi, wo) = kd + ks * I(p, h) * F(theta_d) * G(wi, wo) / (cos_i cos_o)
//
// Each thread segment is an axis-aligned window (s_x, s_y) of a tile of W x H units. Inside it
// the highlight indicator I is 1 inside an ellipse whose center moves with the half vector:
// c = (s_x (k_x h_x + 1) / 2, s_y (k_y h_y + 1) / 2) (window origin at its lower-left corner).
// Choices the report leaves open (docs/btf-synth.md, "Irawan 2006"):
//  - every parameter and (h_x, h_y) is in the global tile frame (no per-weft rotation);
//  - Fresnel: exact unpolarised dielectric at cos(theta_d) = wi.h, index `ior` (or F = 1);
//  - G: V-groove Torrance-Sparrow min(1, 2(n.h)(n.wo)/(wo.h), 2(n.h)(n.wi)/(wo.h));
//  - kd is a BRDF value (albedo / pi), ks is a plain multiplier; no normalization.
#include <array>
#include <string>
#include <vector>

#include "libbtf/synth/model.h"

namespace btf {

// ---- Ellipse / window geometry (exposed for tests) -------------------------------------------

// Area of the unit-circle segment with central angle theta in [0, 2pi]: (theta - sin theta) / 2,
// by a series below theta = 1e-3 so that tiny caps keep full relative accuracy.
double CircularSegmentArea(double theta);

// Area of the unit disk inside a convex polygon given counter-clockwise, case-free: the signed
// sum over edges of area(disk ∩ triangle(O, P_k, P_k+1)). Continuous across tangencies.
double DiskPolygonArea(const std::vector<Vec2>& polygon);

// Roots t1 <= t2 of |a + t d|^2 = 1; false if the line misses or grazes the unit circle.
bool UnitCircleRoots(const Vec2& a, const Vec2& d, double* t1, double* t2);

struct EllipseSegment {
  std::string type;          // "warp" or "weft" (documentation; no frame change)
  double x0 = 0, y0 = 0;     // window lower-left corner in tile units (may wrap across the tile)
  double sx = 1, sy = 1;     // window size
  double alpha = 0.5;        // semi-major axis
  double eta = 0.9;          // eccentricity in [0, 1)
  double phi = 0;            // major-axis angle, radians, CCW from +x
  double kx = 1, ky = 1;     // center motion with the half vector
};

// The window [0,sx]x[0,sy]'s corners (counter-clockwise) in the frame where the segment's ellipse
// for the half-vector projection (hx, hy) is the unit disk.
std::array<Vec2, 4> EllipseWindowInDisk(const EllipseSegment& s, double hx, double hy);

// Area of the window [0,sx]x[0,sy] inside the segment's ellipse for the half-vector projection
// (hx, hy): alpha beta DiskPolygonArea(EllipseWindowInDisk(s, hx, hy)).
double EllipseWindowArea(const EllipseSegment& s, double hx, double hy);

struct Irawan2006Params {
  std::string preset = "twill";
  int tile_w = 4, tile_h = 8;  // tile size in units
  std::vector<EllipseSegment> segments;
  std::array<double, 3> kd{0.30 / kPi, 0.25 / kPi, 0.20 / kPi};  // BRDF values (1/sr)
  std::array<double, 3> ks{1.0, 1.0, 1.0};
  std::string fresnel = "dielectric";  // "dielectric" | "none"
  double ior = 1.5;
  double tile_mm = 4.0;  // physical tile side (square tile)
  // Checks consistency; throws btf::Error (usage) naming the field.
  void Check() const;
};

// Presets: "twill" (the report's parameters, 4x8 layout), "plain", "sateen" (ours).
Irawan2006Params Irawan2006Preset(const std::string& name);

class Irawan2006Model final : public SvbrdfModel {
 public:
  explicit Irawan2006Model(Irawan2006Params p);
  std::string name() const override { return "irawan2006/" + p_.preset; }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override;
  void EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* uv, int n, float* out) const override;
  void EvalBrdf(const Vec3& wi, const Vec3& wo, float* out) const override;
  nlohmann::json Describe() const override;
  double tile_size_mm() const override { return p_.tile_mm; }
  const Irawan2006Params& params() const { return p_; }

  // Fraction of the tile lit by highlights, S̄(h) = sum A_E / sum A_R (analytic).
  double HighlightFraction(const Vec3& wi, const Vec3& wo) const;
  // Direction-only factor ks-free: F G / (cos_i cos_o), 0 below the horizon.
  double SpecularFactor(const Vec3& wi, const Vec3& wo) const;

 private:
  struct Pair;  // per direction pair constants
  bool PrepareDirs(const Vec3& wi, const Vec3& wo, Pair& pr) const;
  void EvalPrepared(const Pair& pr, const Vec2& uv, float* out) const;
  // Index of the segment covering tile position (X, Y) in units and its local coordinates.
  int Locate(double X, double Y, double* lx, double* ly) const;

  Irawan2006Params p_;
  std::vector<int> cell_segment_;  // tile_w * tile_h unit cells -> segment index
};

}  // namespace btf
