#include "libbtf/synth/photo_synth.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/synth/apriltag_render.h"
#include "libbtf/synth/btf_generator.h"

namespace btf {
namespace {

constexpr double kWhite = 0.8, kBlack = 0.05;  // Lambertian albedos: paper and print / table
constexpr double kMaxViewTheta = DegToRad(89.0);

struct MarkerGeom {
  Vec2 origin;   // left-bottom corner of the detection square (plate mm)
  Vec2 ax, ay;   // unit vectors along the tag's right and up
  double module = 0;
  double height = 0;  // marker plane z
  int border_start = 0, width_at_border = 0;
  TagBitmap bitmap;
};

std::vector<MarkerGeom> MarkerGeometry(const Board& board) {
  std::vector<MarkerGeom> out;
  for (const Marker& m : board.markers) {
    MarkerGeom g;
    g.bitmap = RenderTag(board.family, m.id, board.border_bits);
    g.width_at_border = g.bitmap.width_at_border;
    g.border_start = (g.bitmap.total_width - g.width_at_border) / 2;
    g.origin = m.corners_mm[0];
    const Vec2 right = m.corners_mm[1] - m.corners_mm[0], up = m.corners_mm[3] - m.corners_mm[0];
    g.ax = right.normalized();
    g.ay = up.normalized();
    g.module = right.norm() / g.width_at_border;
    g.height = m.height_mm;
    out.push_back(std::move(g));
  }
  return out;
}

// Albedo of the marker card at plate point p (on the marker plane), or -1 if p is off the card.
double MarkerAlbedo(const MarkerGeom& g, const Vec2& p) {
  const Vec2 d = p - g.origin;
  const double s = d.dot(g.ax) / g.module, t = d.dot(g.ay) / g.module;
  const int col = static_cast<int>(std::floor(s)) + g.border_start;
  const int row = (g.width_at_border - 1 - static_cast<int>(std::floor(t))) + g.border_start;
  const int T = g.bitmap.total_width;
  if (s < -g.border_start || t < -g.border_start || col < 0 || row < 0 || col >= T || row >= T) return -1;
  return g.bitmap.at(row, col) ? kWhite : kBlack;
}

double PlateHalfSize(const Board& board) {
  double e = board.sample_size_mm / 2;
  for (const Marker& m : board.markers)
    for (const Vec2& c : m.corners_mm) e = std::max({e, std::abs(c.x()), std::abs(c.y())});
  // Markers' quiet zone and a margin of white paper beyond the outermost detection squares (and
  // beyond an AprilGrid's outer corner squares).
  const TagBitmap probe = RenderTag(board.family, board.markers[0].id, board.border_bits);
  const double module = (board.markers[0].corners_mm[1] - board.markers[0].corners_mm[0]).norm() / probe.width_at_border;
  if (board.grid.valid()) e += board.grid.spacing * board.grid.tag_size_mm;
  if (board.charuco.valid())  // the outer chessboard squares reach beyond the markers
    e = std::max(e, 0.5 * board.charuco.square_mm * std::max(board.charuco.squares_x, board.charuco.squares_y));
  return e + 3 * module;
}

// An AprilGrid's black corner squares (side = the gap) at every tag corner: true if p is in one.
bool InGridCornerSquare(const AprilGrid& g, const Vec2& p) {
  const double s = g.tag_size_mm, gap = g.spacing * s, pitch = s + gap;
  const double w = g.cols * s + (g.cols - 1) * gap, h = g.rows * s + (g.rows - 1) * gap;
  const double u = (p.x() + w / 2 + gap) / pitch, v = (p.y() + h / 2 + gap) / pitch;
  const double iu = std::floor(u), iv = std::floor(v);
  if (iu < 0 || iv < 0 || iu > g.cols || iv > g.rows) return false;
  return (u - iu) * pitch < gap && (v - iv) * pitch < gap;
}

// The ChArUco square (row-major from OpenCV's top-left square) holding plate point p, or -1 off the board.
int CharucoSquare(const CharucoDefinition& c, const Vec2& p) {
  const double col = std::floor((p.x() + 0.5 * c.squares_x * c.square_mm) / c.square_mm);
  const double row = std::floor((0.5 * c.squares_y * c.square_mm - p.y()) / c.square_mm);
  if (col < 0 || row < 0 || col >= c.squares_x || row >= c.squares_y) return -1;
  return static_cast<int>(row) * c.squares_x + static_cast<int>(col);
}

// Separable Gaussian blur of every channel, edges clamped.
void GaussianBlur(Image& img, double sigma) {
  if (sigma <= 0) return;
  const int r = static_cast<int>(std::ceil(4 * sigma));
  std::vector<double> k(static_cast<std::size_t>(2 * r + 1));
  double sum = 0;
  for (int i = -r; i <= r; ++i) sum += k[static_cast<std::size_t>(i + r)] = std::exp(-0.5 * i * i / (sigma * sigma));
  for (auto& v : k) v /= sum;
  const int W = img.width, H = img.height, C = img.channels;
  Image tmp(W, H, C);
#pragma omp parallel for
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < C; ++c) {
        double a = 0;
        for (int i = -r; i <= r; ++i) a += k[static_cast<std::size_t>(i + r)] * img.at(std::clamp(x + i, 0, W - 1), y, c);
        tmp.at(x, y, c) = static_cast<float>(a);
      }
#pragma omp parallel for
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < C; ++c) {
        double a = 0;
        for (int i = -r; i <= r; ++i) a += k[static_cast<std::size_t>(i + r)] * tmp.at(x, std::clamp(y + i, 0, H - 1), c);
        img.at(x, y, c) = static_cast<float>(a);
      }
}

