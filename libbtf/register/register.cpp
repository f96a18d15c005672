#include "libbtf/register/register.h"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <mutex>
#include <set>

#include <Eigen/LU>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "libbtf/core/error.h"
#include "libbtf/io/json_util.h"
#include "libbtf/register/radiometry.h"

namespace btf {
namespace {

using json = nlohmann::json;


// Reads a photo; non-finite values become 0 (counted in a warning) so nothing non-finite escapes.
Image ReadPhoto(const std::filesystem::path& path, std::vector<std::string>* warnings) {
  Image im = ReadImage(path);
  if (im.width < 2 || im.height < 2 || im.channels < 1) ThrowBadInput("'{}': empty image", path.string());
  std::size_t bad = 0;
  for (float& v : im.pixels)
    if (!std::isfinite(v)) v = 0, ++bad;
  if (bad && warnings) warnings->push_back(fmt::format("{} non-finite pixel values replaced by 0", bad));
  return im;
}

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

// Fraction of the sample (64 x 64 grid at z = 0) whose line of sight to the camera centre crosses
// a marker's printed area (detection square enlarged by 1/4: the quiet zone of tag36h11) at the
// marker's height: such texels show the marker, not the cloth, in this photo.
double OccludedFraction(const Board& board, const PhotoGeometry& g) {
  if (!g.has_pose) return 0;
  const Vec3 cam = -g.rotation.transpose() * g.translation;
  const double S = board.sample_size_mm;
  int hidden = 0;
  for (int j = 0; j < 64; ++j)
    for (int i = 0; i < 64; ++i) {
      const Vec3 p(-S / 2 + (i + 0.5) * S / 64, -S / 2 + (j + 0.5) * S / 64, 0);
      for (const auto& m : board.markers) {
        if (!(m.height_mm > 0) || !(cam.z() > m.height_mm)) continue;
        const Vec3 q = p + (m.height_mm / cam.z()) * (cam - p);
        const Vec2 c = 0.25 * (m.corners_mm[0] + m.corners_mm[1] + m.corners_mm[2] + m.corners_mm[3]);
        bool inside = true;
        for (int k = 0; k < 4 && inside; ++k) {
          const Vec2 a = c + 1.25 * (m.corners_mm[k] - c), b = c + 1.25 * (m.corners_mm[(k + 1) % 4] - c);
          const Vec2 e = b - a, d = q.head<2>() - a;
          // Same side of every edge as the centre (convex quad, either orientation).
          const double side = e.x() * d.y() - e.y() * d.x(), ref = e.x() * (c - a).y() - e.y() * (c - a).x();
          inside = side * ref >= 0;
        }
        if (inside) {
          ++hidden;
          break;
        }
      }
    }
  return hidden / 4096.0;
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
  write.Check();
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
      j["rotation"] = btf::ToJson(rotation);
      j["translation_mm"] = btf::ToJson(translation);
    }
  }
  if (ok) {
    j["invalid_texel_fraction"] = invalid_fraction;
    j["max_texel_footprint_px"] = max_footprint_px;
  }
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
            {"times_s", times.ToJson()},
            {"photos", ph}};
  if (lattice) {
    j["lattice"] = lattice->ToJson();
    j["lattice"]["reference_view_index"] = reference_view;
  }
  return j;
}

std::vector<TagDetection> DetectInImage(const std::filesystem::path& image, const TagDetectorOptions& options) {
  TagDetector det(options);
  return det.Detect(ReadPhoto(image, nullptr));
}

