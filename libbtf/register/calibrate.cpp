#include "libbtf/register/calibrate.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "libbtf/core/error.h"

namespace btf {
namespace {

struct Input {
  std::filesystem::path path;
  std::string name;        // as reported
  std::string transfer;    // the manifest's, if any
};

std::vector<Input> ExpandInputs(const std::vector<std::filesystem::path>& inputs) {
  std::vector<Input> out;
  for (const auto& p : inputs) {
    std::string ext = p.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext == ".json") {
      const Manifest m = ReadManifest(p);  // its camera is ignored: that is what we estimate
      for (const auto& e : m.photos) out.push_back({p.parent_path() / e.file, e.file, m.transfer});
    } else {
      out.push_back({p, p.string(), ""});
    }
  }
  return out;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// The board points seen in one photo and where: the corners of the board's markers, or with
// ChArUco the chessboard corners between them (z = 0: the board is planar).
struct Correspondences {
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;
  int markers = 0;  // board markers detected
};

Correspondences FindCorrespondences(const Image& im, const TagDetector& detector, const Board& board,
                                    const std::map<int, const Marker*>& by_id, bool charuco) {
  Correspondences c;
  const std::vector<TagDetection> dets = detector.Detect(im);
  for (const auto& d : dets) {
    const auto it = by_id.find(d.id);
    if (it == by_id.end()) continue;
    ++c.markers;
    for (int k = 0; k < 4 && !charuco; ++k) {
      c.object.emplace_back(static_cast<float>(it->second->corners_mm[k].x()), static_cast<float>(it->second->corners_mm[k].y()), 0.0f);
      c.image.emplace_back(static_cast<float>(d.corners[k].x()), static_cast<float>(d.corners[k].y()));
    }
  }
  if (charuco)
    for (const auto& cc : DetectCharucoCorners(im, board.charuco, dets)) {
      c.object.emplace_back(static_cast<float>(cc.board_mm.x()), static_cast<float>(cc.board_mm.y()), 0.0f);
      c.image.emplace_back(static_cast<float>(cc.pixel.x()), static_cast<float>(cc.pixel.y()));
    }
  return c;
}

// OpenCV's camera fit of one model over the used photos' correspondences.
struct CameraFit {
  cv::Mat K, dist;
  std::vector<cv::Mat> rvecs, tvecs;
  double rms_px = 0;
};

CameraFit FitCamera(const std::string& model, const std::vector<std::vector<cv::Point3f>>& object,
                    const std::vector<std::vector<cv::Point2f>>& image, const cv::Size& size) {
  CameraFit f;
  const cv::TermCriteria crit(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-12);
  if (model == "radtan") {
    f.rms_px = cv::calibrateCamera(object, image, size, f.K, f.dist, f.rvecs, f.tvecs, 0, crit);
    return f;
  }
  std::vector<std::vector<cv::Point3d>> obj_d(object.size());
  std::vector<std::vector<cv::Point2d>> img_d(image.size());
  for (std::size_t i = 0; i < object.size(); ++i) {
    for (const auto& p : object[i]) obj_d[i].emplace_back(p.x, p.y, p.z);
    for (const auto& p : image[i]) img_d[i].emplace_back(p.x, p.y);
  }
  try {
    // OpenCV's own start (f = max(w, h) / pi, no distortion) does not converge on such views:
    // start from the pinhole intrinsics of a radtan fit.
    cv::Mat K0, d0;
    std::vector<cv::Mat> r0, t0;
    cv::calibrateCamera(object, image, size, K0, d0, r0, t0, 0, crit);
    f.K = K0.clone();
    f.dist = cv::Mat::zeros(4, 1, CV_64F);
    f.rms_px = cv::fisheye::calibrate(obj_d, img_d, size, f.K, f.dist, f.rvecs, f.tvecs,
                                      cv::fisheye::CALIB_RECOMPUTE_EXTRINSIC | cv::fisheye::CALIB_FIX_SKEW |
                                          cv::fisheye::CALIB_USE_INTRINSIC_GUESS,
                                      crit);
  } catch (const cv::Exception& e) {
    ThrowBadInput("calibrate: the fisheye fit failed ({}): too few or too similar views", e.err);
  }
  return f;
}

// The fitted intrinsics as a CameraModel.
CameraModel CameraOfFit(const std::string& model, int width, int height, const CameraFit& f) {
  CameraModel c;
  c.model = model;
  c.width = width, c.height = height;
  c.fx = f.K.at<double>(0, 0), c.fy = f.K.at<double>(1, 1), c.cx = f.K.at<double>(0, 2), c.cy = f.K.at<double>(1, 2);
  const auto coef = [&](int i) { return i < static_cast<int>(f.dist.total()) ? f.dist.at<double>(i) : 0.0; };
  if (model == "radtan") {
    c.k1 = coef(0), c.k2 = coef(1), c.p1 = coef(2), c.p2 = coef(3), c.k3 = coef(4);
  } else {
    c.k1 = coef(0), c.k2 = coef(1), c.k3 = coef(2), c.k4 = coef(3);
  }
  return c;
}

// The reprojection RMS (px) of used photo i under the fit.
double ReprojectionRms(const std::string& model, const CameraFit& f, const std::vector<cv::Point3f>& object,
                       const std::vector<cv::Point2f>& image, std::size_t i) {
  std::vector<cv::Point2f> proj;
  if (model == "radtan") {
    cv::projectPoints(object, f.rvecs[i], f.tvecs[i], f.K, f.dist, proj);
  } else {
    std::vector<cv::Point3d> od;
    for (const auto& p : object) od.emplace_back(p.x, p.y, p.z);
    std::vector<cv::Point2d> pd;
    cv::fisheye::projectPoints(od, pd, f.rvecs[i], f.tvecs[i], f.K, f.dist);
    for (const auto& p : pd) proj.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y));
  }
  double ss = 0;
  for (std::size_t k = 0; k < proj.size(); ++k) {
    const double dx = proj[k].x - image[k].x, dy = proj[k].y - image[k].y;
    ss += dx * dx + dy * dy;
  }
  return std::sqrt(ss / static_cast<double>(proj.size()));
}

}  // namespace