// Disc PSF (uniform over a disc of `radius` px, a defocused lens) of every channel, edges clamped.
// The kernel weight of each pixel is the area of the disc over that pixel (16 x 16 sub-samples), so
// the kernel is symmetric and its discretisation does not move an edge.
void DiscBlur(Image& img, double radius) {
  if (radius <= 0) return;
  const int r = static_cast<int>(std::ceil(radius));
  const int side = 2 * r + 1, ns = 16;
  std::vector<double> k(static_cast<std::size_t>(side * side), 0.0);
  double sum = 0;
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      int in = 0;
      for (int j = 0; j < ns; ++j)
        for (int i = 0; i < ns; ++i) {
          const double x = dx - 0.5 + (i + 0.5) / ns, y = dy - 0.5 + (j + 0.5) / ns;
          in += x * x + y * y <= radius * radius;
        }
      sum += k[static_cast<std::size_t>((dy + r) * side + dx + r)] = in;
    }
  for (auto& v : k) v /= sum;
  const int W = img.width, H = img.height, C = img.channels;
  Image out(W, H, C);
#pragma omp parallel for
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < C; ++c) {
        double a = 0;
        for (int dy = -r; dy <= r; ++dy)
          for (int dx = -r; dx <= r; ++dx) {
            const double w = k[static_cast<std::size_t>((dy + r) * side + dx + r)];
            if (w > 0) a += w * img.at(std::clamp(x + dx, 0, W - 1), std::clamp(y + dy, 0, H - 1), c);
          }
        out.at(x, y, c) = static_cast<float>(a);
      }
  img = std::move(out);
}

}  // namespace

