#include "libbtf/register/register.h"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <map>
#include <mutex>
#include <set>

#include <Eigen/LU>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "libbtf/core/error.h"
#include "libbtf/io/json_util.h"
#include "libbtf/register/photo_loader.h"
#include "libbtf/register/radiometry.h"

namespace btf {
namespace {

using json = nlohmann::json;
using register_detail::PhotoLoader;
using register_detail::ReadPhoto;

// Both maps evaluated on an 11 x 11 grid over the sample at z = 0; returns RMS and max px.
std::pair<double, double> HomographyError(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b, double s) {
  double ss = 0, mx = 0;
  for (int j = 0; j <= 10; ++j)
    for (int i = 0; i <= 10; ++i) {
      const Vec3 p(-s / 2 + i * s / 10, -s / 2 + j * s / 10, 1);
      const Vec3 pa = a * p, pb = b * p;
      const double e = (pa.head<2>() / pa.z() - pb.head<2>() / pb.z()).norm();
      ss += e * e;
      mx = std::max(mx, e);
    }
  return {std::sqrt(ss / 121), mx};
}

// Whether the line of sight from plate point p (surface, z = 0) to the camera center `cam`
// crosses a marker's printed area (detection square enlarged by 1/4: the quiet zone of tag36h11)
// at the marker's height: p then shows the marker, not the cloth.
bool HiddenByMarker(const Board& board, const Vec3& cam, const Vec3& p) {
  for (const auto& m : board.markers) {
    if (!(m.height_mm > 0) || !(cam.z() > m.height_mm)) continue;
    const Vec3 q = p + (m.height_mm / cam.z()) * (cam - p);
    const Vec2 c = 0.25 * (m.corners_mm[0] + m.corners_mm[1] + m.corners_mm[2] + m.corners_mm[3]);
    bool inside = true;
    for (int k = 0; k < 4 && inside; ++k) {
      const Vec2 a = c + 1.25 * (m.corners_mm[k] - c), b = c + 1.25 * (m.corners_mm[(k + 1) % 4] - c);
      const Vec2 e = b - a, d = q.head<2>() - a;
      // Same side of every edge as the center (convex quad, either orientation).
      const double side = e.x() * d.y() - e.y() * d.x(), ref = e.x() * (c - a).y() - e.y() * (c - a).x();
      inside = side * ref >= 0;
    }
    if (inside) return true;
  }
  return false;
}

Vec3 CameraCenter(const PhotoGeometry& g) {
  return -g.camera_from_plate_rotation.transpose() * g.camera_from_plate_translation;
}

// Fraction of the sample (64 x 64 grid at z = 0) hidden behind raised markers in this photo.
double OccludedFraction(const Board& board, const PhotoGeometry& g) {
  if (!g.has_pose) return 0;
  const Vec3 cam = CameraCenter(g);
  const double S = board.sample_size_mm;
  int hidden = 0;
  for (int j = 0; j < 64; ++j)
    for (int i = 0; i < 64; ++i)
      hidden += HiddenByMarker(board, cam, Vec3(-S / 2 + (i + 0.5) * S / 64, -S / 2 + (j + 0.5) * S / 64, 0));
  return hidden / 4096.0;
}

// Per texel of the N x N normtexture: 1 where any of 3 x 3 points spread over the texel is hidden
// behind a raised marker (a partly hidden texel mixes marker and cloth), else 0.
std::vector<std::uint8_t> MarkerMask(const Board& board, const PhotoGeometry& g, int n) {
  std::vector<std::uint8_t> mask(std::size_t(n) * n, 0);
  if (!g.has_pose) return mask;
  const Vec3 cam = CameraCenter(g);
  for (int row = 0; row < n; ++row)
    for (int col = 0; col < n; ++col)
      for (int k = 0; k < 9 && !mask[std::size_t(row) * n + col]; ++k) {
        const Vec2 p = TexelCenterMm(col + (k % 3 - 1) / 3.0, row + (k / 3 - 1) / 3.0, n, board.sample_size_mm);
        mask[std::size_t(row) * n + col] = HiddenByMarker(board, cam, Vec3(p.x(), p.y(), 0));
      }
  return mask;
}

// Fills the texels of `im` where mask = 1 with the value of the nearest unmasked texel (Euclidean
// distance, OpenCV's labelled distance transform; ties as OpenCV breaks them).
void FillFromNearestValid(Image& im, const std::vector<std::uint8_t>& mask) {
  cv::Mat valid(im.height, im.width, CV_8U);
  for (int i = 0; i < im.width * im.height; ++i) valid.data[i] = mask[std::size_t(i)] ? 255 : 0;
  cv::Mat dist, labels;
  cv::distanceTransform(valid, dist, labels, cv::DIST_L2, cv::DIST_MASK_PRECISE, cv::DIST_LABEL_PIXEL);
  std::vector<int> source(static_cast<std::size_t>(im.width) * im.height + 1, -1);  // label -> texel
  for (int i = 0; i < im.width * im.height; ++i)
    if (!mask[std::size_t(i)]) source[static_cast<std::size_t>(labels.ptr<int>()[i])] = i;
  for (int i = 0; i < im.width * im.height; ++i)
    if (mask[std::size_t(i)]) {
      const int from = source[static_cast<std::size_t>(labels.ptr<int>()[i])];
      BTF_CHECK(from >= 0);
      for (int c = 0; c < im.channels; ++c) im.pixels[std::size_t(i) * im.channels + c] = im.pixels[std::size_t(from) * im.channels + c];
    }
}

// Area-averaged thumbnail.
Image Thumbnail(const Image& im, int side) {
  cv::Mat src(im.height, im.width, CV_32FC(im.channels), const_cast<float*>(im.pixels.data()));
  cv::Mat dst;
  cv::resize(src, dst, cv::Size(side, side), 0, 0, cv::INTER_AREA);
  Image out(side, side, im.channels);
  std::copy(dst.ptr<float>(), dst.ptr<float>() + out.pixels.size(), out.pixels.begin());
  return out;
}

Image ContactSheet(const std::vector<Image>& thumbs, int side) {
  if (thumbs.empty()) return {};
  const int n = static_cast<int>(thumbs.size()), cols = static_cast<int>(std::ceil(std::sqrt(n)));
  const int rows = (n + cols - 1) / cols, gap = 2, ch = thumbs[0].channels;
  Image sheet(cols * (side + gap) + gap, rows * (side + gap) + gap, ch);
  std::vector<float> all;
  for (const auto& t : thumbs) all.insert(all.end(), t.pixels.begin(), t.pixels.end());
  const std::size_t k = std::min(all.size() - 1, static_cast<std::size_t>(0.99 * static_cast<double>(all.size())));
  std::nth_element(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(k), all.end());
  const float scale = all[k] > 0 ? 1.0f / all[k] : 1.0f;  // 99th percentile -> white, shared by all views
  for (int i = 0; i < n; ++i) {
    const int x0 = gap + (i % cols) * (side + gap), y0 = gap + (i / cols) * (side + gap);
    for (int y = 0; y < side; ++y)
      for (int x = 0; x < side; ++x)
        for (int c = 0; c < ch; ++c) sheet.at(x0 + x, y0 + y, c) = std::clamp(thumbs[i].at(x, y, c) * scale, 0.0f, 1.0f);
  }
  return sheet;
}

}  // namespace

void RegisterOptions::Check() const {
  detector.Check();
  geometry.Check();
  rectify.Check();
  lattice.Check();
  tiles.Check();
  reconstruct.Check();
  BTF_CHECK_OPTION(lattice_resolution >= 0 && lattice_resolution <= 8192, "lattice_resolution", "0..8192");
  BTF_CHECK_OPTION(tile_method == "average" || tile_method == "reconstruct", "tile_method", "'average' or 'reconstruct'");
  write.Check();
  input.Check();
  hdr.Check();
  BTF_CHECK_OPTION(max_invalid_fraction >= 0 && max_invalid_fraction <= 1, "max_invalid_fraction", "0..1");
  BTF_CHECK_OPTION(tile_output == "tiling" || tile_output == "tile", "tile_output", "'tiling' or 'tile'");
  BTF_CHECK_OPTION(contact_sheet_thumb >= 0 && contact_sheet_thumb <= 1024, "contact_sheet_thumb", "0..1024");
}

json PhotoReport::ToJson() const {
  json markers = json::array();
  for (const auto& d : detections) {
    json c = json::array();
    for (const auto& p : d.corners) c.push_back(btf::ToJson(p));
    markers.push_back({{"id", d.id}, {"hamming", d.hamming}, {"decision_margin", d.decision_margin}, {"corners_px", c}});
  }
  json j = {{"file", file},
            {"view_index", view_index},
            {"light_index", light_index},
            {"status", ok ? "ok" : "failed"},
            {"markers_found", static_cast<int>(detections.size())},
            {"markers_used", used_ids},
            {"markers_rejected", rejected_ids},
            {"markers", markers},
            {"warnings", warnings}};
  if (!ok) j["error"] = error;
  if (!used_ids.empty()) {
    j["reprojection_rms_px"] = rms_px;
    j["model"] = has_pose ? "pose" : "homography";
    j["homography"] = btf::ToJson(homography);
    if (has_pose) {
      j["rotation"] = btf::ToJson(camera_from_plate_rotation);
      j["translation_mm"] = btf::ToJson(camera_from_plate_translation);
    }
  }
  if (exposures > 1) j["bracket"] = {{"exposures", exposures}, {"clipped_pixels", hdr_clipped_pixels}};
  else if (hdr_clipped_pixels > 0) j["clipped_pixels"] = hdr_clipped_pixels;
  if (ok) {
    j["masked_texels"] = {{"hidden_by_markers", masked_hidden}, {"clipped", masked_clipped}};
    j["invalid_texel_fraction"] = invalid_fraction;
    j["max_texel_footprint_px"] = max_footprint_px;
  }
  if (tile_pixels_used > 0)
    j["tile_reconstruction"] = {{"pixels_used", tile_pixels_used}, {"pixels_masked", tile_pixels_masked},
                                {"residual_rms", tile_residual_rms}};
  if (truth_corner_rms_px >= 0) j["truth_corner_rms_px"] = truth_corner_rms_px;
  if (truth_homography_rms_px >= 0) {
    j["truth_homography_rms_px"] = truth_homography_rms_px;
    j["truth_homography_max_px"] = truth_homography_max_px;
  }
  return j;
}

json RegisterSummary::ToJson() const {
  json filled_j = json::array();
  for (const auto& [v, l] : filled) filled_j.push_back({{"view_index", v}, {"light_index", l}});
  json ph = json::array();
  for (const auto& r : reports) ph.push_back(r.ToJson());
  json j = {{"format", "libbtf-register-report"},
            {"format_version", "1.0.0"},
            {"photos_total", photos},
            {"photos_ok", photos_ok},
            {"photos_failed", photos_failed},
            {"shape", {{"views", views}, {"lights", lights}, {"height", height}, {"width", width}, {"channels", channels}}},
            {"filled", filled_j},
            {"seconds", times.ToJson()},
            {"photos", ph}};
  if (!response.empty()) j["response_curve"] = {{"from", response_files},
                            {"code_to_linear", response.lut},
                            {"codes_constrained", {response.min_code, response.max_code}}};
  if (lattice) {
    j["lattice"] = lattice->ToJson();
    j["lattice"]["reference_view_index"] = reference_view;
  }
  return j;
}

std::string RegisterSummary::Report() const {
  std::string r = fmt::format("registered {}/{} photos ({} views x {} lights x {}x{} texels, {} filled)\n", photos_ok,
                              photos, views, lights, width, height, filled.size());
  if (lattice)
    r += fmt::format("lattice: a1 = ({:.3f}, {:.3f}), a2 = ({:.3f}, {:.3f}) texels, {} yarn cell(s) per repeat\n",
                     lattice->a1.x(), lattice->a1.y(), lattice->a2.x(), lattice->a2.y(), lattice->yarn_cells_per_repeat);
  std::size_t hidden = 0, clipped = 0;
  for (const auto& p : reports) hidden += p.masked_hidden, clipped += p.masked_clipped;
  if (hidden + clipped > 0)
    r += fmt::format("masked texels: {} hidden behind raised markers, {} clipped ({})\n", hidden, clipped,
                     reference_view >= 0 ? "left out of tile averaging" : "filled from the nearest unmasked texel");
  for (const auto& p : reports)
    if (!p.ok) r += fmt::format("FAILED {}: {}\n", p.file, p.error);
  r += fmt::format("time: {}\n", times.Report());
  return r;
}

std::vector<TagDetection> DetectInImage(const std::filesystem::path& image, const TagDetectorOptions& options,
                                        const ImageReadOptions& input, const CharucoDefinition* charuco,
                                        std::vector<CharucoCorner>* charuco_corners) {
  TagDetector det(options);
  const Image im = ReadPhoto(image, nullptr, input);
  std::vector<TagDetection> dets = det.Detect(im);
  if (charuco && charuco_corners) *charuco_corners = DetectCharucoCorners(im, *charuco, dets);
  return dets;
}

namespace {

// The photo's detected corners and fitted homography against the ground truth (synthetic photos).
void CompareWithTruth(const PhotoTruth& truth, const PhotoGeometry& g, double S, PhotoReport& r) {
  double ss = 0;
  int n = 0;
  for (const auto& d : r.detections)
    if (auto c = truth.marker_corners_px.find(d.id); c != truth.marker_corners_px.end())
      for (int k = 0; k < 4; ++k) ss += (d.corners[k] - c->second[k]).squaredNorm(), ++n;
  if (n) r.truth_corner_rms_px = std::sqrt(ss / n);
  std::tie(r.truth_homography_rms_px, r.truth_homography_max_px) =
      HomographyError(g.image_from_plate, truth.image_from_plate, S);
}

// The whole sample must be in view: its border projects inside the photo (the map is a
// homography plus radial distortion, so the border bounds the region).
void CheckSampleInView(const PhotoGeometry& g, double S, const Image& im) {
  for (int k = 0; k < 4 * 32; ++k) {
    const double s = (k % 32 + 0.5) / 32 * S - S / 2;
    const Vec2 q = k < 32 ? Vec2(s, -S / 2) : k < 64 ? Vec2(S / 2, s) : k < 96 ? Vec2(-s, S / 2) : Vec2(-S / 2, -s);
    Vec2 px;
    if (!g.Project(Vec3(q.x(), q.y(), 0), &px) || px.x() < -0.5 || px.y() < -0.5 || px.x() > im.width - 0.5 ||
        px.y() > im.height - 0.5)
      ThrowBadInput("the sample region is not fully inside the photo (plate point ({:.1f}, {:.1f}) mm maps to "
                    "pixel ({:.1f}, {:.1f}))",
                    q.x(), q.y(), px.x(), px.y());
  }
}

// A photo whose every texel is masked (hidden or clipped, as counted in r): what to do about it.
[[noreturn]] void ThrowAllMasked(const PhotoEntry& entry, const PhotoReport& r, const HdrOptions& hdr,
                                 const ResponseCurve& response) {
  std::string files;
  for (const auto& b : entry.brackets) files += (files.empty() ? "'" : ", '") + b.file + "'";
  const std::string limit = fmt::format("stored value >= {} of full scale{}", hdr.saturation,
                                        response.empty() ? "" : fmt::format(" or code > {}, the response curve's last constrained code", response.max_code));
  ThrowBadInput("every texel of the sample is masked ({} hidden behind raised markers, {} clipped{}{}{}): {}",
                r.masked_hidden, r.masked_clipped, files.empty() ? " (" : " in every exposure of the bracket (",
                files.empty() ? limit : files + "; " + limit, ")",
                r.masked_clipped == 0 ? "use a view where the sample is visible"
                                      : (files.empty() ? "lower the exposure or add a bracket" : "add a shorter exposure"));
}

// The images (n x n, `channels` each) averaged over their channels and lights, each light
// normalized by its mean so that no single bright light dominates.
std::vector<float> NormalizedGray(const std::map<int, const Image*>& by_light, int channels) {
  const int n = by_light.begin()->second->width;
  std::vector<float> gray(static_cast<std::size_t>(n) * n, 0.0f);
  for (const auto& [l, im] : by_light) {
    double mean = 0;
    for (float x : im->pixels) mean += x;
    mean = mean > 0 ? mean / static_cast<double>(im->pixels.size()) : 1;
    for (std::size_t p = 0; p < gray.size(); ++p) {
      double g = 0;
      for (int c = 0; c < channels; ++c) g += im->pixels[p * channels + c];
      gray[p] += static_cast<float>(g / (channels * mean));
    }
  }
  return gray;
}

// The registered dataset's description: units, channel names, texel size (of the unit tile's
// samples with tile output "tile": `width` of them across the lattice's longer side) and provenance.
DatasetInfo RegisteredDatasetInfo(const RegisterOptions& o, const std::optional<Lattice>& lattice, int channels,
                                  int width, double S, const std::string& manifest, const std::string& board) {
  DatasetInfo info;
  info.units = o.radiometry ? "brdf_per_sr" : "relative";
  info.cos_theta_i_included = false;
  info.channel_names = channels == 3 ? std::vector<std::string>{"R", "G", "B"}
                                     : channels == 1 ? std::vector<std::string>{"Y"} : std::vector<std::string>{};
  if (info.channel_names.empty())
    for (int c = 0; c < channels; ++c) info.channel_names.push_back(fmt::format("C{}", c));
  info.texel_size_mm = S / o.rectify.resolution;
  if (o.tile_average && o.tile_output == "tile")
    info.texel_size_mm *= std::max(lattice->a1.norm(), lattice->a2.norm()) / width;
  info.provenance = {{"creator", "btf-register"},
                     {"manifest", manifest},
                     {"board", board},
                     {"sample_size_mm", S},
                     {"resolution", o.rectify.resolution},
                     {"radiometry", o.radiometry},
                     {"tile_average", o.tile_average},
                     {"tile_output", o.tile_output}};
  if (lattice) info.provenance["lattice"] = lattice->ToJson();
  if (o.tile_average) info.provenance["tile_method"] = o.tile_method;
  return info;
}

// One photo's unit tile reconstructed from its pixels (ReconstructTile), in the units of
// RectifyPhoto's normtexture (the radiometric factor of entry e, its exposure that of `merged`,
// evaluated at each pixel's plate point), with RectifyPhoto's masks per pixel: hidden behind a
// raised marker, clipped.
ReconstructedTile ReconstructPhotoTile(const HdrMerge& merged, const PhotoEntry& e, const PhotoGeometry& g,
                                       const Board& board, double S, const RegisterOptions& o, const Lattice& lattice) {
  std::vector<std::uint8_t> clipped;
  if (merged.clipped_pixels > 0)
    for (float c : merged.clipped.pixels) clipped.push_back(c > 0);
  TilePhoto tp;
  tp.photo = &merged.radiance;
  tp.project = [&g](const Vec2& p, Vec2* px) { return g.Project(Vec3(p.x(), p.y(), 0), px); };
  tp.sample_size_mm = S;
  tp.resolution = o.rectify.resolution;
  tp.scale = [&](const Vec2& p) { return 1.0 / (e.exposure * (o.radiometry ? IrradianceAt(e, p) : 1.0)); };
  if (g.has_pose)
    tp.hidden = [&, cam = CameraCenter(g)](const Vec2& p) { return HiddenByMarker(board, cam, Vec3(p.x(), p.y(), 0)); };
  tp.pixel_mask = clipped.empty() ? nullptr : &clipped;
  return ReconstructTile(tp, lattice, o.reconstruct);
}

// What the parallel loops over photos share: thread-safe progress (a cancellation stops the
// remaining iterations) and the first I/O error. A photo that cannot be read (a failing disk, not
// a bad photo) ends the run with an I/O error (exit 4) instead of being left out.
class ParallelLoop {
 public:
  explicit ParallelLoop(const Reporter& reporter) : rep_(reporter) {}

