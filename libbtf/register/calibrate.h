#pragma once
// Camera calibration from photos of a board (btf-register calibrate): markers detected as in
// registration, every detected corner of a board marker (of a ChArUco board: every chessboard
// corner, DetectCharucoCorners, with charuco_corners) paired with its plate position, then
// OpenCV's calibrateCamera (radtan: k1, k2, p1, p2, k3) or cv::fisheye::calibrate (k1..k4).
// Pixel convention: OpenCV's (as detection), so fx, fy, cx, cy are directly OpenCV's.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/register/detect.h"

namespace btf {

struct CalibrateOptions {
  std::string model = "radtan";   // "radtan" (OpenCV calibrateCamera, 5 coefficients) or "fisheye"
  TagDetectorOptions detector;    // family and border_bits: the board's unless family_override
  bool family_override = false;
  ImageReadOptions input;         // decoding of integer photos (a manifest's transfer is used when "auto")
  int min_markers = 4;            // photos with fewer board markers found are left out (named in the summary)
  bool charuco_corners = false;   // a ChArUco board: calibrate on its chessboard corners (DetectCharucoCorners)
                                  // instead of its markers' corners (off: less precise today, docs/btf-register.md)
  int min_corners = 8;            // photos with fewer corners (marker or chessboard) found are left out
  int min_views = 3;              // fewer usable photos: btf::Error (bad input)
  double outlier_factor = 3;      // a photo whose RMS exceeds this x the median (and 0.2 px) is named an outlier
  // Outlier photos are left out and the camera fitted again without them (up to 3 refits, while
  // at least min_views photos remain); false keeps them in the fit, only named.
  bool drop_outliers = true;
  void Check() const;
};

struct CalibrationView {
  std::string file;
  bool used = false;
  std::string error;      // why the photo was left out
  int markers = 0;        // board markers found
  int corners = 0;        // corners paired with the board (4 per marker, or ChArUco chessboard corners)
  double rms_px = 0;      // reprojection RMS of this photo's corners (a dropped photo: in the fit it left)
  bool outlier = false;
  bool dropped = false;   // an outlier left out of the final fit (used is then false)
};

struct CalibrateSummary {
  CameraFile camera;      // intrinsics and rms_px over all used corners
  std::vector<CalibrationView> views;
  int views_used = 0, corners_used = 0;
  int refits = 0;         // fits again after dropping outliers
  PhaseTimes times;
  std::vector<std::string> Outliers() const;
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// `inputs`: image files and/or manifest.json files (their photos, relative to the manifest's
// folder; the manifest's camera is ignored). All photos must have the same size.
// Throws btf::Error (bad input) naming the inputs when fewer than min_views photos are usable.
CalibrateSummary CalibrateCamera(const CalibrateOptions& options, const std::vector<std::filesystem::path>& inputs,
                                 const Board& board, const Reporter& reporter = {});

}  // namespace btf