void PhotoOptions::Check() const {
  BTF_CHECK_OPTION(views.size() >= 1 && lights.size() >= 1, "views/lights", "non-empty samplings");
  for (int v : view_indices) BTF_CHECK_OPTION(v >= 0 && v < views.size(), "views", "index inside the view sampling");
  for (int l : light_indices)
    BTF_CHECK_OPTION(l >= 0 && l < lights.size(), "lights", "index inside the light sampling");
  BTF_CHECK_OPTION(max_photos >= 0, "max-photos", ">= 0");
  BTF_CHECK_OPTION(std::isfinite(sample_tiles) && sample_tiles > 0 && sample_tiles <= 1000, "sample-tiles", "(0, 1000]");
  BTF_CHECK_OPTION(std::isfinite(module_mm) && module_mm >= 0, "module-mm", ">= 0");
  BTF_CHECK_OPTION(std::isfinite(marker_height_mm) && marker_height_mm >= 0, "marker-height", ">= 0 mm");
  BTF_CHECK_OPTION(std::isfinite(irregularity) && irregularity >= 0 && irregularity <= 0.5, "irregularity",
                   "0..0.5 tiles");
  BTF_CHECK_OPTION(width >= 16 && height >= 16 && width <= 16384 && height <= 16384, "width/height", "16..16384 px");
  BTF_CHECK_OPTION(std::isfinite(camera_distance_mm) && camera_distance_mm > 0, "camera-distance", "> 0 mm");
  BTF_CHECK_OPTION(std::isfinite(focal_px) && focal_px >= 0, "focal", ">= 0 px (0 = auto)");
  BTF_CHECK_OPTION(std::isfinite(pixel_aspect) && pixel_aspect >= 0.5 && pixel_aspect <= 2, "pixel-aspect",
                   "0.5..2 (fy / fx)");
  BTF_CHECK_OPTION(std::isfinite(k1) && std::isfinite(k2) && std::abs(k1) < 1 && std::abs(k2) < 1, "k1/k2",
                   "|k| < 1");
  BTF_CHECK_OPTION(lens == "radtan" || lens == "fisheye", "lens", "radtan or fisheye");
  BTF_CHECK_OPTION(lens == "radtan" || (k1 == 0 && k2 == 0), "k1/k2", "0 with lens fisheye (its coefficients are fisheye-k)");
  BTF_CHECK_OPTION(fisheye_k.size() == 4, "fisheye-k", "4 coefficients k1,k2,k3,k4");
  for (double k : fisheye_k) BTF_CHECK_OPTION(std::isfinite(k) && std::abs(k) < 1, "fisheye-k", "|k| < 1");
  BTF_CHECK_OPTION(lens == "fisheye" || (fisheye_k[0] == 0 && fisheye_k[1] == 0 && fisheye_k[2] == 0 && fisheye_k[3] == 0),
                   "fisheye-k", "0 unless lens is fisheye");
  BTF_CHECK_OPTION(pixel_samples >= 1 && pixel_samples <= 16, "pixel-samples", "1..16 per axis");
  BTF_CHECK_OPTION(std::isfinite(light_distance_mm) && light_distance_mm >= 0, "light-distance", ">= 0 mm");
  BTF_CHECK_OPTION(std::isfinite(light_intensity) && light_intensity >= 0, "light-intensity", ">= 0");
  BTF_CHECK_OPTION(format == "png16" || format == "png8" || format == "jpeg" || format == "exr", "format",
                   "png16, png8, jpeg or exr");
  BTF_CHECK_OPTION(transfer == "linear" || transfer == "srgb", "transfer", "linear or srgb");
  BTF_CHECK_OPTION(!(format == "exr" && transfer != "linear"), "transfer", "linear for exr (float)");
  BTF_CHECK_OPTION(jpeg_quality >= 1 && jpeg_quality <= 100, "jpeg-quality", "1..100");
  BTF_CHECK_OPTION(std::isfinite(blur_px) && blur_px >= 0 && blur_px <= 20, "blur", "0..20 px");
  BTF_CHECK_OPTION(psf == "gaussian" || psf == "disc", "psf", "gaussian or disc");
  BTF_CHECK_OPTION(std::isfinite(disc_radius_px) && disc_radius_px >= 0 && disc_radius_px <= 20, "disc-radius",
                   "0..20 px");
  BTF_CHECK_OPTION(psf == "disc" ? disc_radius_px > 0 && blur_px == 0 : disc_radius_px == 0, "psf",
                   "disc with --disc-radius > 0 and no --blur; gaussian (--blur) without --disc-radius");
  BTF_CHECK_OPTION(target == "ring" || target == "aprilgrid" || target == "charuco", "target",
                   "ring, aprilgrid or charuco");
  BTF_CHECK_OPTION(charuco_squares_x >= 2 && charuco_squares_y >= 2 && charuco_squares_x <= 100 &&
                       charuco_squares_y <= 100,
                   "charuco-squares-x/charuco-squares-y", "2..100 squares");
  BTF_CHECK_OPTION(std::isfinite(charuco_square_mm) && charuco_square_mm >= 0, "charuco-square-mm", ">= 0 (0 = auto)");
  BTF_CHECK_OPTION(std::isfinite(charuco_marker_mm) && charuco_marker_mm >= 0 &&
                       (charuco_marker_mm == 0 || charuco_square_mm == 0 || charuco_marker_mm < charuco_square_mm),
                   "charuco-marker-mm", ">= 0 (0 = auto) and below the square side");
  if (target == "charuco") {
    int side = 0;
    try {
      ArucoMarkerModules(charuco_dictionary, 0, 1, &side);
    } catch (const Error&) {
      BTF_CHECK_OPTION(false, "charuco-dictionary", "DICT_4X4_50 .. DICT_7X7_1000 or DICT_ARUCO_ORIGINAL");
    }
  }
  BTF_CHECK_OPTION(border_bits >= 0 && border_bits <= 2, "border-bits", "0 (auto), 1 or 2");
  BTF_CHECK_OPTION(grid_rows >= 1 && grid_cols >= 1 && grid_rows * grid_cols <= 587, "grid-rows/grid-cols",
                   "1.. tags, at most 587 in all (tag36h11)");
  BTF_CHECK_OPTION(std::isfinite(grid_tag_mm) && grid_tag_mm >= 0, "grid-tag-mm", ">= 0 (0 = auto)");
  BTF_CHECK_OPTION(std::isfinite(grid_spacing) && grid_spacing > 0 && grid_spacing < 2, "grid-spacing", "(0, 2)");
  BTF_CHECK_OPTION(std::isfinite(exposure) && exposure >= 0, "exposure", ">= 0 (0 = auto)");
  BTF_CHECK_OPTION(std::isfinite(noise) && noise >= 0 && noise <= 1, "noise", "0..1 of full scale");
  BTF_CHECK_OPTION(std::isfinite(vignetting) && vignetting >= 0 && vignetting <= 0.9, "vignetting", "0..0.9");
  BTF_CHECK_OPTION(std::isfinite(dark_level) && dark_level >= 0 && dark_level <= 0.2, "dark-level", "0..0.2 of full scale");
  BTF_CHECK_OPTION((vignetting == 0 && dark_level == 0) || response_gamma == 0, "vignetting",
                   "and dark-level apply to linear sensor values: not with response-gamma");
  BTF_CHECK_OPTION(brackets.empty() || (brackets.size() >= 2 && brackets.size() <= 16), "brackets", "2..16 exposures");
  for (double b : brackets) BTF_CHECK_OPTION(std::isfinite(b) && b > 0 && b <= 1e6, "brackets", "factors in (0, 1e6]");
  BTF_CHECK_OPTION(brackets.empty() || format != "exr", "brackets", "an integer format (exr does not clip)");
  BTF_CHECK_OPTION(std::isfinite(response_gamma) && response_gamma >= 0 && response_gamma <= 5, "response-gamma",
                   "0 (none) .. 5");
  BTF_CHECK_OPTION(std::isfinite(response_bias) && response_bias > 0 && response_bias < 1, "response-bias", "(0, 1)");
  BTF_CHECK_OPTION(response_gamma == 0 || ((format == "png8" || format == "jpeg") && transfer == "linear"),
                   "response-gamma", "8-bit format (png8 or jpeg) with transfer linear (the response replaces it)");
}

namespace {

// The camera response of `options` (response_gamma > 0): linear value in [0, 1] -> stored value in [0, 1].
double CameraResponse(const PhotoOptions& o, double x) {
  const double y = std::pow(std::clamp(x, 0.0, 1.0), 1.0 / o.response_gamma);
  return y / ((1.0 / o.response_bias - 2.0) * (1.0 - y) + 1.0);
}

}  // namespace

nlohmann::json PhotoSummary::ToJson() const {
  return {{"photos", photos},
          {"seconds_per_photo", photos ? times.Total() / photos : 0.0},
          {"seconds", times.ToJson()}};
}

std::string PhotoSummary::Report() const {
  return fmt::format("{} photos ({:.2f} s each)\n", photos, photos ? times.Total() / photos : 0.0);
}