  void RestartCount() { done_ = 0; }
  bool cancelled() const { return cancelled_; }
  void Cancel() { cancelled_ = true; }

  // Called in a catch block of the loop: keeps the first I/O error and skips the remaining
  // iterations.
  void KeepIoError() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!io_error_) io_error_ = std::current_exception();
    cancelled_ = true;
  }

  // One more iteration done.
  void Progress(const char* stage, int total) {
    const int d = ++done_;
    std::lock_guard<std::mutex> lock(mutex_);
    if (cancelled_) return;
    try {
      rep_.Progress(static_cast<std::size_t>(d), static_cast<std::size_t>(total), stage);
    } catch (const Cancelled&) {
      cancelled_ = true;
    }
  }

  // After the loop: throws the kept I/O error, or Cancelled after a cancellation.
  void Finish() {
    if (io_error_) std::rethrow_exception(io_error_);
    if (cancelled_) throw Cancelled();
  }

 private:
  const Reporter& rep_;
  std::atomic<bool> cancelled_{false};
  std::exception_ptr io_error_;
  std::atomic<int> done_{0};
  std::mutex mutex_;
};

// Runs the pipeline's phases; one member function each, in RegisterPhotos' order.
class Registration {
 public:
  Registration(const RegisterOptions& options, const std::filesystem::path& manifest_path, const Reporter& reporter,
               RegisterSummary& sum)
      : o_(options), manifest_path_(manifest_path), dir_(manifest_path.parent_path()), rep_(reporter), sum_(sum),
        loop_(reporter) {}