void CalibrateOptions::Check() const {
  BTF_CHECK_OPTION(model == "radtan" || model == "fisheye", "model", "radtan or fisheye");
  detector.Check();
  input.Check();
  BTF_CHECK_OPTION(min_markers >= 1, "min-markers", ">= 1");
  BTF_CHECK_OPTION(min_corners >= 4, "min-corners", ">= 4");
  BTF_CHECK_OPTION(min_views >= 3, "min-views", ">= 3 (a planar board needs at least 3 views)");
  BTF_CHECK_OPTION(std::isfinite(outlier_factor) && outlier_factor > 1, "outlier-factor", "> 1");
}

namespace {

constexpr int kMaxRefits = 3;

// Fits the camera to the photos' correspondences (views[view_of[i]] for photo i); per-photo RMS
// and outliers (RMS over outlier_factor x the median, and over 0.2 px). With drop_outliers the
// outliers are left out and the camera fitted again, until none is flagged, kMaxRefits refits,
// or fewer than min_views photos would remain.
void FitDroppingOutliers(const CalibrateOptions& o, const std::vector<std::vector<cv::Point3f>>& object,
                         const std::vector<std::vector<cv::Point2f>>& image, const std::vector<int>& view_of,
                         cv::Size size, CalibrateSummary& sum) {
  std::vector<std::size_t> in(object.size());
  std::iota(in.begin(), in.end(), std::size_t(0));
  for (;;) {
    std::vector<std::vector<cv::Point3f>> obj;
    std::vector<std::vector<cv::Point2f>> img;
    for (std::size_t i : in) obj.push_back(object[i]), img.push_back(image[i]);
    const CameraFit fit = FitCamera(o.model, obj, img, size);
    if (fit.K.empty() || !std::isfinite(fit.rms_px)) ThrowBadInput("calibrate: the fit failed (degenerate views)");
    sum.camera.rms_px = fit.rms_px;
    sum.camera.camera = CameraOfFit(o.model, size.width, size.height, fit);
    std::vector<double> rms;
    sum.corners_used = 0;
    for (std::size_t j = 0; j < in.size(); ++j) {
      rms.push_back(ReprojectionRms(o.model, fit, obj[j], img[j], j));
      CalibrationView& v = sum.views[std::size_t(view_of[in[j]])];
      v.rms_px = rms.back(), v.outlier = false;
      sum.corners_used += static_cast<int>(obj[j].size());
    }
    const double med = Median(rms), limit = std::max(o.outlier_factor * med, 0.2);
    std::vector<std::size_t> kept;
    for (std::size_t j = 0; j < in.size(); ++j) {
      if (!(rms[j] > limit)) kept.push_back(in[j]);
      else sum.views[std::size_t(view_of[in[j]])].outlier = true;
    }
    sum.views_used = static_cast<int>(in.size());
    if (!o.drop_outliers || kept.size() == in.size() || sum.refits == kMaxRefits ||
        kept.size() < std::size_t(o.min_views))
      return;
    for (std::size_t j = 0; j < in.size(); ++j) {
      CalibrationView& v = sum.views[std::size_t(view_of[in[j]])];
      if (!v.outlier) continue;
      v.used = false, v.dropped = true;
      v.error = fmt::format("an outlier (reprojection RMS {:.3f} px, over {} x the median {:.3f} px): left out of the "
                            "fit, which was done again without it",
                            v.rms_px, o.outlier_factor, med);
    }
    in = std::move(kept);
    ++sum.refits;
  }
}

}  // namespace