Board MakeBoard(const PhotoOptions& o, double tile_mm) {
  if (o.target == "aprilgrid") {
    AprilGrid g;
    g.rows = o.grid_rows;
    g.cols = o.grid_cols;
    g.spacing = o.grid_spacing;
    g.tag_size_mm = o.grid_tag_mm;
    if (g.tag_size_mm <= 0) {
      const double span = std::max(g.rows, g.cols) + (std::max(g.rows, g.cols) - 1) * g.spacing;  // in tag sides
      g.tag_size_mm = o.focal_px > 0 ? 0.85 * std::min(o.width, o.height) * o.camera_distance_mm / o.focal_px / span : 88.0;
    }
    Board b = MakeAprilGridBoard(g, o.family, o.border_bits > 0 ? o.border_bits : 2);
    b.Check("generated AprilGrid");
    return b;
  }
  if (o.target == "charuco") {
    CharucoDefinition c;
    c.squares_x = o.charuco_squares_x;
    c.squares_y = o.charuco_squares_y;
    c.dictionary = o.charuco_dictionary;
    c.square_mm = o.charuco_square_mm;
    if (c.square_mm <= 0)
      c.square_mm = o.focal_px > 0 ? 0.85 * std::min(o.width / double(c.squares_x), o.height / double(c.squares_y)) *
                                         o.camera_distance_mm / o.focal_px
                                   : 20.0;
    c.marker_mm = o.charuco_marker_mm > 0 ? o.charuco_marker_mm : 0.75 * c.square_mm;
    if (!(c.marker_mm < c.square_mm))
      ThrowUsage("invalid option 'charuco-marker-mm': {} mm is not below the square side {} mm", c.marker_mm,
                 c.square_mm);
    return MakeCharucoBoard(c, "generated ChArUco board");
  }
  Board b;
  b.family = o.family;
  b.border_bits = o.border_bits > 0 ? o.border_bits : 1;
  b.sample_size_mm = o.sample_tiles * tile_mm;
  const TagBitmap probe = RenderTag(o.family, 0, b.border_bits);
  const double m = o.module_mm > 0 ? o.module_mm : b.sample_size_mm / 20;
  const double det = probe.width_at_border * m, card = probe.total_width * m;
  // Card centers one module outside the sample edge, in a ring of 8 (corners and mid-sides).
  const double d = b.sample_size_mm / 2 + m + card / 2;
  const int ring[8][2] = {{-1, -1}, {0, -1}, {1, -1}, {1, 0}, {1, 1}, {0, 1}, {-1, 1}, {-1, 0}};
  for (int k = 0; k < 8; ++k) {
    Marker mk;
    mk.id = k;
    const Vec2 c(ring[k][0] * d, ring[k][1] * d);
    const double h = det / 2;
    mk.corners_mm = {c + Vec2(-h, -h), c + Vec2(h, -h), c + Vec2(h, h), c + Vec2(-h, h)};
    mk.height_mm = o.marker_height_mm;
    b.markers.push_back(mk);
  }
  b.Check("generated board");
  return b;
}

bool CameraPose::Project(const Vec3& X, Vec2* pixel) const {
  return ProjectToPixel(camera, camera_from_plate_rotation, camera_from_plate_translation, X, pixel);
}

Eigen::Matrix3d CameraPose::PlateHomography() const { return PlaneHomography(camera, camera_from_plate_rotation, camera_from_plate_translation); }

CameraPose MakeCamera(const PhotoOptions& o, const Board& board, const Vec3& view_dir) {
  const Vec3 v = view_dir.normalized();
  if (!(v.z() > std::cos(kMaxViewTheta)))
    ThrowUsage("view direction ({:.4f}, {:.4f}, {:.4f}) is beyond 89 degrees: the camera cannot see the plate", v.x(),
               v.y(), v.z());
  CameraPose c;
  c.camera.width = o.width;
  c.camera.height = o.height;
  const double f = o.focal_px > 0 ? o.focal_px
                                  : 0.9 * 0.5 * std::min(o.width, o.height) * o.camera_distance_mm / PlateHalfSize(board);
  c.camera.fx = f;
  c.camera.fy = o.pixel_aspect * f;
  c.camera.cx = 0.5 * (o.width - 1);
  c.camera.cy = 0.5 * (o.height - 1);
  c.camera.model = o.lens;
  if (o.lens == "fisheye") {
    c.camera.k1 = o.fisheye_k[0], c.camera.k2 = o.fisheye_k[1], c.camera.k3 = o.fisheye_k[2], c.camera.k4 = o.fisheye_k[3];
  } else {
    c.camera.k1 = o.k1;
    c.camera.k2 = o.k2;
  }
  c.center = o.camera_distance_mm * v;
  // OpenCV camera: z forward (to the plate center), y down, x = y cross z. Image up follows plate +y.
  const Vec3 zc = -v;
  const Vec3 up = Vec3::UnitY() - Vec3::UnitY().dot(zc) * zc;
  const Vec3 yc = -up.normalized();
  const Vec3 xc = yc.cross(zc);
  c.camera_from_plate_rotation.row(0) = xc.transpose();
  c.camera_from_plate_rotation.row(1) = yc.transpose();
  c.camera_from_plate_rotation.row(2) = zc.transpose();
  c.camera_from_plate_translation = -c.camera_from_plate_rotation * c.center;
  return c;
}

namespace {

// The photo's light: a point light light_distance_mm along light_dir with its intensity, or (at
// distance <= 0) a directional light.
struct PhotoLight {
  Vec3 dir, pos;
  double intensity = 1, distance = 0;