  // Fail fast on malformed inputs, before any work.
  void ReadInputs() {
    manifest_ = ReadManifest(manifest_path_);
    if (manifest_.photos.empty()) ThrowBadInput("'{}': the manifest lists no photos", manifest_path_.string());
    board_ = ReadBoard(dir_ / manifest_.board_file);
    if (!o_.truth.empty())
      for (auto& t : ReadTruth(o_.truth)) truth_.emplace(t.file, std::move(t));
    detector_ = o_.detector;
    if (!o_.family_override) detector_.family = board_.family, detector_.border_bits = board_.border_bits;
    detector_.Check();
    S_ = board_.sample_size_mm;
    if (!(S_ > 0))
      ThrowBadInput("'{}': sample_size_mm is 0 (a calibration target, not a sample plate): registration needs the "
                    "sample region's side",
                    (dir_ / manifest_.board_file).string());
    ImageReadOptions input = o_.input;
    if (input.colorspace == "auto" && !manifest_.transfer.empty()) input.colorspace = manifest_.transfer;
    loader_ = std::make_unique<PhotoLoader>(manifest_, manifest_path_, input, o_.hdr);
    sum_.response = loader_->response();
    sum_.response_files = loader_->response_files();
    if (!o_.camera.empty()) {
      const CameraFile cf = ReadCameraFile(o_.camera);
      for (auto& e : manifest_.photos) e.camera = cf.camera;
    }
    const int np = static_cast<int>(manifest_.photos.size());
    sum_.photos = np;
    sum_.reports.resize(static_cast<std::size_t>(np));
    std::set<std::pair<int, int>> seen_pairs;
    for (int i = 0; i < np; ++i) {
      const PhotoEntry& e = manifest_.photos[i];
      PhotoReport& r = sum_.reports[i];
      r.file = e.file;
      r.view_index = e.view_index;
      r.light_index = e.light_index;
      if (!seen_pairs.insert({e.view_index, e.light_index}).second)
        ThrowBadInput("'{}': photos[{}] ('{}'): a second photo for view {} and light {}: remove the duplicate entry",
                      manifest_path_.string(), i, e.file, e.view_index, e.light_index);
    }
  }

