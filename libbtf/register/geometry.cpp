#include "libbtf/register/geometry.h"

#include <cmath>
#include <map>

#include <Eigen/LU>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "libbtf/core/error.h"

namespace btf {

void GeometryOptions::Check() const {
  BTF_CHECK_OPTION(min_markers >= 1, "min_markers", ">= 1");
  BTF_CHECK_OPTION(std::isfinite(ransac_threshold_px) && ransac_threshold_px > 0, "ransac_threshold_px", "> 0");
  BTF_CHECK_OPTION(std::isfinite(max_rms_px) && max_rms_px > 0, "max_rms_px", "> 0");
}

bool PhotoGeometry::Project(const Vec3& p, Vec2* px) const {
  if (!has_pose) {
    const Vec3 h = image_from_plate * Vec3(p.x(), p.y(), 1.0);
    if (!(h.z() > 0)) return false;
    *px = h.head<2>() / h.z();
    return true;
  }
  return ProjectToPixel(camera, camera_from_plate_rotation, camera_from_plate_translation, p, px);
}

namespace {

struct MarkerUse {
  const TagDetection* det;
  const Marker* marker;
};

// The detections of board markers, each with its marker (a duplicate id fails; an id not on the
// board is ignored with a warning); at least min_markers of them.
std::vector<MarkerUse> MatchBoardMarkers(const Board& board, const std::vector<TagDetection>& detections,
                                         const GeometryOptions& options, std::vector<std::string>* warnings) {
  std::map<int, const Marker*> by_id;
  for (const auto& m : board.markers) by_id[m.id] = &m;
  std::map<int, int> seen;
  for (const auto& d : detections) ++seen[d.id];
  for (const auto& [id, n] : seen)
    if (n > 1)
      ThrowBadInput("marker id {} detected {} times: two boards in view or a misprinted marker; remove the duplicate",
                    id, n);
  std::vector<MarkerUse> uses;
  for (const auto& d : detections) {
    auto it = by_id.find(d.id);
    if (it == by_id.end()) {
      if (warnings) warnings->push_back(fmt::format("marker id {} is not on the board: ignored", d.id));
      continue;
    }
    uses.push_back({&d, it->second});
  }
  if (static_cast<int>(uses.size()) < options.min_markers)
    ThrowBadInput("too few markers: {} of the board's {} found, at least {} needed", uses.size(), board.markers.size(),
                  options.min_markers);
  return uses;
}

// The camera matrix and distortion coefficients of a lens, as OpenCV takes them.
struct OpenCvLens {
  cv::Mat K, dist;
};

OpenCvLens LensOf(const CameraModel& camera) {
  OpenCvLens l;
  l.K = (cv::Mat_<double>(3, 3) << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
  if (camera.fisheye())
    l.dist = (cv::Mat_<double>(4, 1) << camera.k1, camera.k2, camera.k3, camera.k4);
  else if (camera.has_extended_distortion())
    l.dist = (cv::Mat_<double>(1, 5) << camera.k1, camera.k2, camera.p1, camera.p2, camera.k3);
  else
    l.dist = (cv::Mat_<double>(1, 4) << camera.k1, camera.k2, 0, 0);
  return l;
}

// The four corners of each used marker, marker by marker: on the plate (3D, and 2D for the
// homography) and in the photo (as detected, undistorted in float for the homography, and in
// double for the fisheye pose; without a lens the undistorted ones are the detected ones).
struct Corners {
  std::vector<cv::Point3d> plate3;
  std::vector<cv::Point2f> plate_xy;
  std::vector<cv::Point2d> image_px;
  std::vector<cv::Point2f> ideal;
  std::vector<cv::Point2d> und;  // with a lens only
  bool nonzero_height = false;
};

Corners CollectCorners(const std::vector<MarkerUse>& uses, const CameraModel* camera, const OpenCvLens& lens) {
  Corners c;
  for (const auto& u : uses)
    for (int k = 0; k < 4; ++k) {
      c.plate_xy.emplace_back(static_cast<float>(u.marker->corners_mm[k].x()),
                              static_cast<float>(u.marker->corners_mm[k].y()));
      c.plate3.emplace_back(u.marker->corners_mm[k].x(), u.marker->corners_mm[k].y(), u.marker->height_mm);
      c.image_px.emplace_back(u.det->corners[k].x(), u.det->corners[k].y());
      c.nonzero_height |= u.marker->height_mm != 0;
    }
  // Undistorted pixels for the robust homography (RANSAC only screens outliers, notes 4.2).
  if (camera) {
    if (camera->fisheye())
      cv::fisheye::undistortPoints(c.image_px, c.und, lens.K, lens.dist, cv::noArray(), lens.K);
    else
      cv::undistortPoints(c.image_px, c.und, lens.K, lens.dist, cv::noArray(), lens.K);
    for (const auto& p : c.und) c.ideal.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y));
  } else {
    for (const auto& p : c.image_px) c.ideal.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y));
  }
  return c;
}

