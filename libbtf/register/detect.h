#pragma once
// Fiducial detection with libapriltag (Debian 3.3.0) and, for ArUco dictionaries, OpenCV's aruco
// module (Debian 4.6, contrib).
//
// Families: libapriltag's nine (`tag36h11`, ...), with a black border of `border_bits` modules (1:
// apriltag-imgs; 2: Kalibr's AprilGrid), or `aruco:DICT_5X5_100` etc. (OpenCV's predefined
// dictionaries, markerBorderBits = border_bits). A 2-bit AprilTag border is decoded by
// libapriltag itself through a copy of the family whose detection square is 2 modules wider and
// whose data bits are shifted 1 module inwards (the quad is the same black square).
//
// Corner order: AprilTag's, for the upright printed tag: left-bottom, right-bottom, right-top,
// left-top of the detection square (the black border's outer edge); this is the board file's order.
// Pixel convention: OpenCV's, pixel centers at integer coordinates ((0,0) = center of the top-left
// pixel). AprilTag reports (0.5, 0.5) for that center; the shift is applied once, in DetectTags.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "libbtf/core/directions.h"
#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"

namespace btf {

struct TagDetectorOptions {
  std::string family = "tag36h11";  // any family libapriltag 3.3 compiles in (see TagFamilies()), or
                                    // "aruco:DICT_..." (OpenCV's predefined dictionaries)
  int border_bits = 1;              // black border width, modules: 1 or 2 (2 = Kalibr AprilGrid). AprilTag:
                                    // classic families only (tag16h5, tag25h9, tag36h10, tag36h11) for 2
  int bits_corrected = 2;           // error-correction bits; 48h12/52h13 are capped at 1 (table size)
  double quad_decimate = 1.0;       // 1 = full resolution (decimation biases corners, notes 1.2)
  bool refine_edges = false;        // libapriltag's edge refinement: biased by -0.125 px in 3.3.0 (integer
                                    // sampling; measured in tests/register/detect_test.cpp), so off
  bool refine_corners = true;       // our own sub-pixel edge fit on the linear float image (see below)
  std::string x_corners = "lines";  // with refine_corners: a corner that is an X-junction (the tag's corner
                                    // touches a dark square diagonally, Kalibr's AprilGrid) is then refined
                                    // by "lines", "cornersubpix" or "none" (see below); others keep the edge fit
  double subpix_window = 0.75;      // cornerSubPix window: its corners reach this fraction of the border
                                    // width (border_bits modules) from the corner; (0, 1]
  double decode_sharpening = 0.25;  // libapriltag default
  int max_hamming = 1;              // detections correcting more bits are dropped (false positives; AprilTag only)
  double min_decision_margin = 20;  // weaker detections are dropped (AprilTag only; ArUco reports 0)
  double border_margin_px = 2;      // tags with a corner closer than this to the image edge are dropped
  bool split_touching = true;       // with border_bits 2 (AprilGrid), AprilTag only: a second pass on the image
                                    // with dark regions eroded by a 2 x 2 window finds tags whose corners touch
                                    // the grid's corner squares (libapriltag merges those into one blob)
  void Check() const;
};

struct TagDetection {
  int id = 0;
  int hamming = 0;
  double decision_margin = 0;
  std::array<Vec2, 4> corners;  // px, OpenCV convention, order documented above
  Vec2 center = Vec2::Zero();   // px, OpenCV convention
};

// Corner refinement (Detect(const Image&), refine_corners): first the edge fit: along each edge
// the black border / quiet zone step is located on normal profiles (the profile's area between
// the two levels), one total-least-squares line per edge, corners = intersections of adjacent
// lines. It assumes straight edges (no lens distortion across the tag) and linear intensities (a
// tone curve moves a blurred edge's 50 % point). Then each corner whose outward diagonal is dark
// (an X-junction, below) is refined again. x_corners = "lines" (the default): one line per edge
// through edge points on both sides of the junction (the tag's side and the corner square's, the
// dark side swapped) at mirrored distances of 1-2 modules, intersected; three passes, each kept
// only within one module of the previous corner. The two sides move in opposite directions under
// a tone curve or blur, so their shifts cancel, and the fit is local, so lens distortion barely
// bends it. x_corners = "cornersubpix": each corner whose outward diagonal is dark (black at half a module, against the border and the two quiet zones
// beside it: an X-junction) is refined by cv::cornerSubPix on the linear gray image (100
// iterations / 1e-4 px) in a square window of half-size subpix_window x border_bits x the
// smaller module length at that corner / sqrt 2 (at least 2 px): the window stays in the black
// border, the corner square and the white gaps. A blurred X-junction is point-symmetric about
// its centre whatever the tone curve, and the window is local, so this corner is unbiased by
// gamma and by the edges' curvature. A result moving more than one module is not used.
//
// Families this build can create (libapriltag's, then "aruco:DICT_..." names).
std::vector<std::string> TagFamilies();

// One libapriltag detector and family instance. Not thread-safe: use one per thread (notes 1.5).
class TagDetector {
 public:
  explicit TagDetector(const TagDetectorOptions& options = {});
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;

