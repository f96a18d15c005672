#pragma once
// The measurement rig as files: board (marker layout), photo manifest, and ground truth
// (written by btf-synth photos, read by btf-register). Normative: docs/format.md.
//
// Plate frame: millimetres, origin at the center of the sample region, x right (= weft, texture
// u), y up (= warp, texture v), z towards the camera side; the material surface is z = 0 and a
// marker at height h lies in the plane z = h.
// Pixel convention: OpenCV's, pixel centers at integer coordinates, (0,0) = center of the
// top-left pixel, y down.
#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"

namespace btf {

// Board coordinates and sizes (mm) lie within +-kMaxBoardMm (1 km) of the origin; board readers
// refuse others (bad input) before any geometry is computed with them.
inline constexpr double kMaxBoardMm = 1e6;
// Kalibr target YAML: at most this many bytes, one flat mapping (docs/format.md, "Rig files").
inline constexpr std::size_t kMaxBoardYamlBytes = std::size_t(1) << 20;

struct Marker {
  int id = 0;
  // Corners in plate mm, in AprilTag's order for the upright tag: left-bottom, right-bottom,
  // right-top, left-top of the tag's detection square (the black border's outer edge).
  std::array<Vec2, 4> corners_mm;
  double height_mm = 0;  // height of the marker plane above the material surface
};

// A Kalibr AprilGrid (target_type: aprilgrid): tagRows x tagCols tags of side tagSize, tagSpacing x
// tagSize apart, tag 0 at the bottom left, ids row-major, black squares of the gap's size at the
// tags' corners. Our plate frame puts the origin at the grid's centre (Kalibr's: tag 0's
// bottom-left corner; a translation, which pose and calibration do not see).
struct AprilGrid {
  int rows = 0, cols = 0;     // 0 = not an AprilGrid
  double tag_size_mm = 0;     // detection square (outer edge of the black border)
  double spacing = 0;         // gap between tags / tag size
  int first_id = 0;
  bool valid() const { return rows > 0 && cols > 0; }
};

// A ChArUco board (OpenCV 4.6 aruco): squares_x x squares_y chessboard squares of side square_mm,
// an ArUco marker of side marker_mm centred in every white square, ids 0.. in OpenCV's order.
// Used here through its markers (quads at known plate positions); origin at the board's centre,
// y up (OpenCV's board frame has y down).
struct CharucoDefinition {
  int squares_x = 0, squares_y = 0;
  double square_mm = 0, marker_mm = 0;
  std::string dictionary;  // e.g. "DICT_5X5_100"
  bool valid() const { return squares_x > 0 && squares_y > 0; }
};

struct Board {
  std::string family = "tag36h11";
  int border_bits = 1;         // black border width in modules (Kalibr AprilGrid: 2)
  double sample_size_mm = 40;  // side of the square sample region centered at the origin (0: a calibration target)
  std::vector<Marker> markers;
  AprilGrid grid;              // set for AprilGrid boards (rendering draws its corner squares)
  CharucoDefinition charuco;   // set for ChArUco boards (informative; the markers carry the geometry)
  void Check(const std::string& source) const;  // ids unique, corners finite, non-degenerate
};

// The markers of an AprilGrid, corners in plate mm (frame above), height 0.
Board MakeAprilGridBoard(const AprilGrid& grid, const std::string& family = "tag36h11", int border_bits = 2);
// The ArUco markers of a ChArUco board (family "aruco:DICT_..."); bad input names `source`.
Board MakeCharucoBoard(const CharucoDefinition& charuco, const std::string& source);
// The chessboard corners of a ChArUco board in plate mm (frame above), indexed by OpenCV 4.6's
// corner id (CharucoBoard::chessboardCorners: (squares_x - 1) x (squares_y - 1) inner corners).
std::vector<Vec2> CharucoCornersMm(const CharucoDefinition& charuco);
// The module grid of ArUco marker `id` of `dictionary` (a ChArUco dictionary name, "DICT_5X5_100") with a
// black border of `border_bits` modules, through OpenCV's drawMarker: side x side modules (*side set),
// row-major, row 0 = top of the upright marker, 1 = white.
std::vector<std::uint8_t> ArucoMarkerModules(const std::string& dictionary, int id, int border_bits, int* side);

struct CameraModel {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;  // OpenCV convention
  // Lens model "radtan" (OpenCV calibrateCamera): k1, k2 radial, p1, p2 tangential, k3 third radial
  // (p1, p2, k3 from calibration). "fisheye" (OpenCV cv::fisheye, equidistant): k1..k4 with
  // theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8); p1, p2 unused (0).
  double k1 = 0, k2 = 0;
  double p1 = 0, p2 = 0, k3 = 0;
  double k4 = 0;
  std::string model = "radtan";
  bool fisheye() const { return model == "fisheye"; }
  bool has_extended_distortion() const { return !fisheye() && (p1 != 0 || p2 != 0 || k3 != 0); }
};

// camera.json (btf-register calibrate): the intrinsics with their lens model, and the fit's RMS.
struct CameraFile {
  CameraModel camera;
  double rms_px = 0;
};
CameraFile ReadCameraFile(const std::filesystem::path& path);
void WriteCameraFile(const std::filesystem::path& path, const CameraFile& camera, const nlohmann::json& extra = {});

// The camera projection shared by photo synthesis and registration (docs/conventions.md): plate
// point p (mm, z above the material surface) -> pixel (OpenCV convention), through the pose
// camera_from_plate (R, t) and the lens (radtan as cv::projectPoints, fisheye as
// cv::fisheye::projectPoints with zero skew). False if p is not in front of the camera.
bool ProjectToPixel(const CameraModel& camera, const Eigen::Matrix3d& camera_from_plate_rotation,
                    const Vec3& camera_from_plate_translation, const Vec3& p, Vec2* pixel);

// The inverse of the lens: distorted normalized image coordinates ((u - cx) / fx, (v - cy) / fy) ->
// the ray (x / z, y / z). radtan k1, k2 only (what btf-synth renders): 20 fixed-point steps; fisheye:
// Newton on theta_d(theta) as cv::fisheye::undistortPoints. False where no ray in front of the
// camera maps there (fisheye: theta beyond 90 degrees or past the lens's fold).
bool UndistortNormalized(const CameraModel& camera, const Vec2& distorted, Vec2* ray);

// The homography plate plane z = plane_z (mm) -> undistorted pixels, normalized to h33 = 1.
Eigen::Matrix3d PlaneHomography(const CameraModel& camera, const Eigen::Matrix3d& camera_from_plate_rotation,
                                const Vec3& camera_from_plate_translation, double plane_z = 0);

// One exposure of an exposure bracket (several photos of the same view and light).
struct BracketExposure {
  std::string file;     // relative to the manifest's folder
  double exposure = 1;  // as PhotoEntry::exposure: pixel value = exposure * radiance (clipped at full scale)
};

struct PhotoEntry {
  std::string file;  // relative to the manifest's folder (a bracket: its first exposure's file)
  int view_index = -1, light_index = -1;
  Vec3 view_dir = Vec3::UnitZ(), light_dir = Vec3::UnitZ();  // unit vectors, plate frame
  double exposure = 1;         // pixel value = exposure * radiance (a bracket: its first exposure's)
  std::vector<BracketExposure> brackets;  // empty = one photo (file, exposure); else >= 2 exposures of this
                                          // (view, light), merged to radiance by btf-register (register/hdr.h)
  double light_intensity = 1;  // directional: irradiance at normal incidence; point: intensity (x 1/r^2 in mm^2)
  double light_distance_mm = 0;  // 0 = directional light, else point light at this distance from the origin
  double camera_distance_mm = 0;
  CameraModel camera;
};

struct Manifest {
  std::string board_file;  // relative to the manifest's folder
  Sampling views, lights;  // the full samplings the indices refer to
  int bit_depth = 0;       // 0 = float EXR, 8 or 16 = integer PNG/JPEG
  std::string transfer;    // integer encoding: "" = not stated (linear PNG, or the file's tag), "linear", "srgb"
  // Reference photos of the same camera, relative to the manifest's folder ("" = none): a dark
  // frame (lens capped: the sensor's black level, subtracted from every photo) and a flat field
  // (a uniformly lit white target: the lens's relative illumination, divided out).
  std::string dark_frame, flat_field;
  std::vector<PhotoEntry> photos;
  nlohmann::json extra = nlohmann::json::object();  // model, preset, resolution hints
};

struct PhotoTruth {
  std::string file;
  Eigen::Matrix3d image_from_plate = Eigen::Matrix3d::Identity();  // homography, material surface z = 0 -> pixels
  Eigen::Matrix3d camera_from_plate_rotation = Eigen::Matrix3d::Identity();        // camera_from_plate
  Vec3 camera_from_plate_translation = Vec3::Zero();                               // camera_from_plate, mm
  std::map<int, std::array<Vec2, 4>> marker_corners_px;          // visible markers only
  std::map<int, Vec2> charuco_corners_px;  // ChArUco boards: chessboard corner id -> px (visible corners only)
};

// Readers validate every field and throw btf::Error (bad input) naming file, entry and field.
// ReadBoard reads ours (JSON, format libbtf-board) or a Kalibr target YAML (.yaml/.yml,
// target_type 'aprilgrid' or 'charuco'; sizes in metres); see docs/btf-register.md, "Fiducials and boards".
Board ReadBoard(const std::filesystem::path& path);
void WriteBoard(const std::filesystem::path& path, const Board& board);
Manifest ReadManifest(const std::filesystem::path& path);
// Every file a manifest names (board, dark frame, flat field, photos and their brackets), resolved
// against the manifest's folder: the inputs a registration reads.
std::vector<std::filesystem::path> ManifestFiles(const Manifest& manifest, const std::filesystem::path& manifest_path);
void WriteManifest(const std::filesystem::path& path, const Manifest& manifest);
std::vector<PhotoTruth> ReadTruth(const std::filesystem::path& path);
void WriteTruth(const std::filesystem::path& path, const std::vector<PhotoTruth>& truth);

}  // namespace btf