// The corners of the markers whose four corners all fit the robust homography (RANSAC mask);
// the others are listed in g->rejected_ids with a warning, the kept ones in g->used_ids.
Corners KeepConsistentMarkers(const std::vector<MarkerUse>& uses, const Corners& all,
                              const std::vector<unsigned char>& mask, const GeometryOptions& options, PhotoGeometry* g,
                              std::vector<std::string>* warnings) {
  Corners in;
  for (std::size_t i = 0; i < uses.size(); ++i) {
    bool ok = true;
    for (int k = 0; k < 4; ++k) ok &= mask[4 * i + k] != 0;
    if (!ok) {
      g->rejected_ids.push_back(uses[i].det->id);
      if (warnings)
        warnings->push_back(fmt::format("marker id {} rejected: its corners disagree with the other markers by more "
                                        "than {} px",
                                        uses[i].det->id, options.ransac_threshold_px));
      continue;
    }
    g->used_ids.push_back(uses[i].det->id);
    for (int k = 0; k < 4; ++k) {
      in.plate3.push_back(all.plate3[4 * i + k]);
      in.plate_xy.push_back(all.plate_xy[4 * i + k]);
      in.image_px.push_back(all.image_px[4 * i + k]);
      in.ideal.push_back(all.ideal[4 * i + k]);
      if (!all.und.empty()) in.und.push_back(all.und[4 * i + k]);
    }
  }
  if (static_cast<int>(g->used_ids.size()) < options.min_markers)
    ThrowBadInput("too few consistent markers: {} after rejecting outliers, at least {} needed", g->used_ids.size(),
                  options.min_markers);
  return in;
}

// The camera pose from the inlier corners, and its plane homography and reprojection RMS.
void FitPose(const Corners& in, const CameraModel& camera, const OpenCvLens& lens, PhotoGeometry* g) {
  g->has_pose = true;
  g->camera = camera;
  cv::Mat rvec, tvec;
  // SQPnP takes general 3D points (markers at different heights); then LM on all inlier corners.
  // OpenCV's PnP knows radtan only: a fisheye pose is fitted to the corners undistorted by
  // cv::fisheye::undistortPoints, without distortion.
  const bool fe = camera.fisheye();
  const std::vector<cv::Point2d>& pnp_px = fe ? in.und : in.image_px;
  const cv::Mat pnp_dist = fe ? cv::Mat() : lens.dist;
  if (!cv::solvePnP(in.plate3, pnp_px, lens.K, pnp_dist, rvec, tvec, false, cv::SOLVEPNP_SQPNP))
    ThrowBadInput("degenerate marker layout: the camera pose cannot be solved from {} corners", in.plate3.size());
  cv::solvePnPRefineLM(in.plate3, pnp_px, lens.K, pnp_dist, rvec, tvec);
  cv::Mat Rm;
  cv::Rodrigues(rvec, Rm);
  cv::cv2eigen(Rm, g->camera_from_plate_rotation);
  g->camera_from_plate_translation = Vec3(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  g->image_from_plate = PlaneHomography(g->camera, g->camera_from_plate_rotation, g->camera_from_plate_translation, 0.0);
  double ss = 0;
  for (std::size_t i = 0; i < in.plate3.size(); ++i) {
    Vec2 p;
    if (!g->Project(Vec3(in.plate3[i].x, in.plate3[i].y, in.plate3[i].z), &p))
      ThrowBadInput("degenerate pose: a marker corner lies behind the camera");
    ss += (p - Vec2(in.image_px[i].x, in.image_px[i].y)).squaredNorm();
  }
  g->rms_px = std::sqrt(ss / static_cast<double>(in.plate3.size()));
}

// Without intrinsics: the plate-to-image homography refitted on the inlier corners (least squares
// + LM, method 0), and its reprojection RMS.
void FitHomography(const Corners& in, PhotoGeometry* g) {
  cv::Mat H = cv::findHomography(in.plate_xy, in.ideal, 0);
  if (H.empty()) ThrowBadInput("degenerate marker layout: the homography refit failed");
  cv::cv2eigen(H, g->image_from_plate);
  g->image_from_plate /= g->image_from_plate(2, 2);
  double ss = 0;
  for (std::size_t i = 0; i < in.plate_xy.size(); ++i) {
    Vec2 p;
    if (!g->Project(Vec3(in.plate_xy[i].x, in.plate_xy[i].y, 0), &p))
      ThrowBadInput("degenerate homography: corner at infinity");
    ss += (p - Vec2(in.image_px[i].x, in.image_px[i].y)).squaredNorm();
  }
  g->rms_px = std::sqrt(ss / static_cast<double>(in.plate_xy.size()));
}

}  // namespace

PhotoGeometry EstimateGeometry(const Board& board, const std::vector<TagDetection>& detections,
                               const std::optional<CameraModel>& camera, const GeometryOptions& options,
                               std::vector<std::string>* warnings) {
  options.Check();
  const std::vector<MarkerUse> uses = MatchBoardMarkers(board, detections, options, warnings);
  const bool pose = camera.has_value() && camera->fx > 0 && camera->fy > 0;
  const OpenCvLens lens = pose ? LensOf(*camera) : OpenCvLens{};
  const Corners all = CollectCorners(uses, pose ? &*camera : nullptr, lens);
  std::vector<unsigned char> mask;
  cv::Mat Hr = cv::findHomography(all.plate_xy, all.ideal, cv::RANSAC, options.ransac_threshold_px, mask, 2000, 0.999);
  if (Hr.empty())
    ThrowBadInput("degenerate marker layout in the photo: no homography fits the {} corners", all.ideal.size());

  PhotoGeometry g;
  const Corners in = KeepConsistentMarkers(uses, all, mask, options, &g, warnings);
  g.corners_used = static_cast<int>(in.plate3.size());
  if (pose) {
    FitPose(in, *camera, lens, &g);
  } else {
    if (all.nonzero_height && warnings)
      warnings->push_back("markers sit above the material surface but no intrinsics are given: the marker-height "
                          "parallax is not compensated");
    FitHomography(in, &g);
  }
  if (!g.image_from_plate.allFinite() || std::abs(g.image_from_plate.determinant()) < 1e-12)
    ThrowBadInput("degenerate homography (singular or not finite)");
  if (!(g.rms_px <= options.max_rms_px))
    ThrowBadInput("reprojection RMS {:.3f} px exceeds the limit {} px: markers misdetected or the board does not match",
                  g.rms_px, options.max_rms_px);
  return g;
}

}  // namespace btf
