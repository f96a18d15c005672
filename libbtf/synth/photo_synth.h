#pragma once
// Synthetic measurement photos: a sample plate (material in the middle, a ring of AprilTag
// markers around it) seen by a pinhole camera from each view direction under a directional or
// point light from each light direction. Writes the photos, board.json, manifest.json and
// truth.json (libbtf/io/rig.h, docs/format.md).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/synth/model.h"

namespace btf {

struct PhotoOptions {
  Sampling views = Sampling::Bonn81();   // the full view sampling (indices refer to it)
  Sampling lights = Sampling::Bonn81();  // the full light sampling
  std::vector<int> view_indices;         // empty = all views
  std::vector<int> light_indices;        // empty = all lights
  int max_photos = 0;                    // 0 = every (view, light) pair; else an even spread
  // Plate and markers.
  double sample_tiles = 10;       // sample region side in tiles (side = sample_tiles * tile_mm)
  double module_mm = 0;           // marker module size; 0 = sample side / 20
  double marker_height_mm = 0;    // marker plane above the material surface
  std::string family = "tag36h11";
  std::string target = "ring";    // "ring": the sample with 8 markers around it; "aprilgrid": a Kalibr
                                  // AprilGrid, "charuco": a ChArUco board (both: no sample; a calibration target)
  int border_bits = 0;            // black tag border, modules; 0 = 1 (ring) or 2 (aprilgrid, as Kalibr)
  int grid_rows = 6, grid_cols = 6;  // aprilgrid: tags
  double grid_tag_mm = 0;         // aprilgrid: tag side; 0 = the grid spans 85 % of min(width, height) at 0 deg
                                  // when focal is given, else 88 mm (Kalibr's 6 x 6 grid)
  double grid_spacing = 0.3;      // aprilgrid: gap / tag side (Kalibr tagSpacing)
  // target "charuco": an OpenCV 4.6 ChArUco board (CharucoBoard::create's layout: an ArUco marker in
  // every white square; no sample; a calibration target).
  int charuco_squares_x = 9, charuco_squares_y = 7;  // chessboard squares across and down
  double charuco_square_mm = 0;   // square side; 0 = the board spans 85 % of the image at 0 deg with focal, else 20
  double charuco_marker_mm = 0;   // marker side; 0 = 0.75 x the square side
  std::string charuco_dictionary = "DICT_5X5_100";  // DICT_4X4_50 .. DICT_7X7_1000 or DICT_ARUCO_ORIGINAL
  double irregularity = 0;        // PatternWarp RMS displacement, tiles (as btf-synth btf)
  std::uint64_t irregularity_seed = 7;
  // Camera.
  int width = 1280, height = 960;
  double camera_distance_mm = 500;
  double focal_px = 0;            // 0 = the plate fills 90 % of the image height at 0 deg
  double pixel_aspect = 1;        // fy / fx (non-square pixels: fx = focal, fy = pixel_aspect x focal)
  std::string lens = "radtan";    // lens model: "radtan" (k1, k2 below) or "fisheye" (OpenCV cv::fisheye, fisheye_k)
  double k1 = 0, k2 = 0;          // radtan: radial distortion (OpenCV model)
  std::vector<double> fisheye_k = {0, 0, 0, 0};  // fisheye: k1..k4, theta_d = theta (1 + k1 theta^2 + .. + k4 theta^8)
  int pixel_samples = 3;          // per axis, box filter over the pixel
  std::string psf = "gaussian";   // optical blur (PSF) applied to the radiance image: "gaussian" (sigma blur_px)
                                  // or "disc" (uniform over a disc of radius disc_radius_px: defocus)
  double blur_px = 0;             // Gaussian PSF sigma, px (0 = none)
  double disc_radius_px = 0;      // disc PSF radius, px (psf "disc": > 0)
  // Light.
  double light_distance_mm = 0;   // 0 = directional
  double light_intensity = 0;     // 0 = 1 (directional) or distance^2 (point: irradiance 1 at the center)
  bool true_directions = false;   // evaluate the BTF with per-point directions (default: nominal)
  // Sensor.
  std::string format = "png16";   // "png16", "png8", "jpeg" (8 bit) or "exr"
  std::string transfer = "linear";  // integer encoding: "linear" or "srgb" (the sRGB curve, tagged in the file)
  int jpeg_quality = 90;          // with format jpeg, 1..100
  double exposure = 0;            // 0 = auto: brightest pixel at 0.9 of full scale (1 for exr)
  std::vector<double> brackets;   // exposure bracket: factors on the exposure, one photo each (empty = one
                                  // photo); values clip at the white level (full scale), as on a sensor
  double response_gamma = 0;      // camera response (0 = none): code = bias(min(1, x)^(1 / gamma)), 8-bit formats
  double response_bias = 0.5;     // Schlick's bias(y) = y / ((1 / b - 2) (1 - y) + 1); 0.5 = no bias
  double noise = 0;               // Gaussian read noise, SD as a fraction of full scale
  // Lens and sensor non-uniformity, with reference photos written beside the photos (dark.EXT,
  // flat.EXT; named in the manifest) when set:
  double vignetting = 0;          // relative illumination 1 - vignetting (r / r_corner)^2 (r from the image center)
  double dark_level = 0;          // black level: dark(x, y) = dark_level (0.5 + u(x, y)), u a fixed
                                  // pattern uniform in [0, 1), as a fraction of full scale
  std::uint64_t seed = 1;         // noise seed
  void Check() const;
};

struct PhotoSummary {
  int photos = 0;
  std::vector<std::string> files;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;  // one line: photos, time per photo
};

// The plate layout for a model's tile size (8 markers in a ring, ids 0..7, upright).
Board MakeBoard(const PhotoOptions& options, double tile_mm);

// A camera at `view_dir` x distance looking at the plate center (image up ~ plate +y).
struct CameraPose {
  CameraModel camera;
  Eigen::Matrix3d camera_from_plate_rotation;  // camera_from_plate
  Vec3 camera_from_plate_translation;          // camera_from_plate, mm
  Vec3 center;               // camera center in plate mm
  // Plate point (mm) -> pixel (OpenCV convention), distortion applied. False if behind the camera.
  bool Project(const Vec3& plate_point, Vec2* pixel) const;
  // The z = 0 homography plate mm -> undistorted pixels.
  Eigen::Matrix3d PlateHomography() const;
};
CameraPose MakeCamera(const PhotoOptions& options, const Board& board, const Vec3& view_dir);

// Radiance image (linear float RGB, before exposure) of the plate for one view and light.
Image RenderPhoto(const SvbrdfModel& model, const Board& board, const PhotoOptions& options, const CameraPose& cam,
                  const Vec3& view_dir, const Vec3& light_dir);

// The (view index, light index) pairs to shoot: the subsets, then the even spread.
std::vector<std::pair<int, int>> SelectPhotos(const PhotoOptions& options);

// Renders and writes the whole set into the folder `dir`, atomically as a whole (AtomicDirectory:
// an existing earlier set is replaced only once the new one is complete).
PhotoSummary SynthesizePhotos(const PhotoOptions& options, const SvbrdfModel& model, const std::filesystem::path& dir,
                              const Reporter& reporter = {}, const nlohmann::json& extra = {});

}  // namespace btf
