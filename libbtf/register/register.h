#pragma once
// btf-register's pipeline: manifest of photos -> registered, rectified BTF dataset + report.
//
// Per photo: read, detect markers, fit the geometry (pose at the material surface when the
// manifest gives intrinsics), rectify the sample region into an N x N normtexture in one
// footprint-filtered resampling step, convert to BRDF units (radiometry.h). Optionally estimate
// the weave lattice on the reference view (the most frontal view, averaged over its lights) and
// replace every image by the regular tiling of its averaged unit tile (or by the tile itself).
// A photo that fails is reported with its reason and the rest are still processed.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/register/detect.h"
#include "libbtf/register/geometry.h"
#include "libbtf/register/hdr.h"
#include "libbtf/register/lattice.h"
#include "libbtf/register/rectify.h"
#include "libbtf/register/tile_reconstruct.h"

namespace btf {

struct RegisterOptions {
  TagDetectorOptions detector;    // family and border_bits: the board's unless set explicitly (family_override)
  bool family_override = false;   // true = use detector.family and border_bits even if the board names others
  ImageReadOptions input;         // decoding of integer photos; "auto" = the manifest's transfer if stated, else
                                  // the file's colour-space tag (io/image_io.h)
  std::filesystem::path camera;   // optional camera.json (btf-register calibrate): replaces every photo's
                                  // manifest intrinsics (radtan model only)
  HdrOptions hdr;                 // exposure brackets: merge weights and the camera response (hdr.h)
  GeometryOptions geometry;
  RectifyOptions rectify;         // resolution N (default 256) and the anti-aliasing filter
  bool use_intrinsics = true;     // pose from the manifest camera (marker height, distortion); false = homography
  bool radiometry = true;         // false = values are pixel / exposure, units "relative"
  double max_invalid_fraction = 0.0;  // fraction of texels allowed to fall outside the photo
  bool tile_average = false;
  std::string tile_output = "tiling";  // "tiling": N x N regular tiling; "tile": the averaged T x T tile
  LatticeOptions lattice;
  // Normtexture side on which the lattice is estimated (the reference view rectified again at
  // this resolution, the lattice scaled to N); 0 = max(N, 128). A finer one keeps the weave's
  // harmonics from aliasing: at N = 64 the twill's 0.625 cycles/texel harmonic folds to 0.375 and
  // the estimate is a wrong lattice; at 128 it is right (docs/btf-register.md, "Unit-tile reconstruction").
  int lattice_resolution = 0;
  TileAverageOptions tiles;
  // With tile_average, how the unit tile is obtained: "average" (trimmed mean of the rectified
  // repeats, AverageTiles) or "reconstruct" (least squares from every photo pixel on the sample,
  // ReconstructTile: the photo's pixels at all sub-pixel phases of the repeats).
  std::string tile_method = "average";
  TileReconstructOptions reconstruct;
  int contact_sheet_thumb = 128;  // thumbnail side in the contact sheet (0 = no contact sheet)
  std::filesystem::path truth;    // optional truth.json (btf-synth photos): adds errors to the report
  DatasetWriteOptions write;
  void Check() const;
};

struct PhotoReport {
  std::string file;
  int view_index = -1, light_index = -1;
  bool ok = false;
  std::string error;                      // why the photo failed
  std::vector<TagDetection> detections;   // every decoded marker
  std::vector<int> used_ids, rejected_ids;
  double rms_px = 0;                      // reprojection RMS over used corners
  bool has_pose = false;
  Eigen::Matrix3d homography = Eigen::Matrix3d::Identity();  // plate mm (surface z = 0) -> undistorted px
  Eigen::Matrix3d camera_from_plate_rotation = Eigen::Matrix3d::Identity();    // camera_from_plate (with pose)
  Vec3 camera_from_plate_translation = Vec3::Zero();
  double invalid_fraction = 0, max_footprint_px = 0;
  int exposures = 1;                      // photos merged (a bracket: > 1)
  std::size_t hdr_clipped_pixels = 0;     // bracket: pixels clipped in every exposure (anywhere in the photo)
  // Masked texels of this photo's normtexture (left out of tile averaging, or filled from the
  // nearest unmasked texel without it): hidden behind a raised marker (a line of sight through a
  // marker's printed area), touching a pixel clipped in every exposure of a bracket.
  std::size_t masked_hidden = 0, masked_clipped = 0;
  // With tile_method "reconstruct": pixels used as equations, pixels on the sample left out
  // (hidden behind a marker or clipped) and the RMS of the pixel equations after the solve.
  int tile_pixels_used = 0, tile_pixels_masked = 0;
  double tile_residual_rms = 0;
  std::vector<std::string> warnings;
  // With RegisterOptions::truth: RMS against the true marker corners and the true surface
  // homography over an 11 x 11 grid on the sample (px); -1 = not computed.
  double truth_corner_rms_px = -1, truth_homography_rms_px = -1, truth_homography_max_px = -1;
  nlohmann::json ToJson() const;
};

struct RegisterSummary {
  int photos = 0, photos_ok = 0, photos_failed = 0;
  int views = 0, lights = 0, width = 0, height = 0, channels = 0;
  std::vector<std::pair<int, int>> filled;  // (view, light) manifest indices filled from a neighbor
  std::optional<Lattice> lattice;
  int reference_view = -1;                 // manifest view index used for the lattice
  std::vector<PhotoReport> reports;
  Image contact_sheet;                     // empty unless contact_sheet_thumb > 0 and a view registered
  ResponseCurve response;                  // recovered camera response (HdrOptions::response not "linear")
  std::vector<std::string> response_files;  // the bracket it was recovered from
  PhaseTimes times;
  nlohmann::json ToJson() const;           // the registration report (docs/btf-register.md)
  std::string Report() const;              // what btf-register run prints
};

// Reads the manifest and its board (malformed: btf::Error bad input, before any work), registers
// every photo and writes the dataset atomically to `output`. Photos that fail are listed in the
// summary; the dataset holds the views and lights with at least one registered photo, and pairs
// without one are filled from the nearest registered light of the same view (listed in `filled`).
// Throws btf::Error (bad input) if no photo registers.
RegisterSummary RegisterPhotos(const RegisterOptions& options, const std::filesystem::path& manifest,
                               const std::filesystem::path& output, const Reporter& reporter = {});

// Detection only (btf-register detect). With `charuco` (a ChArUco board of the detector's family)
// and `charuco_corners` set, also its chessboard corners (DetectCharucoCorners).
std::vector<TagDetection> DetectInImage(const std::filesystem::path& image, const TagDetectorOptions& options,
                                        const ImageReadOptions& input = {}, const CharucoDefinition* charuco = nullptr,
                                        std::vector<CharucoCorner>* charuco_corners = nullptr);

}  // namespace btf
