#pragma once
// Test oracle for the Irawan 2006 highlight area: the report's five cases (case 4 as segment +
// triangle) of a unit disk clipped by a convex quadrilateral, written independently of the
// case-free DiskPolygonArea that libbtf uses.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "libbtf/synth/irawan2006.h"

namespace btf::test {

inline double Cross(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

// The five-case area for a convex quadrilateral given counter-clockwise. Returns NaN if the
// configuration is none of the five (which the "ellipse fits in the window" assumption excludes).
inline double DiskQuadAreaFiveCases(const std::array<Vec2, 4>& q, int* case_out = nullptr) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (case_out) *case_out = 0;
  std::array<bool, 4> inside{};
  int n_inside = 0;
  for (int k = 0; k < 4; ++k) n_inside += (inside[k] = q[k].squaredNorm() < 1);
  std::array<int, 4> hits{};
  std::array<Vec2, 4> first_hit;
  std::array<double, 4> dist{};  // signed distance of O from edge k's line, > 0 = O on the inner side
  int total = 0;
  for (int k = 0; k < 4; ++k) {
    const Vec2& a = q[k];
    const Vec2 d = q[(k + 1) % 4] - a;
    dist[k] = Cross(d, -a) / d.norm();
    double t1, t2;
    if (UnitCircleRoots(a, d, &t1, &t2)) {
      for (double t : {t1, t2})
        if (t > 0 && t < 1) {
          if (hits[k] == 0) first_hit[k] = a + t * d;
          ++hits[k];
        }
    }
    total += hits[k];
  }
  auto cap = [](double d) { return 2 * std::acos(std::clamp(d, -1.0, 1.0)); };  // cap angle beyond a line
  if (total == 0 && n_inside == 0) {
    const bool origin_in = std::all_of(dist.begin(), dist.end(), [](double d) { return d > 0; });
    if (case_out) *case_out = origin_in ? 1 : 5;
    return origin_in ? kPi : 0.0;
  }
  if (n_inside == 0 && total == 2) {
    for (int k = 0; k < 4; ++k)
      if (hits[k] == 2) {
        if (case_out) *case_out = 2;
        return CircularSegmentArea((2 * kPi) - cap(dist[k]));
      }
  }
  if (n_inside == 0 && total == 4) {
    for (int k = 0; k < 4; ++k) {
      const int k2 = (k + 1) % 4;
      if (hits[k] == 2 && hits[k2] == 2) {
        if (case_out) *case_out = 3;
        return kPi - CircularSegmentArea(cap(dist[k])) - CircularSegmentArea(cap(dist[k2]));
      }
    }
  }
  if (n_inside == 1 && total == 2) {
    for (int k = 0; k < 4; ++k) {
      const int k2 = (k + 1) % 4;  // shared corner of edges k and k2 is q[k2]
      if (hits[k] == 1 && hits[k2] == 1 && inside[k2]) {
        const Vec2 P = first_hit[k], Q = first_hit[k2], K = q[k2];
        const Vec2 chord = Q - P;
        const double len = chord.norm();
        if (len <= 0) return nan;
        // Signed distance of O from the chord line, positive when O lies away from K.
        const double side_k = Cross(chord, K - P), side_o = Cross(chord, -P);
        const double d = (side_k * side_o < 0 ? 1.0 : -1.0) * std::abs(side_o) / len;
        if (case_out) *case_out = 4;
        return CircularSegmentArea((2 * kPi) - cap(d)) + 0.5 * std::abs(Cross(P - K, Q - K));
      }
    }
  }
  return nan;
}

// EllipseWindowArea computed with the five cases.
inline double FiveCaseWindowArea(const EllipseSegment& s, double hx, double hy) {
  const double beta = s.alpha * std::sqrt((1 - s.eta) * (1 + s.eta));
  return s.alpha * beta * DiskQuadAreaFiveCases(EllipseWindowInDisk(s, hx, hy));
}

}  // namespace btf::test