RegisterSummary RegisterPhotos(const std::filesystem::path& manifest_path, const std::filesystem::path& output,
                               const RegisterOptions& options, const Reporter& reporter) {
  options.Check();
  RegisterSummary sum;
  Timer timer;
  // Fail fast on malformed inputs, before any work.
  const Manifest manifest = ReadManifest(manifest_path);
  const std::filesystem::path dir = manifest_path.parent_path();
  if (manifest.photos.empty()) ThrowBadInput("'{}': the manifest lists no photos", manifest_path.string());
  const Board board = ReadBoard(dir / manifest.board_file);
  std::map<std::string, PhotoTruth> truth;
  if (!options.truth.empty())
    for (auto& t : ReadTruth(options.truth)) truth.emplace(t.file, std::move(t));
  TagDetectorOptions dopt = options.detector;
  if (!options.family_override) dopt.family = board.family;
  dopt.Check();
  const double S = board.sample_size_mm;
  sum.times.Add("read_inputs", timer.Seconds());

  // Phase 1: detection and geometry for every photo, in parallel (one detector per thread).
  timer.Restart();
  const int np = static_cast<int>(manifest.photos.size());
  sum.photos = np;
  sum.reports.resize(static_cast<std::size_t>(np));
  std::vector<PhotoGeometry> geoms(static_cast<std::size_t>(np));
  std::set<std::pair<int, int>> seen_pairs;
  for (int i = 0; i < np; ++i) {
    const PhotoEntry& e = manifest.photos[i];
    PhotoReport& r = sum.reports[i];
    r.file = e.file;
    r.view_index = e.view_index;
    r.light_index = e.light_index;
    if (!seen_pairs.insert({e.view_index, e.light_index}).second)
      ThrowBadInput("'{}': photos[{}] ('{}'): a second photo for view {} and light {}: remove the duplicate entry",
                    manifest_path.string(), i, e.file, e.view_index, e.light_index);
  }
  std::vector<std::unique_ptr<TagDetector>> detectors(static_cast<std::size_t>(omp_get_max_threads()));
  std::atomic<bool> cancelled{false};
  std::atomic<int> done{0};
  std::mutex progress_mutex;
  auto progress = [&](const char* stage, int total) {
    const int d = ++done;
    std::lock_guard<std::mutex> lock(progress_mutex);
    if (cancelled) return;
    try {
      reporter.Progress(static_cast<std::size_t>(d), static_cast<std::size_t>(total), stage);
    } catch (const Cancelled&) {
      cancelled = true;
    }
  };
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < np; ++i) {
    if (cancelled) continue;
    const PhotoEntry& e = manifest.photos[i];
    PhotoReport& r = sum.reports[i];
    try {
      auto& det = detectors[static_cast<std::size_t>(omp_get_thread_num())];
      if (!det) det = std::make_unique<TagDetector>(dopt);
      const Image im = ReadPhoto(dir / e.file, &r.warnings);
      const bool pose = options.use_intrinsics && e.camera.fx > 0;
      if (pose && (im.width != e.camera.width || im.height != e.camera.height))
        ThrowBadInput("photo is {}x{} but its camera model in the manifest is {}x{}", im.width, im.height,
                      e.camera.width, e.camera.height);
      r.detections = det->Detect(im);
      const PhotoGeometry g =
          EstimateGeometry(board, r.detections, pose ? std::optional<CameraModel>(e.camera) : std::nullopt,
                           options.geometry, &r.warnings);
      r.used_ids = g.used_ids;
      r.rejected_ids = g.rejected_ids;
      r.rms_px = g.rms_px;
      r.has_pose = g.has_pose;
      r.homography = g.surface_homography;
      r.rotation = g.rotation;
      r.translation = g.translation;
      if (auto t = truth.find(e.file); t != truth.end()) {
        double ss = 0;
        int n = 0;
        for (const auto& d : r.detections)
          if (auto c = t->second.marker_corners_px.find(d.id); c != t->second.marker_corners_px.end())
            for (int k = 0; k < 4; ++k) ss += (d.corners[k] - c->second[k]).squaredNorm(), ++n;
        if (n) r.truth_corner_rms_px = std::sqrt(ss / n);
        std::tie(r.truth_homography_rms_px, r.truth_homography_max_px) =
            HomographyError(g.surface_homography, t->second.plate_to_image, S);
      }
      // The whole sample must be in view: its border projects inside the photo (the map is a
      // homography plus radial distortion, so the border bounds the region).
      if (options.max_invalid_fraction == 0)
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
      if (const double occ = OccludedFraction(board, g); occ > 0)
        r.warnings.push_back(fmt::format("{:.1f}% of the sample is hidden behind raised markers in this view (texels at "
                                         "the edge show the marker)",
                                         100 * occ));
      geoms[i] = g;
      r.ok = true;
    } catch (const Cancelled&) {
      cancelled = true;
    } catch (const Error& ex) {
      r.ok = false;
      r.error = ex.what();
    } catch (const std::exception& ex) {
      r.ok = false;
      r.error = fmt::format("internal error: {}", ex.what());
    }
    progress("detect", np);
  }
  if (cancelled) throw Cancelled();
  sum.times.Add("detect_and_fit", timer.Seconds());

  // The dataset's samplings: views and lights with at least one registered photo.
  std::set<int> view_set, light_set;
  for (const auto& r : sum.reports)
    if (r.ok) view_set.insert(r.view_index), light_set.insert(r.light_index);
  for (const auto& r : sum.reports)
    if (!r.ok) reporter.Warn("'{}': {}", r.file, r.error);
  if (view_set.empty())
    ThrowBadInput("'{}': none of the {} photos registered (first failure: '{}': {})", manifest_path.string(), np,
                  sum.reports[0].file, sum.reports[0].error);
  const std::vector<int> view_list(view_set.begin(), view_set.end()), light_list(light_set.begin(), light_set.end());
  const Sampling views = manifest.views.Subset(view_list), lights = manifest.lights.Subset(light_list);
  std::map<std::pair<int, int>, int> photo_of;  // (view, light) manifest indices -> photo
  for (int i = 0; i < np; ++i)
    if (sum.reports[i].ok) photo_of[{manifest.photos[i].view_index, manifest.photos[i].light_index}] = i;

  // Phase 2, view by view (one view's images in memory): rectify, radiometry, tile averaging.
  int ref = view_list[0];
  for (int v : view_list)
    if (manifest.views[v].z() > manifest.views[ref].z()) ref = v;
  sum.reference_view = options.tile_average ? ref : -1;
  std::vector<int> order = {ref};
  for (int v : view_list)
    if (v != ref) order.push_back(v);

  std::unique_ptr<DatasetWriter> writer;
  std::vector<Image> thumbs(view_list.size());
  int channels = 0;
  done = 0;
  const int n_ok = static_cast<int>(photo_of.size());
  for (int v : order) {
    std::vector<int> photos;
    for (int l : light_list)
      if (auto it = photo_of.find({v, l}); it != photo_of.end()) photos.push_back(it->second);
    std::vector<Image> tex(photos.size());
    Timer t2;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::size_t k = 0; k < photos.size(); ++k) {
      if (cancelled) continue;
      const int i = photos[k];
      PhotoReport& r = sum.reports[i];
      try {
        const Image im = ReadPhoto(dir / manifest.photos[i].file, nullptr);
        const PhotoGeometry& g = geoms[i];
        RectifyStats st;
        tex[k] = Rectify(
            im, [&g](const Vec2& p, Vec2* px) { return g.Project(Vec3(p.x(), p.y(), 0), px); }, S, options.rectify,
            &st);
        r.invalid_fraction = st.invalid_fraction;
        r.max_footprint_px = st.max_footprint_px;
        if (st.invalid_fraction > options.max_invalid_fraction)
          ThrowBadInput("{:.1f}% of the texels fall outside the photo (limit {:.1f}%)", 100 * st.invalid_fraction,
                        100 * options.max_invalid_fraction);
        if (st.invalid_fraction > 0)
          r.warnings.push_back(fmt::format("{:.2f}% of the texels fall outside the photo (edge values used)",
                                           100 * st.invalid_fraction));
        if (options.radiometry) {
          ApplyRadiometry(tex[k], manifest.photos[i], S);
        } else {
          for (float& x : tex[k].pixels) x = static_cast<float>(x / manifest.photos[i].exposure);
        }
      } catch (const Cancelled&) {
        cancelled = true;
      } catch (const std::exception& ex) {
        r.ok = false;
        r.error = ex.what();
        tex[k] = Image();
      }
      progress("rectify", n_ok);
    }
    if (cancelled) throw Cancelled();
    sum.times.Add("rectify", t2.Seconds());
    // Drop photos that failed here (I/O, light below the horizon).
    std::map<int, const Image*> by_light;
    for (std::size_t k = 0; k < photos.size(); ++k)
      if (sum.reports[photos[k]].ok) by_light[manifest.photos[photos[k]].light_index] = &tex[k];
    if (by_light.empty())
      ThrowBadInput("view {}: every photo failed at rectification (first: '{}': {})", v,
                    sum.reports[photos[0]].file, sum.reports[photos[0]].error);
    const Image& any = *by_light.begin()->second;
    if (channels == 0) channels = any.channels;
    for (const auto& [l, im] : by_light)
      if (im->channels != channels)
        ThrowBadInput("photos have {} and {} channels: all photos must have the same channels", channels, im->channels);

    // Tile averaging: lattice once, on the reference view averaged over its lights.
    Timer t3;
    std::map<int, Image> averaged;
    if (options.tile_average) {
      if (v == ref) {
        const int n = any.width;
        std::vector<float> grey(static_cast<std::size_t>(n) * n, 0.0f);
        for (const auto& [l, im] : by_light) {
          // Normalise each light by its mean so that no single bright light dominates.
          double mean = 0;
          for (float x : im->pixels) mean += x;
          mean = mean > 0 ? mean / static_cast<double>(im->pixels.size()) : 1;
          for (std::size_t p = 0; p < grey.size(); ++p) {
            double g = 0;
            for (int c = 0; c < channels; ++c) g += im->pixels[p * channels + c];
            grey[p] += static_cast<float>(g / (channels * mean));
          }
        }
        sum.lattice = EstimateLattice(grey, n, n, options.lattice);
        reporter.Info("lattice on view {}: a1 = ({:.3f}, {:.3f}), a2 = ({:.3f}, {:.3f}) texels, {} yarn cell(s) per repeat",
                      v, sum.lattice->a1.x(), sum.lattice->a1.y(), sum.lattice->a2.x(), sum.lattice->a2.y(),
                      sum.lattice->yarn_cells_per_repeat);
      }
      for (const auto& [l, im] : by_light) {
        AveragedTile t = AverageTiles(*im, *sum.lattice, options.tiles);
        averaged[l] = options.tile_output == "tile" ? std::move(t.tile) : TileImage(t, *sum.lattice, im->width, im->height);
      }
      for (auto& [l, im] : averaged) by_light[l] = &im;
      sum.times.Add("tile_average", t3.Seconds());
    }

    const Image& first = *by_light.begin()->second;
    if (!writer) {
      sum.width = first.width;
      sum.height = first.height;
      sum.channels = channels;
      sum.views = views.size();
      sum.lights = lights.size();
      DatasetInfo info;
      info.units = options.radiometry ? "brdf_per_sr" : "relative";
      info.cos_theta_i_included = false;
      info.channel_names = channels == 3 ? std::vector<std::string>{"R", "G", "B"}
                                         : channels == 1 ? std::vector<std::string>{"Y"} : std::vector<std::string>{};
      if (info.channel_names.empty())
        for (int c = 0; c < channels; ++c) info.channel_names.push_back(fmt::format("C{}", c));
      info.texel_size_mm = S / options.rectify.resolution;
      if (options.tile_average && options.tile_output == "tile")
        info.texel_size_mm *= std::max(sum.lattice->a1.norm(), sum.lattice->a2.norm()) / first.width;
      info.provenance = {{"creator", "btf-register"},
                         {"manifest", manifest_path.string()},
                         {"board", (dir / manifest.board_file).string()},
                         {"sample_size_mm", S},
                         {"resolution", options.rectify.resolution},
                         {"radiometry", options.radiometry},
                         {"tile_average", options.tile_average},
                         {"tile_output", options.tile_output}};
      if (sum.lattice) info.provenance["lattice"] = sum.lattice->ToJson();
      DatasetWriteOptions wo = options.write;
      if (wo.creator == "libbtf") wo.creator = "btf-register";
      writer = std::make_unique<DatasetWriter>(output, views, lights, first.height, first.width, channels, info, wo);
    }
    const int vi = static_cast<int>(std::lower_bound(view_list.begin(), view_list.end(), v) - view_list.begin());
    const Image* brightest = nullptr;
    double best = -1;
    for (int li = 0; li < static_cast<int>(light_list.size()); ++li) {
      const int l = light_list[li];
      const Image* img = nullptr;
      if (auto it = by_light.find(l); it != by_light.end()) {
        img = it->second;
      } else {
        // Fill from the registered light of this view nearest in angle.
        double best_dot = -2;
        for (const auto& [l2, im2] : by_light) {
          const double d = manifest.lights[l2].dot(manifest.lights[l]);
          if (d > best_dot) best_dot = d, img = im2;
        }
        sum.filled.emplace_back(v, l);
      }
      if (img->width != sum.width || img->height != sum.height || img->channels != channels)
        throw Error(ExitCode::kInternal, "register: image shape changed between views");
      writer->WriteImage(vi, li, img->pixels.data());
      double mean = 0;
      for (float x : img->pixels) mean += x;
      if (mean > best) best = mean, brightest = img;
    }
    if (options.contact_sheet_thumb > 0 && brightest) thumbs[vi] = Thumbnail(*brightest, options.contact_sheet_thumb);
  }
  Timer t4;
  writer->Commit();
  sum.times.Add("write", t4.Seconds());
  for (const auto& r : sum.reports) (r.ok ? sum.photos_ok : sum.photos_failed)++;
  if (options.contact_sheet_thumb > 0) sum.contact_sheet = ContactSheet(thumbs, options.contact_sheet_thumb);
  return sum;
}

}  // namespace btf