  // gray: row-major 8-bit, width x height, any stride >= width. Sorted by id.
  std::vector<TagDetection> Detect(const unsigned char* gray, int width, int height, int stride) const;
  // Converts a linear float image to 8-bit gray (see GrayForDetection) and detects.
  std::vector<TagDetection> Detect(const Image& image) const;
  const TagDetectorOptions& options() const { return options_; }

 private:
  std::vector<TagDetection> DetectAruco(const unsigned char* gray, int width, int height, int stride) const;
  // Decodes the quad q (AprilTag pixel convention) on `gray` with the family's bit layout.
  bool DecodeQuad(const std::vector<unsigned char>& gray, int w, int h, std::array<Vec2, 4> q, TagDetection* out) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  TagDetectorOptions options_;
};

// ChArUco chessboard corners (OpenCV 4.6 aruco): the board's markers, detected by a TagDetector of
// its family ("aruco:DICT_..."), give each inner corner a first position through the local
// homography of its two nearest markers (cv::aruco::interpolateCornersCharuco, both markers
// needed); then cv::cornerSubPix on the linear gray image, in a window that stays clear of the
// markers (half-size = 0.7 x the distance to the nearest marker corner / sqrt 2, 2..max_window_px).
// Same pixel convention as the tags (OpenCV's: (0,0) = centre of the top-left pixel).
struct CharucoCorner {
  int id = 0;                 // OpenCV's chessboard corner id (CharucoBoard::chessboardCorners)
  Vec2 pixel = Vec2::Zero();  // px, OpenCV convention
  Vec2 board_mm = Vec2::Zero();  // plate mm (libbtf/io/rig.h frame: origin at the board's centre, y up), z = 0
};
struct CharucoOptions {
  int max_window_px = 12;     // cornerSubPix half-window cap
  double max_move_px = 2;     // a corner cornerSubPix moves further than this from the interpolation is dropped
  double border_margin_px = 2;  // corners closer than this to the image edge are dropped
  void Check() const;
};
// `markers`: detections of the board's family on `image` (ids not on the board are ignored).
// Sorted by id.
std::vector<CharucoCorner> DetectCharucoCorners(const Image& image, const CharucoDefinition& board,
                                                const std::vector<TagDetection>& markers,
                                                const CharucoOptions& options = {});

// Linear gray (Rec.709 luminance for 3+ channels) scaled so the 99.5th percentile maps to 255.
// Stays linear on purpose: AprilTag thresholds at the mid level, and under a symmetric blur the
// 50% crossing of the linear signal is the true edge (a gamma curve would move it).
std::vector<unsigned char> GrayForDetection(const Image& image);

}  // namespace btf