std::vector<std::string> CalibrateSummary::Outliers() const {
  std::vector<std::string> out;
  for (const auto& v : views)
    if (v.outlier) out.push_back(v.file);
  return out;
}

nlohmann::json CalibrateSummary::ToJson() const {
  const CameraModel& c = camera.camera;
  nlohmann::json cam = {{"model", c.model}, {"image_size", {c.width, c.height}}, {"fx", c.fx}, {"fy", c.fy},
                        {"cx", c.cx},         {"cy", c.cy}};
  if (!c.fisheye()) {
    cam["k1"] = c.k1, cam["k2"] = c.k2, cam["p1"] = c.p1, cam["p2"] = c.p2, cam["k3"] = c.k3;
  } else {
    cam["k1"] = c.k1, cam["k2"] = c.k2, cam["k3"] = c.k3, cam["k4"] = c.k4;
  }
  cam["rms_px"] = camera.rms_px;
  nlohmann::json vs = nlohmann::json::array();
  for (const auto& v : views) {
    nlohmann::json j = {{"file", v.file}, {"used", v.used}, {"markers", v.markers}, {"corners", v.corners}};
    if (v.used || v.dropped) j["rms_px"] = v.rms_px, j["outlier"] = v.outlier, j["dropped"] = v.dropped;
    if (!v.error.empty()) j["error"] = v.error;
    vs.push_back(j);
  }
  return {{"camera", cam},     {"views_used", views_used}, {"corners_used", corners_used}, {"views", vs},
          {"outliers", Outliers()}, {"refits", refits},       {"seconds", times.ToJson()}};
}

std::string CalibrateSummary::Report() const {
  const CameraModel& c = camera.camera;
  std::string r = fmt::format("{} model, {} x {} px, {} of {} photos, {} corners: RMS {:.4f} px\n", c.model,
                              c.width, c.height, views_used, views.size(), corners_used, camera.rms_px);
  r += fmt::format("fx {:.4f}  fy {:.4f}  cx {:.4f}  cy {:.4f}\n", c.fx, c.fy, c.cx, c.cy);
  if (!c.fisheye())
    r += fmt::format("k1 {:.6f}  k2 {:.6f}  p1 {:.6f}  p2 {:.6f}  k3 {:.6f}\n", c.k1, c.k2, c.p1, c.p2, c.k3);
  else
    r += fmt::format("k1 {:.6f}  k2 {:.6f}  k3 {:.6f}  k4 {:.6f}\n", c.k1, c.k2, c.k3, c.k4);
  for (const auto& v : views) {
    if (v.used)
      r += fmt::format("  {}: {} markers, {} corners, RMS {:.4f} px{}\n", v.file, v.markers, v.corners, v.rms_px,
                       v.outlier ? "  OUTLIER" : "");
    else
      r += fmt::format("  {}: left out: {}\n", v.file, v.error);
  }
  const auto out = Outliers();
  if (!out.empty()) {
    std::string list;
    for (const auto& f : out) list += (list.empty() ? "" : ", ") + f;
    r += fmt::format("outlier photos (RMS over outlier_factor x the median): {}{}\n", list,
                     refits > 0 ? fmt::format("; left out, the camera fitted again without them ({} refit{})", refits,
                                              refits > 1 ? "s" : "")
                                : "; kept in the fit");
  }
  r += fmt::format("time: {}\n", times.Report());
  return r;
}