  PhotoLight(const PhotoOptions& o, const Vec3& light_dir)
      : dir(light_dir),
        pos(o.light_distance_mm * light_dir),
        intensity(o.light_intensity > 0 ? o.light_intensity
                                        : (o.light_distance_mm > 0 ? o.light_distance_mm * o.light_distance_mm : 1.0)),
        distance(o.light_distance_mm) {}

  // Irradiance at plate point X.
  double At(const Vec3& X) const {
    if (distance <= 0) return intensity * std::max(0.0, dir.z());
    const Vec3 r = pos - X;
    const double r2 = r.squaredNorm();
    return intensity * std::max(0.0, r.z() / std::sqrt(r2)) / r2;
  }
  // The direction to the light from X.
  Vec3 From(const Vec3& X) const { return distance > 0 ? Vec3((pos - X).normalized()) : dir; }
};

// ChArUco: the marker in each square (-1: a black square); white squares hold a marker. Empty
// without a ChArUco board.
std::vector<int> CharucoSquareMarkers(const Board& board) {
  std::vector<int> square_marker;
  if (!board.charuco.valid()) return square_marker;
  square_marker.assign(static_cast<std::size_t>(board.charuco.squares_x * board.charuco.squares_y), -1);
  for (std::size_t i = 0; i < board.markers.size(); ++i) {
    const auto& c = board.markers[i].corners_mm;
    const int sq = CharucoSquare(board.charuco, 0.25 * (c[0] + c[1] + c[2] + c[3]));
    if (sq >= 0) square_marker[static_cast<std::size_t>(sq)] = static_cast<int>(i);
  }
  return square_marker;
}

// The board's part of a ray from the camera center along dir (dir.z() < 0): if the ray ends on
// a chessboard square, an AprilGrid corner square or a marker card, adds its radiance to a[0..2]
// and returns true; false if it reaches the material or the plate.
bool AddBoardRadiance(const Board& board, const std::vector<MarkerGeom>& markers, const std::vector<int>& square_marker,
                      const CameraPose& cam, const Vec3& dir, const PhotoLight& light, double* a) {
  const MarkerGeom* only = nullptr;  // AprilGrid: the one tag whose cell holds the point
  if (board.charuco.valid()) {  // chessboard squares and markers, all in the plane z = 0
    const double t = -cam.center.z() / dir.z();
    const Vec3 X = cam.center + t * dir;
    const int sq = CharucoSquare(board.charuco, X.head<2>());
    if (sq >= 0) {
      const int mi = square_marker[static_cast<std::size_t>(sq)];
      double alb = mi < 0 ? kBlack : MarkerAlbedo(markers[static_cast<std::size_t>(mi)], X.head<2>());
      if (alb < 0) alb = kWhite;  // the white square around the marker
      const double L = alb / kPi * light.At(X);
      a[0] += L, a[1] += L, a[2] += L;
      return true;
    }
  }
  if (board.grid.valid()) {  // corner squares and tags, all in the plane z = 0
    const double t = -cam.center.z() / dir.z();
    const Vec3 X = cam.center + t * dir;
    if (InGridCornerSquare(board.grid, X.head<2>())) {
      const double L = kBlack / kPi * light.At(X);
      a[0] += L, a[1] += L, a[2] += L;
      return true;
    }
    const AprilGrid& gr = board.grid;
    const double s = gr.tag_size_mm, gap = gr.spacing * s, pitch = s + gap;
    const double c = std::floor((X.x() + (gr.cols * pitch - gap) / 2 + gap / 2) / pitch);
    const double r = std::floor((X.y() + (gr.rows * pitch - gap) / 2 + gap / 2) / pitch);
    if (c >= 0 && r >= 0 && c < gr.cols && r < gr.rows)
      only = &markers[static_cast<std::size_t>(r * gr.cols + c)];
  }
  // Marker cards (they lie at or above the material surface).
  for (const MarkerGeom& g : markers) {
    if (board.grid.valid() && &g != only) continue;
    const double t = (g.height - cam.center.z()) / dir.z();
    const Vec3 X = cam.center + t * dir;
    const double alb = MarkerAlbedo(g, X.head<2>());
    if (alb < 0) continue;
    const double L = alb / kPi * light.At(X);
    a[0] += L, a[1] += L, a[2] += L;
    return true;
  }
  return false;
}

}  // namespace

