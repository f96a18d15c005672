#include "libbtf/register/detect.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <functional>

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

#include "libbtf/core/error.h"

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

const FamilyEntry& FindFamily(const std::string& name) {
  for (const auto& e : Families())
    if (name == e.name) return e;
  std::string known;
  for (const auto& e : Families()) known += std::string(known.empty() ? "" : ", ") + e.name;
  ThrowUsage("unknown tag family '{}': use one of {}", name, known);
}

}  // namespace

void TagDetectorOptions::Check() const {
  FindFamily(family);
  BTF_CHECK_OPTION(bits_corrected >= 0 && bits_corrected <= 3, "bits_corrected", "0..3");
  BTF_CHECK_OPTION(quad_decimate >= 1 && quad_decimate <= 8, "quad_decimate", "1..8");
  BTF_CHECK_OPTION(decode_sharpening >= 0 && decode_sharpening <= 4, "decode_sharpening", "0..4");
  BTF_CHECK_OPTION(max_hamming >= 0 && max_hamming <= 3, "max_hamming", "0..3");
  BTF_CHECK_OPTION(std::isfinite(min_decision_margin) && min_decision_margin >= 0, "min_decision_margin", ">= 0");
  BTF_CHECK_OPTION(std::isfinite(border_margin_px) && border_margin_px >= 0, "border_margin_px", ">= 0");
}

std::vector<std::string> TagFamilies() {
  std::vector<std::string> names;
  for (const auto& e : Families()) names.emplace_back(e.name);
  return names;
}

struct TagDetector::Impl {
  const FamilyEntry* entry = nullptr;
  apriltag_family_t* family = nullptr;
  apriltag_detector_t* detector = nullptr;
  ~Impl() {
    // The detector references the family: destroy it first (notes 1.1).
    if (detector) apriltag_detector_destroy(detector);
    if (family) entry->destroy(family);
  }
};

TagDetector::TagDetector(const TagDetectorOptions& options) : impl_(std::make_unique<Impl>()), options_(options) {
  options_.Check();
  impl_->entry = &FindFamily(options_.family);
  impl_->family = impl_->entry->create();
  impl_->detector = apriltag_detector_create();
  if (!impl_->family || !impl_->detector) throw Error(ExitCode::kInternal, "libapriltag: cannot create the detector");
  errno = 0;
  apriltag_detector_add_family_bits(impl_->detector, impl_->family,
                                    std::min(options_.bits_corrected, impl_->entry->max_bits));
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

bool RefineTagCorners(const std::vector<float>& gray, int w, int h, int modules, std::array<Vec2, 4>* corners) {
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
        const Vec2 p = a + t * (b - a);
        bool ok = true;
        const double dark = Bilinear(gray, w, h, p.x() - 0.5 * module * normal.x(), p.y() - 0.5 * module * normal.y(), &ok);
        const double bright = Bilinear(gray, w, h, p.x() + 0.5 * module * normal.x(), p.y() + 0.5 * module * normal.y(), &ok);
        if (!ok || !(bright - dark > 1e-6)) continue;
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
        if (ok && std::abs(best) < 0.5 * module) pts.push_back(p + best * normal);
      }
      if (pts.size() < 4) return false;
      // Total least squares line.
      Vec2 mean = Vec2::Zero();
      for (const auto& q : pts) mean += q;
      mean /= static_cast<double>(pts.size());
      Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
      for (const auto& q : pts) cov += (q - mean) * (q - mean).transpose();
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
      const Vec2 n = es.eigenvectors().col(0);  // smallest eigenvalue: the normal
      lines[e] = Eigen::Vector3d(n.x(), n.y(), -n.dot(mean));
    }
    std::array<Vec2, 4> refined;
    for (int k = 0; k < 4; ++k) {
      // Corner k joins edge k-1 (c[k-1] -> c[k]) and edge k (c[k] -> c[k+1]).
      const Eigen::Vector3d x = lines[(k + 3) % 4].cross(lines[k]);
      if (!(std::abs(x.z()) > 1e-12)) return false;
      refined[k] = x.head<2>() / x.z();
      if (!refined[k].allFinite() || (refined[k] - c[k]).norm() > 3.0) return false;  // refinement must stay local
    }
    c = refined;
  }
  return true;
}

std::vector<TagDetection> TagDetector::Detect(const Image& image) const {
  if (image.width < 1 || image.height < 1 || image.channels < 1) ThrowBadInput("tag detection: empty image");
  const std::vector<float> gray = LinearGray(image);
  const std::vector<unsigned char> gray8 = Quantize(gray);
  std::vector<TagDetection> dets = Detect(gray8.data(), image.width, image.height, image.width);
  if (options_.refine_corners)
    for (auto& d : dets) {
      std::array<Vec2, 4> c = d.corners;
      if (RefineTagCorners(gray, image.width, image.height, impl_->family->width_at_border, &c)) d.corners = c;
    }
  return dets;
}

}  // namespace btf
