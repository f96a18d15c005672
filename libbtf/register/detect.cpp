#include "libbtf/register/detect.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <tuple>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h10.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>
#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "libbtf/core/error.h"

// Exported by Debian's libapriltag 3.3 (and declared only in its sources): the quad stage alone.
// Returns a zarray of struct quad (corners only; H and Hinv are still null).
extern "C" zarray_t* apriltag_quad_thresh(apriltag_detector_t* td, image_u8_t* im);

namespace btf {
namespace {

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
  int max_bits;  // 2 bits for the big families would allocate GBs of decode table (notes 1.5)
};

const std::vector<FamilyEntry>& Families() {
  static const std::vector<FamilyEntry> f = {
      {"tag36h11", tag36h11_create, tag36h11_destroy, 3},
      {"tag36h10", tag36h10_create, tag36h10_destroy, 3},
      {"tag25h9", tag25h9_create, tag25h9_destroy, 3},
      {"tag16h5", tag16h5_create, tag16h5_destroy, 2},
      {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy, 3},
      {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy, 1},
      {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy, 2},
      {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy, 1},
      {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy, 1},
  };
  return f;
}

struct ArucoEntry {
  const char* name;
  int dict;
};
const std::vector<ArucoEntry>& ArucoDictionaries() {
  namespace a = cv::aruco;
  static const std::vector<ArucoEntry> d = {
      {"DICT_4X4_50", a::DICT_4X4_50},         {"DICT_4X4_100", a::DICT_4X4_100},
      {"DICT_4X4_250", a::DICT_4X4_250},       {"DICT_4X4_1000", a::DICT_4X4_1000},
      {"DICT_5X5_50", a::DICT_5X5_50},         {"DICT_5X5_100", a::DICT_5X5_100},
      {"DICT_5X5_250", a::DICT_5X5_250},       {"DICT_5X5_1000", a::DICT_5X5_1000},
      {"DICT_6X6_50", a::DICT_6X6_50},         {"DICT_6X6_100", a::DICT_6X6_100},
      {"DICT_6X6_250", a::DICT_6X6_250},       {"DICT_6X6_1000", a::DICT_6X6_1000},
      {"DICT_7X7_50", a::DICT_7X7_50},         {"DICT_7X7_100", a::DICT_7X7_100},
      {"DICT_7X7_250", a::DICT_7X7_250},       {"DICT_7X7_1000", a::DICT_7X7_1000},
      {"DICT_ARUCO_ORIGINAL", a::DICT_ARUCO_ORIGINAL}, {"DICT_APRILTAG_16h5", a::DICT_APRILTAG_16h5},
      {"DICT_APRILTAG_25h9", a::DICT_APRILTAG_25h9},   {"DICT_APRILTAG_36h10", a::DICT_APRILTAG_36h10},
      {"DICT_APRILTAG_36h11", a::DICT_APRILTAG_36h11},
  };
  return d;
}
constexpr const char* kArucoPrefix = "aruco:";

std::string KnownFamilies() {
  std::string known;
  for (const auto& e : Families()) known += std::string(known.empty() ? "" : ", ") + e.name;
  return known + ", or aruco:DICT_4X4_50 .. aruco:DICT_APRILTAG_36h11 (OpenCV's predefined dictionaries)";
}

const FamilyEntry& FindFamily(const std::string& name) {
  for (const auto& e : Families())
    if (name == e.name) return e;
  ThrowUsage("unknown tag family '{}': use one of {}", name, KnownFamilies());
}

int FindAruco(const std::string& family) {
  const std::string name = family.substr(std::string(kArucoPrefix).size());
  for (const auto& e : ArucoDictionaries())
    if (name == e.name) return e.dict;
  ThrowUsage("unknown ArUco dictionary '{}': use one of {}", family, KnownFamilies());
}

// Families whose black border is the outer ring of the detection square (every data bit inside
// it): only these can carry a wider border.
bool ClassicFamily(const std::string& name) {
  return name == "tag16h5" || name == "tag25h9" || name == "tag36h10" || name == "tag36h11";
}

bool IsArucoFamily(const std::string& family) { return family.rfind(kArucoPrefix, 0) == 0; }

}  // namespace