Image RenderPhoto(const SvbrdfModel& model, const Board& board, const PhotoOptions& o, const CameraPose& cam,
                  const Vec3& view_dir_in, const Vec3& light_dir_in) {
  if (model.channels() != 3) ThrowUsage("photo synthesis needs an RGB model, '{}' has {} channels", model.name(),
                                        model.channels());
  const Vec3 view_dir = view_dir_in.normalized(), light_dir = light_dir_in.normalized();
  const std::vector<MarkerGeom> markers = MarkerGeometry(board);
  const double half_sample = board.sample_size_mm / 2, plate_half = PlateHalfSize(board);
  const double tile = model.tile_size_mm();
  const PatternWarp warp(o.irregularity, o.irregularity_seed);
  const PhotoLight light(o, light_dir);
  const int W = o.width, H = o.height, n = o.pixel_samples;
  const auto& K = cam.camera;
  const Eigen::Matrix3d Rt = cam.camera_from_plate_rotation.transpose();
  Image img(W, H, 3);
  const std::vector<int> square_marker = CharucoSquareMarkers(board);
#pragma omp parallel
  {
    std::vector<Vec2> uvs;
    std::vector<int> owner;
    std::vector<double> weight;
    std::vector<float> vals;
    std::vector<double> acc(static_cast<std::size_t>(W) * 3);
#pragma omp for schedule(dynamic, 4)
    for (int py = 0; py < H; ++py) {
      std::fill(acc.begin(), acc.end(), 0.0);
      uvs.clear();
      owner.clear();
      weight.clear();
      for (int px = 0; px < W; ++px) {
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i) {
            // Sub-pixel position (OpenCV: pixel center at integer coordinates), undistorted.
            const Vec2 d((px + (i + 0.5) / n - 0.5 - K.cx) / K.fx, (py + (j + 0.5) / n - 0.5 - K.cy) / K.fy);
            Vec2 u;
            if (!UndistortNormalized(K, d, &u)) continue;  // no ray of the lens: black
            const Vec3 dir = Rt * Vec3(u.x(), u.y(), 1);
            if (dir.z() >= 0) continue;  // ray misses the plate: black
            double* a = &acc[static_cast<std::size_t>(px) * 3];
            if (AddBoardRadiance(board, markers, square_marker, cam, dir, light, a)) continue;
            const double t0 = -cam.center.z() / dir.z();
            const Vec3 X = cam.center + t0 * dir;
            const double E = light.At(X);
            if (half_sample > 0 && std::abs(X.x()) <= half_sample && std::abs(X.y()) <= half_sample) {
              const Vec2 uv = warp.Apply(Vec2((X.x() + half_sample) / tile, (X.y() + half_sample) / tile));
              if (o.true_directions) {
                float f[3];
                model.Eval(uv, light.From(X), (cam.center - X).normalized(), f);
                a[0] += f[0] * E, a[1] += f[1] * E, a[2] += f[2] * E;
              } else {
                uvs.push_back(uv);
                owner.push_back(px);
                weight.push_back(E);
              }
            } else {
              const double alb = (std::abs(X.x()) <= plate_half && std::abs(X.y()) <= plate_half) ? kWhite : kBlack;
              const double L = alb / kPi * E;
              a[0] += L, a[1] += L, a[2] += L;
            }
          }
      }
      if (!uvs.empty()) {
        // One batch per row: the model's per-direction work is done once.
        vals.resize(uvs.size() * 3);
        model.EvalBatch(light_dir, view_dir, uvs.data(), static_cast<int>(uvs.size()), vals.data());
        for (std::size_t k = 0; k < uvs.size(); ++k)
          for (int c = 0; c < 3; ++c) acc[static_cast<std::size_t>(owner[k]) * 3 + c] += vals[k * 3 + c] * weight[k];
      }
      const double inv = 1.0 / (n * n);
      for (int px = 0; px < W; ++px)
        for (int c = 0; c < 3; ++c) img.at(px, py, c) = static_cast<float>(acc[static_cast<std::size_t>(px) * 3 + c] * inv);
    }
  }
  return img;
}

std::vector<std::pair<int, int>> SelectPhotos(const PhotoOptions& o) {
  std::vector<int> vs = o.view_indices, ls = o.light_indices;
  if (vs.empty())
    for (int i = 0; i < o.views.size(); ++i) vs.push_back(i);
  if (ls.empty())
    for (int i = 0; i < o.lights.size(); ++i) ls.push_back(i);
  std::vector<std::pair<int, int>> all;
  for (int v : vs)
    for (int l : ls) all.emplace_back(v, l);
  if (o.max_photos <= 0 || o.max_photos >= static_cast<int>(all.size())) return all;
  std::vector<std::pair<int, int>> out;
  const double step = static_cast<double>(all.size()) / o.max_photos;
  for (int k = 0; k < o.max_photos; ++k) out.push_back(all[static_cast<std::size_t>((k + 0.5) * step)]);
  return out;
}