CalibrateSummary CalibrateCamera(const CalibrateOptions& o, const std::vector<std::filesystem::path>& inputs,
                                 const Board& board, const Reporter& reporter) {
  o.Check();
  if (inputs.empty()) ThrowUsage("calibrate: no images or manifests given");
  TagDetectorOptions dopt = o.detector;
  if (!o.family_override) dopt.family = board.family, dopt.border_bits = board.border_bits;
  const TagDetector detector(dopt);
  const bool charuco = board.charuco.valid() && o.charuco_corners && dopt.family == board.family;
  std::map<int, const Marker*> by_id;
  for (const auto& m : board.markers) by_id[m.id] = &m;
  // calibrateCamera's planar initialisation wants z = 0: markers all at one height are shifted there.
  const double h0 = board.markers.front().height_mm;
  for (const auto& m : board.markers)
    if (m.height_mm != h0)
      ThrowBadInput("calibrate: the board's markers lie at different heights ({} and {} mm): a planar board is needed",
                    h0, m.height_mm);

  CalibrateSummary sum;
  Timer t;
  const std::vector<Input> photos = ExpandInputs(inputs);
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  std::vector<int> view_of;  // index into sum.views
  int width = 0, height = 0;
  std::string size_from;
  for (std::size_t i = 0; i < photos.size(); ++i) {
    reporter.Progress(i, photos.size(), "detect");
    CalibrationView v;
    v.file = photos[i].name;
    ImageReadOptions in = o.input;
    if (in.colorspace == "auto" && !photos[i].transfer.empty()) in.colorspace = photos[i].transfer;
    const Image im = ReadImage(photos[i].path, in);  // unreadable: the error names the file
    if (width == 0) {
      width = im.width, height = im.height, size_from = v.file;
    } else if (im.width != width || im.height != height) {
      ThrowBadInput("calibrate: '{}' is {} x {} px but '{}' is {} x {}: all photos must come from one camera setting",
                    v.file, im.width, im.height, size_from, width, height);
    }
    Correspondences corr = FindCorrespondences(im, detector, board, by_id, charuco);
    v.markers = corr.markers;
    v.corners = static_cast<int>(corr.object.size());
    if (v.markers < o.min_markers) {
      v.error = fmt::format("{} board markers found, at least {} needed (min_markers)", v.markers, o.min_markers);
    } else if (v.corners < o.min_corners) {
      v.error = fmt::format("{} {}corners found, at least {} needed (min_corners)", v.corners,
                            charuco ? "chessboard " : "", o.min_corners);
    } else {
      v.used = true;
      object.push_back(std::move(corr.object));
      image.push_back(std::move(corr.image));
      view_of.push_back(static_cast<int>(sum.views.size()));
    }
    sum.views.push_back(std::move(v));
  }
  reporter.Progress(photos.size(), photos.size(), "detect");
  sum.times.Add("detect", t.Seconds());
  if (static_cast<int>(object.size()) < o.min_views) {
    std::string failed;
    for (const auto& v : sum.views)
      if (!v.used) failed += fmt::format("{}'{}': {}", failed.empty() ? "" : "; ", v.file, v.error);
    ThrowBadInput("calibrate: {} usable photos of {}, at least {} needed (min_views){}{}", object.size(),
                  sum.views.size(), o.min_views, failed.empty() ? "" : "; left out: ", failed);
  }

  t.Restart();
  FitDroppingOutliers(o, object, image, view_of, cv::Size(width, height), sum);
  sum.times.Add("calibrate", t.Seconds());
  for (const auto& f : sum.Outliers())
    reporter.Warn("'{}': reprojection RMS over {} x the median: an outlier photo{}", f, o.outlier_factor,
                  sum.refits > 0 ? ", left out of the fit" : " (kept in the fit)");
  return sum;
}

}  // namespace btf
