#pragma once
// Per-photo geometry: from detected marker corners and the board to a map plate (mm) -> pixels.
//
// With intrinsics (CameraModel with fx > 0): a full pose (camera_from_plate) from all inlier
// corners, each at its true 3D position (x, y, h) with h the marker's height above the material
// surface, so the map is evaluated at the material surface z = 0 and the marker-height parallax
// (about h tan(theta), notes 4.1) is removed. Lens distortion (radtan or fisheye) is modelled in the fit and
// in the map. Without intrinsics: one homography from the marker plane, marker height ignored
// (a warning says so when heights are non-zero).
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "libbtf/io/rig.h"
#include "libbtf/register/detect.h"

namespace btf {

struct GeometryOptions {
  int min_markers = 2;               // fewer usable markers fail the photo
  double ransac_threshold_px = 3.0;  // RANSAC (wrong ids, bad corners): inlier distance in px
  double max_rms_px = 1.0;           // larger reprojection RMS fails the photo (degenerate geometry)
  void Check() const;
};

// Plate (mm) -> pixel map of one photo, pixel centers at integer coordinates.
struct PhotoGeometry {
  bool has_pose = false;
  CameraModel camera;                                             // used when has_pose
  Eigen::Matrix3d camera_from_plate_rotation = Eigen::Matrix3d::Identity();         // camera_from_plate
  Vec3 camera_from_plate_translation = Vec3::Zero();                                // camera_from_plate, mm
  Eigen::Matrix3d image_from_plate = Eigen::Matrix3d::Identity();  // plate z = 0 -> undistorted px, h33 = 1
  double rms_px = 0;                                              // reprojection RMS over used corners
  int corners_used = 0;
  std::vector<int> used_ids, rejected_ids;                        // rejected: RANSAC outliers

  // Pixel of plate point (x, y, z) (mm, z above the material surface); with distortion.
  // Returns false if the point is behind the camera.
  bool Project(const Vec3& plate, Vec2* px) const;
};

// Throws btf::Error (bad input) with the reason when the photo cannot be registered: too few
// markers, duplicate ids, degenerate fit, RMS over the limit. `warnings` collects the rest.
PhotoGeometry EstimateGeometry(const Board& board, const std::vector<TagDetection>& detections,
                               const std::optional<CameraModel>& camera, const GeometryOptions& options,
                               std::vector<std::string>* warnings);

}  // namespace btf