namespace {

// The manifest of a photo set before its photos: the samplings, the encoding and in `extra` how
// the photos were made (keys of the newer options only when they are used, so that the default
// manifest stays as it was).
Manifest PhotoManifest(const PhotoOptions& o, const SvbrdfModel& model, const nlohmann::json& extra) {
  Manifest manifest;
  manifest.board_file = "board.json";
  manifest.views = o.views;
  manifest.lights = o.lights;
  manifest.bit_depth = o.format == "exr" ? 0 : (o.format == "png8" || o.format == "jpeg" ? 8 : 16);
  if (o.transfer != "linear" || o.format == "jpeg") manifest.transfer = o.transfer;
  manifest.extra = extra.is_object() ? extra : nlohmann::json::object();
  manifest.extra["model"] = model.Describe();
  manifest.extra["model_name"] = model.name();
  manifest.extra["tile_size_mm"] = model.tile_size_mm();
  manifest.extra["sample_tiles"] = o.sample_tiles;
  manifest.extra["irregularity"] = PatternWarp(o.irregularity, o.irregularity_seed).Describe();
  manifest.extra["irregularity_seed"] = o.irregularity_seed;
  manifest.extra["pixel_samples_per_axis"] = o.pixel_samples;
  manifest.extra["directions"] = o.true_directions ? "per point (true)" : "nominal per photo";
  manifest.extra["noise_sd"] = o.noise;
  if (o.blur_px > 0) manifest.extra["blur_sigma_px"] = o.blur_px;
  if (o.psf == "disc") manifest.extra["psf"] = {{"kind", "disc"}, {"radius_px", o.disc_radius_px}};
  if (o.format == "jpeg") manifest.extra["jpeg_quality"] = o.jpeg_quality;
  if (o.target != "ring") manifest.extra["target"] = o.target;
  if (!o.brackets.empty()) {
    manifest.extra["brackets"] = o.brackets;
    manifest.extra["white_level"] = "full scale: exposure * radiance (+ noise) is clipped at 1 before encoding";
  }
  if (o.response_gamma > 0) {
    std::vector<double> inverse(256);  // the truth a recovered curve is compared with: code -> linear
    for (int z = 0; z < 256; ++z) {
      double lo = 0, hi = 1;  // bisection of the monotone response
      for (int it = 0; it < 60; ++it) (CameraResponse(o, 0.5 * (lo + hi)) < z / 255.0 ? lo : hi) = 0.5 * (lo + hi);
      inverse[static_cast<std::size_t>(z)] = 0.5 * (lo + hi);
    }
    manifest.extra["response"] = {{"curve", "code / 255 = bias(min(1, x)^(1 / gamma)), bias(y) = y / ((1 / b - 2) (1 - y) + 1)"},
                                  {"gamma", o.response_gamma},
                                  {"bias", o.response_bias},
                                  {"code_to_linear", inverse}};
  }
  return manifest;
}

ImageWriteOptions PhotoWriteOptions(const PhotoOptions& o) {
  ImageWriteOptions wopt;
  wopt.has_format = true;
  wopt.format = o.format == "exr" ? PixelFormat::kFloat
                : (o.format == "png8" || o.format == "jpeg" ? PixelFormat::kUint8 : PixelFormat::kUint16);
  wopt.srgb = o.transfer == "srgb";
  wopt.jpeg_quality = o.jpeg_quality;
  return wopt;
}

// The sensor's relative illumination (vignetting) and black level per pixel (channels alike).
struct SensorPattern {
  std::vector<double> gain, dark;
};

SensorPattern MakeSensorPattern(const PhotoOptions& o) {
  const std::size_t np = static_cast<std::size_t>(o.width) * o.height;
  SensorPattern sp{std::vector<double>(np, 1.0), std::vector<double>(np, 0.0)};
  const double cx = 0.5 * o.width, cy = 0.5 * o.height, r2_corner = cx * cx + cy * cy;
  for (std::size_t p = 0; p < np; ++p) {
    const double dx = double(p % std::size_t(o.width)) + 0.5 - cx, dy = double(p / std::size_t(o.width)) + 0.5 - cy;
    sp.gain[p] = 1 - o.vignetting * (dx * dx + dy * dy) / r2_corner;
    if (o.dark_level > 0) sp.dark[p] = o.dark_level * (0.5 + HashUniform(o.seed, 0x5eed0da4c, p));
  }
  return sp;
}

// Reference photos, in the photos' format: the dark frame, and the flat field (a white target at
// 0.8 of full scale at the image center), each with the photos' black level; named in the manifest.
void WriteReferenceFrames(const PhotoOptions& o, const SensorPattern& sp, const std::filesystem::path& dir,
                          const std::string& ext, const ImageWriteOptions& wopt, Manifest* manifest) {
  const int C = 3;
  Image dark_img(o.width, o.height, C), flat_img(o.width, o.height, C);
  for (std::size_t i = 0; i < dark_img.pixels.size(); ++i) {
    dark_img.pixels[i] = static_cast<float>(sp.dark[i / C]);
    flat_img.pixels[i] = static_cast<float>(std::min(1.0, 0.8 * sp.gain[i / C] + sp.dark[i / C]));
  }
  manifest->dark_frame = "dark" + ext;
  manifest->flat_field = "flat" + ext;
  WriteImage(dir / manifest->dark_frame, dark_img, wopt);
  WriteImage(dir / manifest->flat_field, flat_img, wopt);
  manifest->extra["vignetting"] = {{"relative_illumination", "1 - v (r / r_corner)^2, r from the image center"},
                                   {"v", o.vignetting}};
  manifest->extra["dark_level"] = {{"dark", "level (0.5 + u), u uniform per pixel (fixed pattern)"}, {"level", o.dark_level}};
}

// What the camera stores for the rendered radiance img at exposure eb: through the sensor
// pattern, with noise (from hash stream `stream`), clipped at the white level for a bracket, and
// through the camera response.
Image ExposeShot(const Image& img, double eb, const SensorPattern& sp, const PhotoOptions& o, std::uint64_t stream) {
  Image shot = img;
  for (std::size_t i = 0; i < shot.pixels.size(); ++i) {
    double x = eb * sp.gain[i / std::size_t(img.channels)] * img.pixels[i] + sp.dark[i / std::size_t(img.channels)];
    if (o.noise > 0) {  // Box-Muller on a hash: the same noise whatever the thread count
      const double u1 = std::max(HashUniform(o.seed, stream + 1, i), 1e-300), u2 = HashUniform(o.seed, stream + 2, i);
      x += o.noise * std::sqrt(-2 * std::log(u1)) * std::cos(2 * kPi * u2);
    }
    x = std::max(0.0, x);
    if (!o.brackets.empty()) x = std::min(1.0, x);  // the white level (integer writing clips there anyway)
    if (o.response_gamma > 0) x = CameraResponse(o, x);
    shot.pixels[i] = static_cast<float>(x);
  }
  return shot;
}

// The ground truth of one photo: the camera pose, its plate homography and the pixels of the
// marker corners (and ChArUco corners) at least one pixel inside the image.
PhotoTruth TruthOf(const CameraPose& cam, const Board& board, const PhotoOptions& o, const std::string& file) {
  PhotoTruth tr;
  tr.file = file;
  tr.image_from_plate = cam.PlateHomography();
  tr.camera_from_plate_rotation = cam.camera_from_plate_rotation;
  tr.camera_from_plate_translation = cam.camera_from_plate_translation;
  for (const Marker& m : board.markers) {
    std::array<Vec2, 4> px;
    bool visible = true;
    for (int q = 0; q < 4; ++q) {
      visible = visible && cam.Project(Vec3(m.corners_mm[q].x(), m.corners_mm[q].y(), m.height_mm), &px[q]);
      visible = visible && px[q].x() >= 1 && px[q].y() >= 1 && px[q].x() <= o.width - 2 && px[q].y() <= o.height - 2;
    }
    if (visible) tr.marker_corners_px[m.id] = px;
  }
  if (board.charuco.valid()) {
    const std::vector<Vec2> corners = CharucoCornersMm(board.charuco);
    for (std::size_t id = 0; id < corners.size(); ++id) {
      Vec2 px;
      if (cam.Project(Vec3(corners[id].x(), corners[id].y(), 0), &px) && px.x() >= 1 && px.y() >= 1 &&
          px.x() <= o.width - 2 && px.y() <= o.height - 2)
        tr.charuco_corners_px[static_cast<int>(id)] = px;
    }
  }
  return tr;
}

}  // namespace