void TagDetectorOptions::Check() const {
  if (IsArucoFamily(family)) {
    FindAruco(family);
  } else {
    FindFamily(family);
    if (border_bits != 1 && !ClassicFamily(family))
      ThrowUsage("invalid option 'border_bits': {} has data bits outside its border ring; a {}-bit border is "
                 "supported for tag16h5, tag25h9, tag36h10 and tag36h11 only",
                 family, border_bits);
  }
  BTF_CHECK_OPTION(border_bits >= 1 && border_bits <= 2, "border_bits", "1 or 2");
  BTF_CHECK_OPTION(bits_corrected >= 0 && bits_corrected <= 3, "bits_corrected", "0..3");
  BTF_CHECK_OPTION(quad_decimate >= 1 && quad_decimate <= 8, "quad_decimate", "1..8");
  BTF_CHECK_OPTION(decode_sharpening >= 0 && decode_sharpening <= 4, "decode_sharpening", "0..4");
  BTF_CHECK_OPTION(max_hamming >= 0 && max_hamming <= 3, "max_hamming", "0..3");
  BTF_CHECK_OPTION(std::isfinite(min_decision_margin) && min_decision_margin >= 0, "min_decision_margin", ">= 0");
  BTF_CHECK_OPTION(std::isfinite(border_margin_px) && border_margin_px >= 0, "border_margin_px", ">= 0");
  BTF_CHECK_OPTION(x_corners == "lines" || x_corners == "cornersubpix" || x_corners == "none", "x_corners",
                   "lines, cornersubpix or none");
  BTF_CHECK_OPTION(std::isfinite(subpix_window) && subpix_window > 0 && subpix_window <= 1, "subpix_window", "(0, 1]");
}

std::vector<std::string> TagFamilies() {
  std::vector<std::string> names;
  for (const auto& e : Families()) names.emplace_back(e.name);
  for (const auto& e : ArucoDictionaries()) names.push_back(std::string(kArucoPrefix) + e.name);
  return names;
}

struct TagDetector::Impl {
  const FamilyEntry* entry = nullptr;
  apriltag_family_t* family = nullptr;
  // A wider border: a copy of the family with the detection square border_bits - 1 modules wider
  // on each side and the data bits shifted inwards by as much (codes shared with `family`).
  apriltag_family_t wide{};
  std::vector<std::uint32_t> wide_x, wide_y;
  std::string wide_name;
  apriltag_detector_t* detector = nullptr;
  // ArUco (OpenCV): dictionary and parameters; width = modules across the detection square.
  cv::Ptr<cv::aruco::Dictionary> aruco;
  cv::Ptr<cv::aruco::DetectorParameters> aruco_params;
  int modules = 0;
  const apriltag_family_t* used = nullptr;  // the family libapriltag decodes (the wide copy or the original)
  ~Impl() {
    // The detector references the family: destroy it first (notes 1.1).
    if (detector) apriltag_detector_destroy(detector);
    if (family) entry->destroy(family);
  }
};

TagDetector::TagDetector(const TagDetectorOptions& options) : impl_(std::make_unique<Impl>()), options_(options) {
  options_.Check();
  if (IsArucoFamily(options_.family)) {
    impl_->aruco = cv::aruco::getPredefinedDictionary(
        static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(FindAruco(options_.family)));
    impl_->aruco_params = cv::aruco::DetectorParameters::create();
    impl_->aruco_params->markerBorderBits = options_.border_bits;
    impl_->aruco_params->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;  // our edge fit refines
    impl_->modules = impl_->aruco->markerSize + 2 * options_.border_bits;
    return;
  }
  impl_->entry = &FindFamily(options_.family);
  impl_->family = impl_->entry->create();
  impl_->detector = apriltag_detector_create();
  if (!impl_->family || !impl_->detector) throw Error(ExitCode::kInternal, "libapriltag: cannot create the detector");
  apriltag_family_t* used = impl_->family;
  if (options_.border_bits > 1) {
    const int extra = options_.border_bits - 1;
    Impl& m = *impl_;
    m.wide = *m.family;
    m.wide.width_at_border += 2 * extra;
    m.wide.total_width += 2 * extra;
    m.wide_x.assign(m.family->bit_x, m.family->bit_x + m.family->nbits);
    m.wide_y.assign(m.family->bit_y, m.family->bit_y + m.family->nbits);
    for (auto& v : m.wide_x) v += static_cast<std::uint32_t>(extra);
    for (auto& v : m.wide_y) v += static_cast<std::uint32_t>(extra);
    m.wide.bit_x = m.wide_x.data();
    m.wide.bit_y = m.wide_y.data();
    m.wide_name = fmt::format("{}b{}", m.family->name, options_.border_bits);
    m.wide.name = m.wide_name.data();
    m.wide.impl = nullptr;  // the decode table: built by add_family_bits, freed by the detector
    used = &m.wide;
  }
  impl_->modules = used->width_at_border;
  impl_->used = used;
  errno = 0;
  apriltag_detector_add_family_bits(impl_->detector, used, std::min(options_.bits_corrected, impl_->entry->max_bits));
  if (errno == ENOMEM)
    throw Error(ExitCode::kInternal,
                fmt::format("libapriltag: out of memory building the decode table of {} with {} bits: lower "
                            "bits_corrected",
                            options_.family, options_.bits_corrected));
  impl_->detector->quad_decimate = static_cast<float>(options_.quad_decimate);
  impl_->detector->quad_sigma = 0;  // non-zero would blur the caller's buffer in place (notes 1.5)
  impl_->detector->refine_edges = options_.refine_edges;
  impl_->detector->decode_sharpening = options_.decode_sharpening;
  impl_->detector->nthreads = 1;  // parallelism is across photos, one detector per thread
}

