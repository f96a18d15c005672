#pragma once
// Test-only renderer for registration: a pinhole camera looking at a plate with AprilTag markers
// (tag36h11, drawn from libapriltag's own code tables) lying at height h above a textured
// material surface z = 0. Pixels are area-integrated by k x k supersampling with ray casting, so
// marker parallax and foreshortening are exact. OpenCV pixel convention (centers at integers).
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>

#include <cmath>
#include <functional>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <memory>

#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/register/geometry.h"

namespace btf::test {

// Board: 8 tag36h11 markers (ids 0..7, detection square `tag_mm`) around a square sample.
inline Board MakeRingBoard(double sample_mm = 40, double tag_mm = 8, double height_mm = 0) {
  Board b;
  b.sample_size_mm = sample_mm;
  const double off = sample_mm / 2 + 2 + tag_mm / 2 + tag_mm / 8;  // center distance from origin (quiet zone)
  const double centers[8][2] = {{-off, -off}, {0, -off}, {off, -off}, {off, 0}, {off, off}, {0, off}, {-off, off}, {-off, 0}};
  for (int i = 0; i < 8; ++i) {
    Marker m;
    m.id = i;
    m.height_mm = height_mm;
    const double cx = centers[i][0], cy = centers[i][1], h = tag_mm / 2;
    m.corners_mm = {Vec2(cx - h, cy - h), Vec2(cx + h, cy - h), Vec2(cx + h, cy + h), Vec2(cx - h, cy + h)};
    b.markers.push_back(m);
  }
  return b;
}

struct TestCamera {
  CameraModel model;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // camera_from_plate
  Vec3 t = Vec3::Zero();
  PhotoGeometry Geometry() const {
    PhotoGeometry g;
    g.has_pose = true;
    g.camera = model;
    g.camera_from_plate_rotation = R;
    g.camera_from_plate_translation = t;
    g.image_from_plate = PlaneHomography(model, R, t, 0);
    return g;
  }
};

// Camera at `distance_mm` along the view direction (theta, phi in degrees) looking at the origin,
// image "down" as close to plate -y as possible.
inline TestCamera LookAt(double theta_deg, double phi_deg, double distance_mm, int width, int height, double f) {
  TestCamera c;
  c.model.width = width;
  c.model.height = height;
  c.model.fx = c.model.fy = f;
  c.model.cx = (width - 1) / 2.0;
  c.model.cy = (height - 1) / 2.0;
  const Vec3 w = DirectionFromAngles(DegToRad(theta_deg), DegToRad(phi_deg));
  const Vec3 z = -w;
  Vec3 down(0, -1, 0);
  if (std::abs(down.dot(z)) > 0.99) down = Vec3(1, 0, 0);
  const Vec3 y = (down - down.dot(z) * z).normalized();
  const Vec3 x = y.cross(z);
  c.R.row(0) = x.transpose();
  c.R.row(1) = y.transpose();
  c.R.row(2) = z.transpose();
  c.t = -c.R * (distance_mm * w);
  return c;
}

// Tag module value (0 black, 1 white) of `id` at tag coordinates (i, j) in 0..total_width-1
// (AprilTag's own layout: apriltag_to_image), for a non-reversed-border family.
class TagPainter {
 public:
  TagPainter() : fam_(tag36h11_create()) {}
  ~TagPainter() { tag36h11_destroy(fam_); }
  // Value at plate (x, y) if it falls on marker m's printed area (incl. white quiet module), else -1.
  double At(const Marker& m, double x, double y) const {
    // Upright tag: corners_mm[3] = left-top, [1] = right-bottom; square of 8 modules.
    const Vec2 lt = m.corners_mm[3], rb = m.corners_mm[1];
    const double mod = (rb.x() - lt.x()) / fam_->width_at_border;
    const double i = (x - lt.x()) / mod + 1, j = (lt.y() - y) / mod + 1;  // printed grid incl. 1 white module
    if (i < 0 || j < 0 || i >= fam_->total_width || j >= fam_->total_width) return -1;
    const int ii = static_cast<int>(i), jj = static_cast<int>(j);
    if (ii == 0 || jj == 0 || ii == fam_->total_width - 1 || jj == fam_->total_width - 1) return 1;  // quiet zone
    const int b = (fam_->total_width - fam_->width_at_border) / 2;                                     // = 1
    const uint64_t code = fam_->codes[m.id];
    for (uint32_t k = 0; k < fam_->nbits; ++k)
      if (static_cast<int>(fam_->bit_x[k]) + b == ii && static_cast<int>(fam_->bit_y[k]) + b == jj)
        return (code >> (fam_->nbits - k - 1)) & 1 ? 1.0 : 0.0;
    return 0;  // black border
  }

 private:
  apriltag_family_t* fam_;
};

// Renders one gray (1 channel) or RGB photo. `material(x, y)` gives the material value at the
// surface; the plate (z = marker height) is white (0.9) outside the sample; markers on top.
// Each pixel is probed with 5 rays; where they differ it is integrated with ss x ss rays
// (ss = 8 puts tag edges to ~0.01 px; 3 x 3 leaves ~0.08 px staircase errors at 60 deg).
inline Image RenderPhoto(const TestCamera& cam, const Board& board, const std::function<double(double, double)>& material,
                         int channels = 1, int ss = 8) {
  static const TagPainter painter;
  Image im(cam.model.width, cam.model.height, channels);
  const Eigen::Matrix3d Rt = cam.R.transpose();
  const Vec3 C = -Rt * cam.t;
  const double half = board.sample_size_mm / 2;
  const double h = board.markers.empty() ? 0 : board.markers[0].height_mm;
  const auto ray = [&](double u, double v) {
    const Vec3 d = Rt * Vec3((u - cam.model.cx) / cam.model.fx, (v - cam.model.cy) / cam.model.fy, 1.0);
    if (d.z() >= 0) return 0.05;  // background above the horizon
    // Plate top at z = h (markers, white carrier); the sample is a hole down to z = 0.
    const Vec3 ph = C + ((h - C.z()) / d.z()) * d;
    for (const auto& m : board.markers) {
      const double marker = painter.At(m, ph.x(), ph.y());
      if (marker >= 0) return 0.1 + 0.8 * marker;
    }
    if (std::abs(ph.x()) > half || std::abs(ph.y()) > half) return 0.9;
    const Vec3 p0 = C + (-C.z() / d.z()) * d;
    return material(p0.x(), p0.y());
  };
#pragma omp parallel for schedule(dynamic, 8)
  for (int py = 0; py < im.height; ++py)
    for (int px = 0; px < im.width; ++px) {
      // Probes at the pixel's 4 corners and center: a straight edge through the pixel separates
      // at least two corners, so uniform probes mean a uniform pixel (features >> 1 px).
      double probe[5], lo = 1e300, hi = -1e300;
      for (int k = 0; k < 5; ++k) {
        probe[k] = k == 4 ? ray(px, py) : ray(px - 0.5 + (k % 2), py - 0.5 + (k / 2));
        lo = std::min(lo, probe[k]);
        hi = std::max(hi, probe[k]);
      }
      double val = probe[4];
      if (hi - lo > 1e-12) {
        double acc = 0;
        for (int sy = 0; sy < ss; ++sy)
          for (int sx = 0; sx < ss; ++sx) acc += ray(px - 0.5 + (sx + 0.5) / ss, py - 0.5 + (sy + 0.5) / ss);
        val = acc / (ss * ss);
      }
      for (int c = 0; c < channels; ++c) im.at(px, py, c) = static_cast<float>(val);
    }
  return im;
}

}  // namespace btf::test