PhotoSummary SynthesizePhotos(const PhotoOptions& o, const SvbrdfModel& model, const std::filesystem::path& out_dir,
                              const Reporter& reporter, const nlohmann::json& extra) {
  o.Check();
  AtomicDirectory output(out_dir, "manifest.json");
  const std::filesystem::path& dir = output.temp_path();
  const Board board = MakeBoard(o, model.tile_size_mm());
  const auto pairs = SelectPhotos(o);
  for (const auto& [v, l] : pairs) MakeCamera(o, board, o.views[v]);  // fail fast on impossible views
  const double intensity =
      o.light_intensity > 0 ? o.light_intensity : (o.light_distance_mm > 0 ? o.light_distance_mm * o.light_distance_mm : 1.0);
  Manifest manifest = PhotoManifest(o, model, extra);
  std::vector<PhotoTruth> truth;
  PhotoSummary summary;
  PhaseTimes times;
  const ImageWriteOptions wopt = PhotoWriteOptions(o);
  const std::string ext = o.format == "exr" ? ".exr" : (o.format == "jpeg" ? ".jpg" : ".png");
  const SensorPattern sensor = MakeSensorPattern(o);
  if (o.vignetting > 0 || o.dark_level > 0) WriteReferenceFrames(o, sensor, dir, ext, wopt, &manifest);
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    reporter.Progress(k, pairs.size(), "photos");
    const auto [vi, li] = pairs[k];
    const Vec3 vdir = o.views[vi], ldir = o.lights[li];
    const CameraPose cam = MakeCamera(o, board, vdir);
    Timer t;
    Image img = RenderPhoto(model, board, o, cam, vdir, ldir);
    if (o.psf == "disc")
      DiscBlur(img, o.disc_radius_px);
    else
      GaussianBlur(img, o.blur_px);
    times.Add("render", t.Seconds());
    t.Restart();
    double peak = 0;
    for (float x : img.pixels) peak = std::max(peak, static_cast<double>(x));
    double exposure = o.exposure;
    if (exposure <= 0) exposure = (o.format == "exr" || peak <= 0) ? 1.0 : 0.9 / peak;
    PhotoEntry e;
    const std::vector<double> factors = o.brackets.empty() ? std::vector<double>{1.0} : o.brackets;
    for (std::size_t b = 0; b < factors.size(); ++b) {
      const double eb = exposure * factors[b];
      const std::uint64_t stream = (k + b * pairs.size()) * 2;  // bracket 0: the single photo's noise
      const std::string file = o.brackets.empty() ? fmt::format("v{:03d}_l{:03d}{}", vi, li, ext)
                                                  : fmt::format("v{:03d}_l{:03d}_e{}{}", vi, li, b, ext);
      WriteImage(dir / file, ExposeShot(img, eb, sensor, o, stream), wopt);
      if (!o.brackets.empty()) e.brackets.push_back({file, eb});
      summary.files.push_back(file);
    }
    times.Add("write", t.Seconds());
    const std::string file = o.brackets.empty() ? summary.files.back() : e.brackets[0].file;
    e.file = file;
    e.view_index = vi;
    e.light_index = li;
    e.view_dir = vdir.normalized();
    e.light_dir = ldir.normalized();
    e.exposure = o.brackets.empty() ? exposure : e.brackets[0].exposure;
    e.light_intensity = intensity;
    e.light_distance_mm = o.light_distance_mm;
    e.camera_distance_mm = o.camera_distance_mm;
    e.camera = cam.camera;
    manifest.photos.push_back(e);
    truth.push_back(TruthOf(cam, board, o, file));
  }
  reporter.Progress(pairs.size(), pairs.size(), "photos");
  WriteBoard(dir / "board.json", board);
  WriteTruth(dir / "truth.json", truth);
  WriteManifest(dir / "manifest.json", manifest);
  output.Commit();
  summary.photos = static_cast<int>(pairs.size());
  summary.times = times;
  return summary;
}

}  // namespace btf