TagDetector::~TagDetector() = default;

std::vector<TagDetection> TagDetector::Detect(const unsigned char* gray, int width, int height, int stride) const {
  if (width < 1 || height < 1 || stride < width) ThrowBadInput("tag detection: bad image size {}x{}", width, height);
  if (impl_->aruco) return DetectAruco(gray, width, height, stride);
  // AprilTag reads the buffer only (quad_sigma is 0); its struct wants a non-const pointer.
  image_u8_t im{width, height, stride, const_cast<unsigned char*>(gray)};
  errno = 0;
  zarray_t* dets = apriltag_detector_detect(impl_->detector, &im);
  if (!dets) throw Error(ExitCode::kInternal, "libapriltag: detection failed");
  std::vector<TagDetection> out;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    if (d->hamming > options_.max_hamming || d->decision_margin < options_.min_decision_margin) continue;
    TagDetection t;
    t.id = d->id;
    t.hamming = d->hamming;
    t.decision_margin = d->decision_margin;
    bool inside = true;
    for (int k = 0; k < 4; ++k) {
      // The one place where AprilTag's pixel-corner origin becomes OpenCV's pixel-center origin.
      t.corners[k] = Vec2(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
      const Vec2& c = t.corners[k];
      const double m = options_.border_margin_px;
      if (!(c.x() >= m && c.y() >= m && c.x() <= width - 1 - m && c.y() <= height - 1 - m)) inside = false;
    }
    t.center = Vec2(d->c[0] - 0.5, d->c[1] - 0.5);
    if (inside) out.push_back(t);  // border-cut tags can decode with wrong corners (notes 1.5)
  }
  apriltag_detections_destroy(dets);
  std::sort(out.begin(), out.end(), [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  return out;
}

bool TagDetector::DecodeQuad(const std::vector<unsigned char>& gray, int w, int h, std::array<Vec2, 4> q,
                             TagDetection* out) const {
  const apriltag_family_t& f = *impl_->used;
  const double W = impl_->modules;
  // Tag frame (modules, u right, v down, (0,0) = top-left of the detection square) -> AprilTag
  // pixels, with the quad's corners as TL, TR, BR, BL; reversed if that order is mirrored on screen.
  const Vec2 e1 = q[1] - q[0], e2 = q[3] - q[0];
  if (e1.x() * e2.y() - e1.y() * e2.x() < 0) std::swap(q[1], q[3]);
  cv::Mat H = cv::getPerspectiveTransform(
      std::vector<cv::Point2f>{{0, 0}, {static_cast<float>(W), 0}, {static_cast<float>(W), static_cast<float>(W)},
                               {0, static_cast<float>(W)}},
      std::vector<cv::Point2f>{{static_cast<float>(q[0].x()), static_cast<float>(q[0].y())},
                               {static_cast<float>(q[1].x()), static_cast<float>(q[1].y())},
                               {static_cast<float>(q[2].x()), static_cast<float>(q[2].y())},
                               {static_cast<float>(q[3].x()), static_cast<float>(q[3].y())}});
  const auto map = [&](double u, double v) {
    const double x = H.at<double>(0, 0) * u + H.at<double>(0, 1) * v + H.at<double>(0, 2);
    const double y = H.at<double>(1, 0) * u + H.at<double>(1, 1) * v + H.at<double>(1, 2);
    const double z = H.at<double>(2, 0) * u + H.at<double>(2, 1) * v + H.at<double>(2, 2);
    return Vec2(x / z, y / z);
  };
  bool ok = true;
  const auto sample = [&](double u, double v) {  // bilinear on the 8-bit image, AprilTag pixel convention
    const Vec2 p = map(u, v) - Vec2(0.5, 0.5);
    if (!(p.x() >= 0 && p.y() >= 0 && p.x() <= w - 1 && p.y() <= h - 1)) {
      ok = false;
      return 0.0;
    }
    const int x0 = std::min(static_cast<int>(p.x()), w - 2), y0 = std::min(static_cast<int>(p.y()), h - 2);
    const double fx = p.x() - x0, fy = p.y() - y0;
    const unsigned char* r0 = &gray[static_cast<std::size_t>(y0) * w + x0];
    const unsigned char* r1 = r0 + w;
    return (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
  };
  // Black level: the border ring half a module inside; white: half a module outside.
  double black = 0, white = 0;
  int n = 0;
  for (int k = 0; k < static_cast<int>(W); ++k) {
    const double t = k + 0.5;
    black += sample(t, 0.5) + sample(t, W - 0.5) + sample(0.5, t) + sample(W - 0.5, t);
    white += sample(t, -0.5) + sample(t, W + 0.5) + sample(-0.5, t) + sample(W + 0.5, t);
    n += 4;
  }
  if (!ok) return false;
  black /= n, white /= n;
  if (!(white - black > 20)) return false;
  const double thr = 0.5 * (black + white);
  // The code read in each of the 4 rotations of the tag frame; best match over the family.
  int best_h = 99, best_id = -1, best_rot = 0;
  double margin = 0;
  for (int rot = 0; rot < 4; ++rot) {
    std::uint64_t code = 0;
    double m = 1e9;
    for (std::uint32_t i = 0; i < f.nbits; ++i) {
      double u = f.bit_x[i] + 0.5, v = f.bit_y[i] + 0.5;
      for (int r = 0; r < rot; ++r) std::tie(u, v) = std::make_pair(W - v, u);  // 90 deg on screen
      const double val = sample(u, v);
      code = (code << 1) | (val > thr ? 1u : 0u);
      m = std::min(m, std::abs(val - thr));
    }
    if (!ok) return false;
    for (std::uint32_t id = 0; id < f.ncodes; ++id) {
      const int hd = __builtin_popcountll(code ^ f.codes[id]);
      if (hd < best_h) best_h = hd, best_id = static_cast<int>(id), best_rot = rot, margin = m;
    }
  }
  // The margin here is the smallest |sample - threshold| over the data bits in 8-bit grey levels
  // (libapriltag's decision margin is a different statistic): a quarter of min_decision_margin.
  if (best_id < 0 || best_h > options_.max_hamming || margin < options_.min_decision_margin / 4) return false;
  // Corners of the upright tag (LB, RB, RT, LT in its frame) through the same rotation, into
  // OpenCV's pixel convention.
  const std::array<Vec2, 4> upright = {Vec2(0, W), Vec2(W, W), Vec2(W, 0), Vec2(0, 0)};
  out->id = best_id;
  out->hamming = best_h;
  out->decision_margin = margin;
  Vec2 centre = Vec2::Zero();
  for (int k = 0; k < 4; ++k) {
    double u = upright[static_cast<std::size_t>(k)].x(), v = upright[static_cast<std::size_t>(k)].y();
    for (int r = 0; r < best_rot; ++r) std::tie(u, v) = std::make_pair(W - v, u);
    out->corners[k] = map(u, v) - Vec2(0.5, 0.5);
    centre += 0.25 * out->corners[k];
    const double mg = options_.border_margin_px;
    const Vec2& c = out->corners[k];
    if (!(c.x() >= mg && c.y() >= mg && c.x() <= w - 1 - mg && c.y() <= h - 1 - mg)) return false;
  }
  out->center = centre;
  return true;
}

std::vector<TagDetection> TagDetector::DetectAruco(const unsigned char* gray, int width, int height, int stride) const {
  const cv::Mat im(height, width, CV_8UC1, const_cast<unsigned char*>(gray), static_cast<std::size_t>(stride));
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(im, impl_->aruco, corners, ids, impl_->aruco_params);
  std::vector<TagDetection> out;
  // OpenCV's order is clockwise from the marker's top-left (TL, TR, BR, BL), pixel centers at
  // integers (no shift). Ours is LB, RB, RT, LT of the upright marker. OpenCV 4.6 draws its
  // DICT_APRILTAG_* markers rotated by 180 degrees relative to apriltag-imgs (notes 1.3), so for
  // those the upright printed tag's LB is OpenCV's TR.
  const bool apriltag_dict = options_.family.find("APRILTAG") != std::string::npos;
  const std::array<int, 4> order = apriltag_dict ? std::array<int, 4>{1, 0, 3, 2} : std::array<int, 4>{3, 2, 1, 0};
  for (std::size_t i = 0; i < ids.size(); ++i) {
    TagDetection t;
    t.id = ids[i];
    bool inside = true;
    Vec2 c = Vec2::Zero();
    for (int k = 0; k < 4; ++k) {
      const cv::Point2f& p = corners[i][static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
      t.corners[k] = Vec2(p.x, p.y);
      c += 0.25 * t.corners[k];
      const double m = options_.border_margin_px;
      if (!(p.x >= m && p.y >= m && p.x <= width - 1 - m && p.y <= height - 1 - m)) inside = false;
    }
    t.center = c;
    if (inside) out.push_back(t);
  }
  std::sort(out.begin(), out.end(), [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  return out;
}

namespace {
std::vector<float> LinearGray(const Image& image) {
  const std::size_t n = static_cast<std::size_t>(image.width) * image.height;
  std::vector<float> gray(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float* p = &image.pixels[i * image.channels];
    float g = image.channels >= 3 ? 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2] : p[0];
    gray[i] = std::isfinite(g) ? std::max(g, 0.0f) : 0.0f;
  }
  return gray;
}

std::vector<unsigned char> Quantize(const std::vector<float>& gray) {
  const std::size_t n = gray.size();
  std::vector<float> sorted = gray;
  const std::size_t k = std::min(n - 1, static_cast<std::size_t>(0.995 * static_cast<double>(n)));
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k), sorted.end());
  const float top = sorted[k] > 0 ? sorted[k] : 1.0f;
  std::vector<unsigned char> out(n);
  for (std::size_t i = 0; i < n; ++i)
    out[i] = static_cast<unsigned char>(std::lround(std::clamp(gray[i] / top, 0.0f, 1.0f) * 255.0f));
  return out;
}

double Bilinear(const std::vector<float>& g, int w, int h, double x, double y, bool* ok) {
  if (!(x >= 0 && y >= 0 && x <= w - 1 && y <= h - 1)) {
    *ok = false;
    return 0;
  }
  const int x0 = std::min(static_cast<int>(x), w - 2), y0 = std::min(static_cast<int>(y), h - 2);
  const double fx = x - x0, fy = y - y0;
  const float* r0 = &g[static_cast<std::size_t>(y0) * w + x0];
  const float* r1 = r0 + w;
  return (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
}

}  // namespace

std::vector<unsigned char> GrayForDetection(const Image& image) { return Quantize(LinearGray(image)); }

namespace {

// The dark -> bright step on the profile through p along the unit `normal` (dark side at -normal),
// over [-module / 2, module / 2]: false if the profile has no contrast, leaves the image or puts the
// step outside the window.
bool EdgeOnProfile(const std::vector<float>& gray, int w, int h, const Vec2& p, const Vec2& normal, double module,
                   Vec2* edge) {
  bool ok = true;
  const double dark = Bilinear(gray, w, h, p.x() - 0.5 * module * normal.x(), p.y() - 0.5 * module * normal.y(), &ok);
  const double bright = Bilinear(gray, w, h, p.x() + 0.5 * module * normal.x(), p.y() + 0.5 * module * normal.y(), &ok);
  if (!ok || !(bright - dark > 1e-6)) return false;
  // Edge position from the profile's area: for a step from `dark` to `bright` at s_e, the
  // integral of the normalized profile over [-m/2, m/2] is m/2 - s_e, and any blur narrower
  // than the window preserves it. Less sensitive to interpolation error than a level crossing.
  const int nsteps = std::max(8, static_cast<int>(module / 0.05));
  const double step = module / nsteps;
  double area = 0;
  for (int k = 0; k <= nsteps && ok; ++k) {
    const double s = -0.5 * module + k * step;
    const double v = Bilinear(gray, w, h, p.x() + s * normal.x(), p.y() + s * normal.y(), &ok);
    const double u = std::clamp((v - dark) / (bright - dark), 0.0, 1.0);
    area += (k == 0 || k == nsteps ? 0.5 : 1.0) * u * step;
  }
  const double best = 0.5 * module - area;
  if (!ok || !(std::abs(best) < 0.5 * module)) return false;
  *edge = p + best * normal;
  return true;
}

// Total-least-squares line a x + b y + d = 0, (a, b) unit.
Eigen::Vector3d FitLine(const std::vector<Vec2>& pts) {
  Vec2 mean = Vec2::Zero();
  for (const auto& q : pts) mean += q;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const auto& q : pts) cov += (q - mean) * (q - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
  const Vec2 n = es.eigenvectors().col(0);  // smallest eigenvalue: the normal
  return Eigen::Vector3d(n.x(), n.y(), -n.dot(mean));
}

// Sub-pixel corner refinement used by Detect(const Image&) when refine_corners is set: along each
// edge of the quad, the 50% crossing between the black border level (half a module inside) and
// the quiet-zone level (half a module outside) is located on profiles normal to the edge in the
// linear gray image (exact for a straight edge under any symmetric blur); a total-least-squares
// line per edge; corners = intersections of adjacent lines. Two passes. `modules` = the family's
// width_at_border. Returns false (corners unchanged) if an edge has too few valid profiles or a
// corner would move by more than `max_move_px`.
bool RefineTagCorners(const std::vector<float>& gray, int w, int h, int modules, std::array<Vec2, 4>* corners,
                      double max_move_px = 3.0) {
  if (w < 2 || h < 2) return false;
  for (int pass = 0; pass < 2; ++pass) {
    std::array<Vec2, 4>& c = *corners;
    // The quad's center decides which side of an edge is inside (order-agnostic).
    const Vec2 center = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    std::array<Eigen::Vector3d, 4> lines;  // a x + b y + d = 0 with (a, b) unit
    for (int e = 0; e < 4; ++e) {
      const Vec2 a = c[e], b = c[(e + 1) % 4];
      const Vec2 dir = (b - a).normalized();
      Vec2 normal(-dir.y(), dir.x());
      if ((center - a).dot(normal) > 0) normal = -normal;  // outward
      // Module size across this edge: the adjacent edges' lengths / modules, projected on the normal.
      const double across = std::min(std::abs((c[(e + 3) % 4] - a).dot(normal)), std::abs((c[(e + 2) % 4] - b).dot(normal)));
      const double module = across / modules;
      if (!(module > 1.0)) return false;  // under 1 px per module the profiles carry no sub-pixel information
      const double len = (b - a).norm();
      const int samples = std::clamp(static_cast<int>(len / 1.5), 8, 200);
      std::vector<Vec2> pts;
      for (int i = 0; i < samples; ++i) {
        // Stay a module away from the corners, where the neighboring edge bends the profile.
        const double t = module / len + (1 - 2 * module / len) * (i + 0.5) / samples;
        if (t <= 0 || t >= 1) continue;
        Vec2 q;
        if (EdgeOnProfile(gray, w, h, a + t * (b - a), normal, module, &q)) pts.push_back(q);
      }
      if (pts.size() < 4) return false;
      lines[e] = FitLine(pts);
    }
    std::array<Vec2, 4> refined;
    for (int k = 0; k < 4; ++k) {
      // Corner k joins edge k-1 (c[k-1] -> c[k]) and edge k (c[k] -> c[k+1]).
      const Eigen::Vector3d x = lines[(k + 3) % 4].cross(lines[k]);
      if (!(std::abs(x.z()) > 1e-12)) return false;
      refined[k] = x.head<2>() / x.z();
      if (!refined[k].allFinite() || (refined[k] - c[k]).norm() > max_move_px) return false;  // must stay local
    }
    c = refined;
  }
  return true;
}

// Is corner k of c an X-junction (dark outward diagonal)? u, v: one module along each edge.
bool IsXJunction(const std::vector<float>& gray, int w, int h, const Vec2& c, const Vec2& u, const Vec2& v) {
  bool ok = true;
  const Vec2 b = c + 0.5 * (u + v), g1 = c + 1.5 * v - 0.5 * u, g2 = c + 1.5 * u - 0.5 * v, o = c - 0.5 * (u + v);
  const double black = Bilinear(gray, w, h, b.x(), b.y(), &ok);
  const double white = 0.5 * (Bilinear(gray, w, h, g1.x(), g1.y(), &ok) + Bilinear(gray, w, h, g2.x(), g2.y(), &ok));
  const double out = Bilinear(gray, w, h, o.x(), o.y(), &ok);
  return ok && white > 2 * black && out < 0.5 * (black + white);
}

constexpr int kXLinePasses = 3;

// X-junction corners by lines: each of the corner's two edges continues past the junction as the
// corner square's edge, with the dark side swapped. One line per edge through edge points on both
// sides, at the same distances (1..2 modules) from the corner: a tone curve or a one-sided blur
// moves the two sides' points in opposite directions, and the line at the corner is their mean.
void RefineXCornersByLines(const std::vector<float>& gray, int w, int h, int modules, std::array<Vec2, 4>* corners) {
  std::array<Vec2, 4>& c = *corners;
  const std::array<Vec2, 4> first = c;
  for (int k = 0; k < 4; ++k) {
    const Vec2 u = (first[(k + 3) % 4] - first[k]) / modules, v = (first[(k + 1) % 4] - first[k]) / modules;
    const double module = std::min(u.norm(), v.norm());
    if (!(module > 1.0) || !IsXJunction(gray, w, h, first[k], u, v)) continue;
    // Passes: the sample distances are mirrored about the current corner, so a first corner off by
    // a tone curve's shift is refined again from the better one.
    for (int pass = 0; pass < kXLinePasses; ++pass) {
    std::array<Eigen::Vector3d, 2> lines;
    bool ok = true;
    for (int e = 0; e < 2 && ok; ++e) {
      const Vec2 along = (e == 0 ? u : v).normalized(), other = e == 0 ? v : u;
      Vec2 normal(-along.y(), along.x());  // outward from the tag across this edge
      if (normal.dot(other) > 0) normal = -normal;
      const double m = std::abs(other.dot(normal));  // the module across this edge
      const int n = std::max(4, static_cast<int>(m / 0.5));
      std::vector<Vec2> pts;
      int tag_side = 0, square_side = 0;
      for (int i = 0; i < n; ++i) {
        const double t = (1 + (i + 0.5) / n) * (e == 0 ? u : v).norm();
        Vec2 q;
        if (EdgeOnProfile(gray, w, h, c[k] + t * along, normal, m, &q)) pts.push_back(q), ++tag_side;
        if (EdgeOnProfile(gray, w, h, c[k] - t * along, -normal, m, &q)) pts.push_back(q), ++square_side;
      }
      ok = tag_side >= 3 && square_side >= 3;
      if (ok) lines[static_cast<std::size_t>(e)] = FitLine(pts);
    }
    const Eigen::Vector3d x = lines[0].cross(lines[1]);
    if (!ok || !(std::abs(x.z()) > 1e-12)) {
      c[k] = first[k];
      break;
    }
    const Vec2 r = x.head<2>() / x.z();
    if (!r.allFinite() || (r - first[k]).norm() > module) {
      c[k] = first[k];
      break;
    }
    c[k] = r;
    }
  }
}

// The X-junction refinement of the header ("Corner refinement"). `border` = border_bits; corners
// that are not X-junctions, or whose refinement fails its checks, are left as they are.
void RefineXCorners(const std::vector<float>& gray, int w, int h, int modules, int border, double window,
                    std::array<Vec2, 4>* corners) {
  std::array<Vec2, 4>& c = *corners;
  const cv::Mat imf(h, w, CV_32FC1, const_cast<float*>(gray.data()));
  for (int k = 0; k < 4; ++k) {
    // One module along each edge from corner k towards the tag's other corners.
    const Vec2 u = (c[(k + 3) % 4] - c[k]) / modules, v = (c[(k + 1) % 4] - c[k]) / modules;
    const double module = std::min(u.norm(), v.norm());
    if (!(module > 1.0)) continue;
    if (!IsXJunction(gray, w, h, c[k], u, v)) continue;  // no contrast, or an L corner
    const int half = std::max(2, static_cast<int>(window * border * module / std::sqrt(2.0)));
    if (!(c[k].x() >= half + 1 && c[k].y() >= half + 1 && c[k].x() <= w - 2 - half && c[k].y() <= h - 2 - half)) continue;
    std::vector<cv::Point2f> p = {cv::Point2f(static_cast<float>(c[k].x()), static_cast<float>(c[k].y()))};
    cv::cornerSubPix(imf, p, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-4));
    const Vec2 r(p[0].x, p[0].y);
    if (r.allFinite() && (r - c[k]).norm() <= module) c[k] = r;
  }
}

}  // namespace

void CharucoOptions::Check() const {
  BTF_CHECK_OPTION(max_window_px >= 2 && max_window_px <= 64, "max_window_px", "2..64");
  BTF_CHECK_OPTION(std::isfinite(max_move_px) && max_move_px > 0, "max_move_px", "> 0");
  BTF_CHECK_OPTION(std::isfinite(border_margin_px) && border_margin_px >= 0, "border_margin_px", ">= 0");
}

std::vector<CharucoCorner> DetectCharucoCorners(const Image& image, const CharucoDefinition& def,
                                                const std::vector<TagDetection>& markers, const CharucoOptions& o) {
  o.Check();
  const std::vector<Vec2> board_mm = CharucoCornersMm(def);  // validates the definition
  const cv::Ptr<cv::aruco::CharucoBoard> board = cv::aruco::CharucoBoard::create(
      def.squares_x, def.squares_y, static_cast<float>(def.square_mm), static_cast<float>(def.marker_mm),
      cv::aruco::getPredefinedDictionary(
          static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(FindAruco(kArucoPrefix + def.dictionary))));
  // Back to OpenCV's marker corner order (TL, TR, BR, BL of the marker as drawn = our LT, RT, RB, LB).
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  const int n_markers = static_cast<int>(board->ids.size());
  for (const auto& d : markers) {
    if (d.id < 0 || d.id >= n_markers) continue;
    std::vector<cv::Point2f> c;
    for (int k = 3; k >= 0; --k) c.emplace_back(static_cast<float>(d.corners[k].x()), static_cast<float>(d.corners[k].y()));
    corners.push_back(std::move(c));
    ids.push_back(d.id);
  }
  std::vector<CharucoCorner> out;
  if (ids.empty()) return out;
  const int w = image.width, h = image.height;
  const std::vector<float> gray = LinearGray(image);
  const std::vector<unsigned char> gray8 = Quantize(gray);
  const cv::Mat im8(h, w, CV_8UC1, const_cast<unsigned char*>(gray8.data()));
  std::vector<cv::Point2f> first;
  std::vector<int> first_ids;
  cv::aruco::interpolateCornersCharuco(corners, ids, im8, board, first, first_ids);
  const cv::Mat imf(h, w, CV_32FC1, const_cast<float*>(gray.data()));
  for (std::size_t i = 0; i < first.size(); ++i) {
    // The nearest marker corner bounds the window: cornerSubPix assumes the window holds the
    // corner's two edges only.
    double nearest = 1e30;
    for (const auto& c : corners)
      for (const auto& p : c) nearest = std::min(nearest, std::hypot(double(p.x) - first[i].x, double(p.y) - first[i].y));
    const int half = std::clamp(static_cast<int>(0.7 * nearest / std::sqrt(2.0)), 2, o.max_window_px);
    std::vector<cv::Point2f> p = {first[i]};
    if (!(p[0].x >= half + 1 && p[0].y >= half + 1 && p[0].x <= w - 2 - half && p[0].y <= h - 2 - half)) continue;
    cv::cornerSubPix(imf, p, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-4));
    if (std::hypot(double(p[0].x) - first[i].x, double(p[0].y) - first[i].y) > o.max_move_px) continue;
    const double m = o.border_margin_px;
    if (!(p[0].x >= m && p[0].y >= m && p[0].x <= w - 1 - m && p[0].y <= h - 1 - m)) continue;
    CharucoCorner c;
    c.id = first_ids[i];
    c.pixel = Vec2(p[0].x, p[0].y);
    c.board_mm = board_mm[static_cast<std::size_t>(c.id)];
    out.push_back(c);
  }
  std::sort(out.begin(), out.end(), [](const CharucoCorner& a, const CharucoCorner& b) { return a.id < b.id; });
  return out;
}

std::vector<TagDetection> TagDetector::Detect(const Image& image) const {
  if (image.width < 1 || image.height < 1 || image.channels < 1) ThrowBadInput("tag detection: empty image");
  const std::vector<float> gray = LinearGray(image);
  const std::vector<unsigned char> gray8 = Quantize(gray);
  std::vector<TagDetection> dets = Detect(gray8.data(), image.width, image.height, image.width);
  if (options_.split_touching && options_.border_bits >= 2 && !impl_->aruco) {
    // Kalibr's corner squares touch the tags diagonally; wherever the thresholded image joins them
    // (or splits the white gaps at the joints), libapriltag's segmentation finds no quad for the tag.
    const int w = image.width, h = image.height;
    // 1. Dark regions eroded by a 3 x 3 maximum (symmetric: no shift): the joints open, libapriltag
    //    finds the quads, but thin data modules may erode away, so the ids are not trusted yet.
    //    On the sRGB-encoded image: its brighter mid-tones open the joints further.
    std::vector<unsigned char> encoded(gray8.size()), eroded(gray8.size());
    for (std::size_t i = 0; i < gray8.size(); ++i)
      encoded[i] = static_cast<unsigned char>(std::lround(255 * LinearToSrgb(gray8[i] / 255.0f)));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        unsigned char v = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            v = std::max(v, encoded[static_cast<std::size_t>(std::clamp(y + dy, 0, h - 1)) * w + std::clamp(x + dx, 0, w - 1)]);
        eroded[static_cast<std::size_t>(y) * w + x] = v;
      }
    // 2. Each quad found there is decoded on the original image (DecodeQuad); only ids the first
    //    pass missed are added.
    image_u8_t eim{w, h, w, eroded.data()};
    zarray_t* quads = apriltag_quad_thresh(impl_->detector, &eim);
    if (!quads) throw Error(ExitCode::kInternal, "libapriltag: quad detection failed");
    for (int i = 0; i < zarray_size(quads); ++i) {
      struct quad* q = nullptr;
      zarray_get_volatile(quads, i, &q);
      std::array<Vec2, 4> c;
      for (int k = 0; k < 4; ++k) c[k] = Vec2(q->p[k][0], q->p[k][1]);
      std::free(q->H);  // null here; a 3.3 matd_t is one calloc block (notes 1.1)
      std::free(q->Hinv);
      TagDetection d;
      if (!DecodeQuad(gray8, w, h, c, &d)) continue;
      if (std::any_of(dets.begin(), dets.end(), [&](const TagDetection& e) { return e.id == d.id; })) continue;
      // These corners can be a few px inside the true ones (erosion, the cut joints, the encoded
      // threshold): one fit allowed to move further brings them within the final fit's reach.
      if (options_.refine_corners) {
        std::array<Vec2, 4> r = d.corners;
        const double reach = 0.7 * (r[0] - r[2]).norm() / impl_->modules + 3.0;  // ~ a module + 3 px
        if (!RefineTagCorners(gray, w, h, impl_->modules, &r, reach)) continue;  // no usable edges: leave it out
        d.corners = r;
      }
      dets.push_back(d);
    }
    zarray_destroy(quads);
    std::sort(dets.begin(), dets.end(), [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  }
  if (options_.refine_corners)
    for (auto& d : dets) {
      std::array<Vec2, 4> c = d.corners;
      if (RefineTagCorners(gray, image.width, image.height, impl_->modules, &c)) d.corners = c;
      if (options_.x_corners == "lines")
        RefineXCornersByLines(gray, image.width, image.height, impl_->modules, &d.corners);
      else if (options_.x_corners == "cornersubpix")
        RefineXCorners(gray, image.width, image.height, impl_->modules, options_.border_bits, options_.subpix_window,
                       &d.corners);
    }
  return dets;
}

}  // namespace btf