  // Phase 1: detection and geometry for every photo, in parallel (one detector per thread).
  void DetectAndFit() {
    const int np = sum_.photos;
    geoms_.assign(static_cast<std::size_t>(np), PhotoGeometry());
    std::vector<std::unique_ptr<TagDetector>> detectors(static_cast<std::size_t>(omp_get_max_threads()));
    loop_.RestartCount();
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < np; ++i) {
      if (loop_.cancelled()) continue;
      PhotoReport& r = sum_.reports[i];
      try {
        auto& det = detectors[static_cast<std::size_t>(omp_get_thread_num())];
        if (!det) det = std::make_unique<TagDetector>(detector_);
        geoms_[i] = FitPhoto(manifest_.photos[i], *det, r);
        r.ok = true;
      } catch (const Cancelled&) {
        loop_.Cancel();
      } catch (const Error& ex) {
        r.ok = false;
        r.error = ex.what();
        if (ex.code() == ExitCode::kIo) loop_.KeepIoError();
      } catch (const std::exception& ex) {
        r.ok = false;
        r.error = fmt::format("internal error: {}", ex.what());
      }
      loop_.Progress("detect", np);
    }
    loop_.Finish();
  }

  // The dataset's samplings: views and lights with at least one registered photo; the reference
  // view (the most frontal) comes first, as the lattice is estimated on it.
  void ChooseSamplings() {
    std::set<int> view_set, light_set;
    for (const auto& r : sum_.reports)
      if (r.ok) view_set.insert(r.view_index), light_set.insert(r.light_index);
    for (const auto& r : sum_.reports)
      if (!r.ok) rep_.Warn("'{}': {}", r.file, r.error);
    if (view_set.empty())
      ThrowBadInput("'{}': none of the {} photos registered (first failure: '{}': {})", manifest_path_.string(),
                    sum_.photos, sum_.reports[0].file, sum_.reports[0].error);
    view_list_.assign(view_set.begin(), view_set.end());
    light_list_.assign(light_set.begin(), light_set.end());
    views_ = manifest_.views.Subset(view_list_);
    lights_ = manifest_.lights.Subset(light_list_);
    for (int i = 0; i < sum_.photos; ++i)
      if (sum_.reports[i].ok) photo_of_[{manifest_.photos[i].view_index, manifest_.photos[i].light_index}] = i;
    reference_ = view_list_[0];
    for (int v : view_list_)
      if (manifest_.views[v].z() > manifest_.views[reference_].z()) reference_ = v;
    sum_.reference_view = o_.tile_average ? reference_ : -1;
  }

  // Phase 2, view by view (one view's images in memory): rectify, radiometry, tile averaging, write.
  void RegisterViews(const std::filesystem::path& output) {
    std::vector<int> order = {reference_};
    for (int v : view_list_)
      if (v != reference_) order.push_back(v);
    thumbs_.assign(view_list_.size(), Image());
    loop_.RestartCount();
    for (int v : order) {
      Timer t;
      std::vector<Image> tex;
      std::map<int, std::vector<std::uint8_t>> masks;  // by light, only photos with masked texels
      std::map<int, const Image*> by_light = RectifyView(v, tex, masks);
      sum_.times.Add("rectify", t.Seconds());
      std::map<int, Image> averaged;
      if (o_.tile_average) {
        t.Restart();
        if (v == reference_) EstimateReferenceLattice(v, by_light);
        if (o_.tile_method == "reconstruct") {
          averaged = ReconstructView(v, by_light);
        } else {
          for (const auto& [l, im] : by_light) {
            const auto m = masks.find(l);
            AveragedTile at = AverageTiles(*im, *sum_.lattice, o_.tiles, m == masks.end() ? nullptr : &m->second);
            if (at.samples_without_valid_tile > 0)
              sum_.reports[photo_of_.at({v, l})].warnings.push_back(fmt::format(
                  "{} tile samples are masked in every tile (averaged over all tiles there)", at.samples_without_valid_tile));
            averaged[l] = o_.tile_output == "tile" ? std::move(at.tile) : TileImage(at, *sum_.lattice, im->width, im->height);
          }
        }
        for (auto& [l, im] : averaged) by_light[l] = &im;
        sum_.times.Add("tile_average", t.Seconds());
      }
      if (!writer_) OpenWriter(output, *by_light.begin()->second);
      WriteView(v, by_light);
    }
    Timer t;
    writer_->Commit();
    sum_.times.Add("write", t.Seconds());
    for (const auto& r : sum_.reports) (r.ok ? sum_.photos_ok : sum_.photos_failed)++;
    if (o_.contact_sheet_thumb > 0) sum_.contact_sheet = ContactSheet(thumbs_, o_.contact_sheet_thumb);
  }

 private:
  // Reads one photo, detects its markers, fits its geometry and checks that the sample is in view.
  PhotoGeometry FitPhoto(const PhotoEntry& e, const TagDetector& det, PhotoReport& r) const {
    double exposure = 0;
    const HdrMerge merged = loader_->Load(e, &r.warnings, &exposure);
    const Image& im = merged.radiance;
    r.exposures = e.brackets.empty() ? 1 : static_cast<int>(e.brackets.size());
    r.hdr_clipped_pixels = merged.clipped_pixels;
    const bool pose = o_.use_intrinsics && e.camera.fx > 0;
    if (pose && (im.width != e.camera.width || im.height != e.camera.height))
      ThrowBadInput("photo is {}x{} but its camera model in the manifest is {}x{}", im.width, im.height,
                    e.camera.width, e.camera.height);
    r.detections = det.Detect(im);
    const PhotoGeometry g = EstimateGeometry(board_, r.detections, pose ? std::optional<CameraModel>(e.camera) : std::nullopt,
                                             o_.geometry, &r.warnings);
    r.used_ids = g.used_ids;
    r.rejected_ids = g.rejected_ids;
    r.rms_px = g.rms_px;
    r.has_pose = g.has_pose;
    r.homography = g.image_from_plate;
    r.camera_from_plate_rotation = g.camera_from_plate_rotation;
    r.camera_from_plate_translation = g.camera_from_plate_translation;
    if (auto t = truth_.find(e.file); t != truth_.end()) CompareWithTruth(t->second, g, S_, r);
    if (o_.max_invalid_fraction == 0) CheckSampleInView(g, S_, im);
    if (const double occ = OccludedFraction(board_, g); occ > 0)
      r.warnings.push_back(fmt::format("{:.1f}% of the sample is hidden behind raised markers in this view (texels at "
                                       "the edge show the marker)",
                                       100 * occ));
    return g;
  }

  // Rectifies and normalizes every registered photo of view v (in parallel); returns the images
  // by manifest light index (photos that fail here are dropped and reported).
  std::map<int, const Image*> RectifyView(int v, std::vector<Image>& tex, std::map<int, std::vector<std::uint8_t>>& masks) {
    std::vector<int> photos;
    for (int l : light_list_)
      if (auto it = photo_of_.find({v, l}); it != photo_of_.end()) photos.push_back(it->second);
    tex.assign(photos.size(), Image());
    std::vector<std::vector<std::uint8_t>> mask(photos.size());
    const int n_ok = static_cast<int>(photo_of_.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (std::size_t k = 0; k < photos.size(); ++k) {
      if (loop_.cancelled()) continue;
      const int i = photos[k];
      PhotoReport& r = sum_.reports[i];
      try {
        tex[k] = RectifyPhoto(manifest_.photos[i], geoms_[i], r, &mask[k]);
      } catch (const Cancelled&) {
        loop_.Cancel();
      } catch (const std::exception& ex) {
        r.ok = false;
        r.error = ex.what();
        tex[k] = Image();
        if (const auto* e = dynamic_cast<const Error*>(&ex); e && e->code() == ExitCode::kIo) loop_.KeepIoError();
      }
      loop_.Progress("rectify", n_ok);
    }
    loop_.Finish();
    std::map<int, const Image*> by_light;
    for (std::size_t k = 0; k < photos.size(); ++k)
      if (sum_.reports[photos[k]].ok) {
        const int l = manifest_.photos[photos[k]].light_index;
        by_light[l] = &tex[k];
        if (std::count(mask[k].begin(), mask[k].end(), 1) == 0) continue;
        // Masked texels are left out of tile averaging, or else take the nearest unmasked value.
        if (o_.tile_average)
          masks[l] = std::move(mask[k]);
        else
          FillFromNearestValid(tex[k], mask[k]);
      }
    if (by_light.empty())
      ThrowBadInput("view {}: every photo failed at rectification (first: '{}': {})", v, sum_.reports[photos[0]].file,
                    sum_.reports[photos[0]].error);
    if (channels_ == 0) channels_ = by_light.begin()->second->channels;
    for (const auto& [l, im] : by_light)
      if (im->channels != channels_)
        ThrowBadInput("photos have {} and {} channels: all photos must have the same channels", channels_, im->channels);
    return by_light;
  }

  // Rectifies and normalizes one photo; *mask gets 1 for each texel hidden behind a raised marker
  // or touching a pixel clipped in every exposure of a bracket (counted in the report).
  Image RectifyPhoto(const PhotoEntry& entry, const PhotoGeometry& g, PhotoReport& r, std::vector<std::uint8_t>* mask) const {
    PhotoEntry e = entry;
    const HdrMerge merged = loader_->Load(entry, nullptr, &e.exposure);
    const PlateToPixel project = [&g](const Vec2& p, Vec2* px) { return g.Project(Vec3(p.x(), p.y(), 0), px); };
    RectifyStats st;
    Image tex = Rectify(merged.radiance, project, S_, o_.rectify, &st);
    *mask = MarkerMask(board_, g, tex.width);
    r.masked_hidden = static_cast<std::size_t>(std::count(mask->begin(), mask->end(), 1));
    if (merged.clipped_pixels > 0) {  // a texel touching a clipped pixel (every exposure of a bracket) has no value
      RectifyOptions mask_options = o_.rectify;  // a 0/1 mask: no spline ringing into the texels around it
      mask_options.filter = "area";
      const Image clipped = Rectify(merged.clipped, project, S_, mask_options);
      for (std::size_t i = 0; i < mask->size(); ++i)
        if (clipped.pixels[i] > 0) r.masked_clipped += 1, (*mask)[i] = 1;
    }
    if (std::count(mask->begin(), mask->end(), 0) == 0) ThrowAllMasked(entry, r, o_.hdr, sum_.response);
    r.invalid_fraction = st.invalid_fraction;
    r.max_footprint_px = st.max_footprint_px;
    if (st.invalid_fraction > o_.max_invalid_fraction)
      ThrowBadInput("{:.1f}% of the texels fall outside the photo (limit {:.1f}%)", 100 * st.invalid_fraction,
                    100 * o_.max_invalid_fraction);
    if (st.invalid_fraction > 0)
      r.warnings.push_back(fmt::format("{:.2f}% of the texels fall outside the photo (edge values used)",
                                       100 * st.invalid_fraction));
    if (o_.radiometry) {
      ApplyRadiometry(tex, e, S_);
    } else {
      for (float& x : tex.pixels) x = static_cast<float>(x / e.exposure);
    }
    return tex;
  }

  // With tile_method "reconstruct": the unit tile of each registered photo of view v
  // (ReconstructPhotoTile). Photos in parallel, each solved serially.
  std::map<int, Image> ReconstructView(int v, const std::map<int, const Image*>& by_light) {
    std::vector<int> lights;
    for (const auto& [l, im] : by_light) lights.push_back(l);
    std::vector<Image> out(lights.size());
    std::exception_ptr error;
    std::mutex error_mutex;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::size_t k = 0; k < lights.size(); ++k) {
      const int i = photo_of_.at({v, lights[k]});
      PhotoReport& r = sum_.reports[i];
      try {
        PhotoEntry e = manifest_.photos[i];
        const HdrMerge merged = loader_->Load(manifest_.photos[i], nullptr, &e.exposure);
        ReconstructedTile rt = ReconstructPhotoTile(merged, e, geoms_[i], board_, S_, o_, *sum_.lattice);
        const int resolution = o_.rectify.resolution;
        r.tile_pixels_used = rt.pixels_used;
        r.tile_pixels_masked = rt.pixels_masked;
        r.tile_residual_rms = rt.residual_rms;
        out[k] = o_.tile_output == "tile" ? std::move(rt.tile.tile) : TileImage(rt.tile, *sum_.lattice, resolution, resolution);
      } catch (const Error& ex) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::make_exception_ptr(Error(ex.code(), fmt::format("'{}': {}", r.file, ex.what())));
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
      }
    }
    if (error) std::rethrow_exception(error);
    std::map<int, Image> result;
    for (std::size_t k = 0; k < lights.size(); ++k) result[lights[k]] = std::move(out[k]);
    return result;
  }

  // The weave lattice, once, on the reference view (EstimateLatticeOn). With lattice_resolution
  // R != N, the reference photos are rectified again at R x R for it and the lattice is scaled to
  // the N x N texels (x_N = (x_R + 0.5) N / R - 0.5).
  void EstimateReferenceLattice(int v, const std::map<int, const Image*>& by_light) {
    const int N = o_.rectify.resolution, R = o_.lattice_resolution > 0 ? o_.lattice_resolution : std::max(N, 128);
    std::map<int, const Image*> images = by_light;
    std::vector<Image> finer;
    if (R != N) {
      RectifyOptions ro = o_.rectify;
      ro.resolution = R;
      finer.reserve(by_light.size());
      for (const auto& [l, im] : by_light) {
        const int i = photo_of_.at({v, l});
        double exposure = 0;
        const PhotoGeometry& g = geoms_[i];
        finer.push_back(Rectify(loader_->Load(manifest_.photos[i], nullptr, &exposure).radiance,
                                [&g](const Vec2& p, Vec2* px) { return g.Project(Vec3(p.x(), p.y(), 0), px); }, S_, ro));
        images[l] = &finer.back();
      }
    }
    EstimateLatticeOn(v, images);
    if (R == N) return;
    Lattice& L = *sum_.lattice;
    const double f = static_cast<double>(N) / R;
    L.a1 *= f, L.a2 *= f, L.k1 /= f, L.k2 /= f;
    L.origin = (L.origin + Vec2(0.5, 0.5)) * f - Vec2(0.5, 0.5);
    for (auto& [k, m] : L.peaks) k /= f;
  }

  // The lattice of view v's images averaged over its lights (each light normalized by its mean so
  // that no single bright light dominates).
  void EstimateLatticeOn(int v, const std::map<int, const Image*>& by_light) {
    const int n = by_light.begin()->second->width;
    sum_.lattice = EstimateLattice(NormalizedGray(by_light, channels_), n, n, o_.lattice);
    rep_.Info("lattice on view {} ({} x {} texels): a1 = ({:.3f}, {:.3f}), a2 = ({:.3f}, {:.3f}) texels, {} yarn cell(s) per repeat", v, n, n,
              sum_.lattice->a1.x(), sum_.lattice->a1.y(), sum_.lattice->a2.x(), sum_.lattice->a2.y(),
              sum_.lattice->yarn_cells_per_repeat);
  }

  void OpenWriter(const std::filesystem::path& output, const Image& first) {
    sum_.width = first.width;
    sum_.height = first.height;
    sum_.channels = channels_;
    sum_.views = views_.size();
    sum_.lights = lights_.size();
    const DatasetInfo info = RegisteredDatasetInfo(o_, sum_.lattice, channels_, first.width, S_, manifest_path_.string(),
                                                   (dir_ / manifest_.board_file).string());
    DatasetWriteOptions wo = o_.write;
    if (wo.creator == "libbtf") wo.creator = "btf-register";
    writer_ = std::make_unique<DatasetWriter>(output, views_, lights_, first.height, first.width, channels_, info, wo);
  }

  // Writes view v's images; a light without a registered photo is filled from the registered
  // light of this view nearest in angle (listed in `filled`).
  void WriteView(int v, const std::map<int, const Image*>& by_light) {
    const int vi = static_cast<int>(std::lower_bound(view_list_.begin(), view_list_.end(), v) - view_list_.begin());
    const Image* brightest = nullptr;
    double best = -1;
    for (int li = 0; li < static_cast<int>(light_list_.size()); ++li) {
      const int l = light_list_[li];
      const Image* img = nullptr;
      if (auto it = by_light.find(l); it != by_light.end()) {
        img = it->second;
      } else {
        double best_dot = -2;
        for (const auto& [l2, im2] : by_light) {
          const double d = manifest_.lights[l2].dot(manifest_.lights[l]);
          if (d > best_dot) best_dot = d, img = im2;
        }
        sum_.filled.emplace_back(v, l);
      }
      BTF_CHECK(img->width == sum_.width && img->height == sum_.height && img->channels == channels_);
      writer_->WriteImage(vi, li, img->pixels.data());
      double mean = 0;
      for (float x : img->pixels) mean += x;
      if (mean > best) best = mean, brightest = img;
    }
    if (o_.contact_sheet_thumb > 0 && brightest) thumbs_[vi] = Thumbnail(*brightest, o_.contact_sheet_thumb);
  }

  const RegisterOptions& o_;
  const std::filesystem::path manifest_path_, dir_;
  const Reporter& rep_;
  RegisterSummary& sum_;
  Manifest manifest_;
  Board board_;
  std::map<std::string, PhotoTruth> truth_;
  TagDetectorOptions detector_;
  std::unique_ptr<PhotoLoader> loader_;  // the photos as linear images (after ReadInputs)
  double S_ = 0;  // sample side, mm
  std::vector<PhotoGeometry> geoms_;
  std::vector<int> view_list_, light_list_;
  Sampling views_, lights_;
  std::map<std::pair<int, int>, int> photo_of_;  // (view, light) manifest indices -> photo
  int reference_ = 0;
  int channels_ = 0;
  std::unique_ptr<DatasetWriter> writer_;
  std::vector<Image> thumbs_;
  ParallelLoop loop_;
};

}  // namespace

RegisterSummary RegisterPhotos(const RegisterOptions& options, const std::filesystem::path& manifest_path,
                               const std::filesystem::path& output, const Reporter& reporter) {
  options.Check();
  RegisterSummary sum;
  Registration reg(options, manifest_path, reporter, sum);
  Timer timer;
  reg.ReadInputs();
  sum.times.Add("read_inputs", timer.Seconds());
  timer.Restart();
  reg.DetectAndFit();
  sum.times.Add("detect_and_fit", timer.Seconds());
  reg.ChooseSamplings();
  reg.RegisterViews(output);
  return sum;
}

}  // namespace btf
