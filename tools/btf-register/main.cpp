// btf-register: fiducial registration of measurement photos into a BTF dataset (docs/btf-register.md).
#include <optional>
#include <vector>

#include <fmt/format.h>

#include <filesystem>
#include <optional>

#include "libbtf/core/atomic_file.h"
#include "libbtf/register/calibrate.h"
#include "libbtf/register/register.h"
#include "tools/common/cli.h"

namespace {

// The board marker of a detection, or null (no board, or an id the board does not have).
const btf::Marker* OnBoard(const btf::Board* board, int id) {
  if (!board) return nullptr;
  for (const auto& m : board->markers)
    if (m.id == id) return &m;
  return nullptr;
}

nlohmann::json DetectionsJson(const std::string& path, const std::vector<btf::TagDetection>& dets,
                              const btf::TagDetectorOptions& options, const btf::Board* board,
                              const std::vector<btf::CharucoCorner>& charuco) {
  nlohmann::json tags = nlohmann::json::array();
  for (const auto& d : dets) {
    nlohmann::json c = nlohmann::json::array();
    for (const auto& p : d.corners) c.push_back({p.x(), p.y()});
    nlohmann::json t = {{"id", d.id},
                        {"hamming", d.hamming},
                        {"decision_margin", d.decision_margin},
                        {"center_px", {d.center.x(), d.center.y()}},
                        {"corners_px", c}};
    if (board) {
      const btf::Marker* m = OnBoard(board, d.id);
      t["on_board"] = m != nullptr;
      if (m) {
        nlohmann::json b = nlohmann::json::array();
        for (const auto& q : m->corners_mm) b.push_back({q.x(), q.y(), m->height_mm});
        t["corners_board_mm"] = b;
      }
    }
    tags.push_back(t);
  }
  nlohmann::json j = {{"image", path},
                      {"family", options.family},
                      {"corner_order", "left-bottom, right-bottom, right-top, left-top of the upright tag"},
                      {"pixel_convention", "OpenCV: (0,0) is the center of the top-left pixel, y down"},
                      {"tags", tags}};
  if (options.border_bits != 1) j["border_bits"] = options.border_bits;
  if (board) j["board_frame"] = "plate mm: x right, y up, z = marker height above the material surface";
  if (board && board->charuco.valid()) {
    nlohmann::json cs = nlohmann::json::array();
    for (const auto& c : charuco)
      cs.push_back({{"id", c.id}, {"pixel_px", {c.pixel.x(), c.pixel.y()}}, {"board_mm", {c.board_mm.x(), c.board_mm.y(), 0.0}}});
    j["charuco_corners"] = cs;
  }
  return j;
}

struct DetectFlags {
  std::string image, board;
  bool no_refine = false, no_split = false;
  bool family_given = false;
  btf::TagDetectorOptions options;
  btf::ImageReadOptions input;
  double input_gamma = 0;
};

// --input-gamma G implies --colorspace gamma.
void ApplyGamma(btf::ImageReadOptions& input, double gamma) {
  if (gamma > 0) input.colorspace = "gamma", input.gamma = gamma;
}

struct CalibrateFlags {
  std::vector<std::string> inputs;
  std::string board, output;
  bool family_given = false, keep_outliers = false;
  double input_gamma = 0;
  btf::CalibrateOptions options;
};

struct RunFlags {
  std::string manifest, output, report, sheet, family;
  bool allow_missing = false, no_intrinsics = false, no_radiometry = false, half = false;
  double input_gamma = 0;
  btf::RegisterOptions options;
};

int RunDetect(const CLI::App& app, const btf::cli::CommonFlags& common, DetectFlags& f) {
  btf::TagDetectorOptions& options = f.options;
  options.refine_corners = !f.no_refine;
  options.split_touching = !f.no_split;
  ApplyGamma(f.input, f.input_gamma);
  std::optional<btf::Board> board;
  if (!f.board.empty()) {
    board = btf::ReadBoard(f.board);
    if (!f.family_given) options.family = board->family, options.border_bits = board->border_bits;
  }
  // A ChArUco board detected with its own family: its chessboard corners too.
  const bool charuco = board && board->charuco.valid() && options.family == board->family;
  std::vector<btf::CharucoCorner> corners;
  const auto dets =
      btf::DetectInImage(f.image, options, f.input, charuco ? &board->charuco : nullptr, charuco ? &corners : nullptr);
  const btf::Board* b = board ? &*board : nullptr;
  if (common.json) {
    btf::cli::PrintJson(app, DetectionsJson(f.image, dets, options, b, corners));
    return 0;
  }
  fmt::print("{}: {} {} tag(s); corners px (OpenCV centers), order LB RB RT LT{}\n", f.image, dets.size(),
             options.family, b ? "; board mm (x, y, z) below each" : "");
  for (const auto& d : dets) {
    fmt::print("  id {:4d}  hamming {}  margin {:6.1f}  ({:.2f}, {:.2f}) ({:.2f}, {:.2f}) ({:.2f}, {:.2f}) "
               "({:.2f}, {:.2f})\n",
               d.id, d.hamming, d.decision_margin, d.corners[0].x(), d.corners[0].y(), d.corners[1].x(),
               d.corners[1].y(), d.corners[2].x(), d.corners[2].y(), d.corners[3].x(), d.corners[3].y());
    if (!b) continue;
    if (const btf::Marker* m = OnBoard(b, d.id))
      fmt::print("            board mm  ({:.3f}, {:.3f}, {:.3f}) ({:.3f}, {:.3f}, {:.3f}) ({:.3f}, {:.3f}, {:.3f}) "
                 "({:.3f}, {:.3f}, {:.3f})\n",
                 m->corners_mm[0].x(), m->corners_mm[0].y(), m->height_mm, m->corners_mm[1].x(), m->corners_mm[1].y(),
                 m->height_mm, m->corners_mm[2].x(), m->corners_mm[2].y(), m->height_mm, m->corners_mm[3].x(),
                 m->corners_mm[3].y(), m->height_mm);
    else
      fmt::print("            not on the board\n");
  }
  if (charuco) {
    fmt::print("{} ChArUco chessboard corner(s): id, px (OpenCV centers), board mm (x, y, z)\n", corners.size());
    for (const auto& c : corners)
      fmt::print("  corner {:4d}  ({:.3f}, {:.3f})  ({:.3f}, {:.3f}, 0.000)\n", c.id, c.pixel.x(), c.pixel.y(),
                 c.board_mm.x(), c.board_mm.y());
  }
  return 0;
}

int RunCalibrate(const CLI::App& app, const btf::cli::CommonFlags& common, CalibrateFlags& f) {
  btf::CalibrateOptions& o = f.options;
  o.family_override = f.family_given;
  o.drop_outliers = !f.keep_outliers;
  ApplyGamma(o.input, f.input_gamma);
  o.Check();
  std::vector<std::filesystem::path> inputs(f.inputs.begin(), f.inputs.end());
  std::vector<std::filesystem::path> read = inputs;
  read.push_back(f.board);
  btf::CheckOutput(f.output, read);
  const btf::Board board = btf::ReadBoard(f.board);
  const btf::CalibrateSummary sum = btf::CalibrateCamera(o, inputs, board, btf::cli::MakeReporter(common));
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : sum.views)
    if (v.used) views.push_back({{"file", v.file}, {"rms_px", v.rms_px}, {"outlier", v.outlier}});
  btf::WriteCameraFile(f.output, sum.camera, {{"board", f.board}, {"views", views}, {"outliers", sum.Outliers()}});
  if (common.json) {
    nlohmann::json j = sum.ToJson();
    j["output"] = f.output;
    btf::cli::PrintJson(app, j);
  } else {
    fmt::print("{}", sum.Report());
    fmt::print("-> {}\n", f.output);
  }
  return 0;
}

int RunRegister(const CLI::App& app, const btf::cli::CommonFlags& common, RunFlags& f) {
  btf::RegisterOptions& ro = f.options;
  ro.use_intrinsics = !f.no_intrinsics;
  ro.radiometry = !f.no_radiometry;
  if (!f.family.empty()) ro.detector.family = f.family, ro.family_override = true;
  ApplyGamma(ro.input, f.input_gamma);
  if (f.half) ro.write.storage = btf::h5::Storage::kFloat16;
  ro.Check();
  std::vector<std::filesystem::path> inputs = btf::ManifestFiles(btf::ReadManifest(f.manifest), f.manifest);
  inputs.push_back(f.manifest);
  if (!ro.camera.empty()) inputs.push_back(ro.camera);
  for (const std::string* out : {&f.output, &f.report, &f.sheet}) btf::CheckOutput(*out, inputs);
  // The dataset, report and contact sheet are all written under temporary names first and renamed
  // together at the end, so a failure in any of them leaves every earlier output as it was; a run
  // with failed photos (without --allow-missing) replaces only the report, which lists them.
  btf::AtomicOutput data_out(f.output);
  std::optional<btf::AtomicOutput> report_out, sheet_out;
  if (!f.report.empty()) report_out.emplace(f.report);
  if (!f.sheet.empty()) sheet_out.emplace(f.sheet);
  const btf::RegisterSummary sum =
      btf::RegisterPhotos(ro, f.manifest, data_out.temp_path(), btf::cli::MakeReporter(common));
  const nlohmann::json report = sum.ToJson();
  const bool failed = sum.photos_failed > 0 && !f.allow_missing;
  std::vector<btf::AtomicOutput*> outputs;
  if (!failed) outputs.push_back(&data_out);
  if (report_out) {
    btf::WriteTextFileAtomic(report_out->temp_path(), btf::cli::JsonDocument(app, report).dump(2) + "\n");
    outputs.push_back(&*report_out);
  }
  if (sheet_out && !failed && sum.contact_sheet.width > 0) {
    btf::ImageWriteOptions wo;
    wo.has_format = true;
    wo.format = btf::PixelFormat::kUint8;
    wo.srgb = true;
    btf::WriteImage(sheet_out->temp_path(), sum.contact_sheet, wo);
    outputs.push_back(&*sheet_out);
  }
  btf::AtomicOutput::CommitTogether(outputs);
  nlohmann::json failures = nlohmann::json::array();
  for (const auto& r : sum.reports)
    if (!r.ok) failures.push_back({{"file", r.file}, {"error", r.error}});
  if (common.json) {
    nlohmann::json j = {{"output", f.output},         {"photos_total", sum.photos}, {"photos_ok", sum.photos_ok},
                        {"photos_failed", sum.photos_failed}, {"failures", failures},
                        {"shape", report["shape"]},   {"filled", report["filled"]}, {"seconds", report["seconds"]}};
    if (report.contains("lattice")) j["lattice"] = report["lattice"];
    if (!f.report.empty()) j["report"] = f.report;
    if (!f.sheet.empty()) j["contact_sheet"] = f.sheet;
    btf::cli::PrintJson(app, j);
  } else {
    fmt::print("{} -> {}\n{}", f.manifest, f.output, sum.Report());
  }
  if (sum.photos_failed > 0 && !f.allow_missing) {
    fmt::print(stderr,
               "btf-register: error: {} of {} photos failed (listed above{}); '{}' was not written (an earlier file "
               "there is kept); pass --allow-missing to write a dataset without those images\n",
               sum.photos_failed, sum.photos, f.report.empty() ? "" : " and in the report", f.output);
    return static_cast<int>(btf::ExitCode::kBadInput);
  }
  return 0;
}

}  // namespace

BTF_TOOL_MAIN(int argc, char** argv) {
  CLI::App app{"Register measurement photos (AprilTag markers) into a rectified BTF dataset, or detect markers.",
               "btf-register"};
  btf::cli::Configure(app);
  app.require_subcommand(1);
  app.fallthrough();  // common flags may follow the subcommand
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  const auto add_input_flags = [](CLI::App* c, btf::ImageReadOptions& in, double& gamma) {
    c->add_option("--colorspace", in.colorspace,
                  "Decoding of integer images: auto (file metadata) | linear | srgb | gamma");
    c->add_option("--input-gamma", gamma, "Decode integer images as value^G (implies --colorspace gamma)");
    c->add_option("--max-pixels", in.max_pixels,
                  "Refuse an image whose header claims more pixels (width x height), before reading it (0 = no limit)");
  };

  // detect
  DetectFlags df;
  btf::TagDetectorOptions& dopt = df.options;
  auto* cd = app.add_subcommand("detect", "Detect AprilTag or ArUco markers in one image and print ids and corners");
  cd->add_option("IMAGE", df.image, "Image file (any format OpenImageIO reads)")->required();
  auto* fam = cd->add_option("--family", dopt.family, "Tag family: tag36h11, ... or aruco:DICT_5X5_100, ...");
  auto* bb = cd->add_option("--border-bits", dopt.border_bits, "Black tag border width, modules (1 or 2)");
  cd->add_option("--board", df.board, "Board file (ours, or a Kalibr aprilgrid .yaml): print board coordinates");
  cd->add_option("--max-hamming", dopt.max_hamming, "Drop detections correcting more bits");
  cd->add_option("--min-margin", dopt.min_decision_margin, "Drop detections with a lower decision margin");
  cd->add_option("--decimate", dopt.quad_decimate, "libapriltag quad_decimate");
  cd->add_flag("--apriltag-refine", dopt.refine_edges, "Use libapriltag's refine_edges (biased in 3.3.0)");
  cd->add_flag("--no-refine", df.no_refine, "Skip our sub-pixel edge fit (raw libapriltag corners)");
  cd->add_flag("--no-split-touching", df.no_split,
               "2-bit border: skip the second pass for tags touching an AprilGrid's corner squares");
  cd->add_option("--x-corners", dopt.x_corners,
                 "X-junction corners (AprilGrid): lines (edge points on both sides) | cornersubpix | none (edge fit)");
  cd->add_option("--subpix-window", dopt.subpix_window,
                 "X-junction cornerSubPix window reach, fraction of the border width (0, 1]");
  add_input_flags(cd, df.input, df.input_gamma);

  // calibrate
  CalibrateFlags kf;
  btf::CalibrateOptions& ko = kf.options;
  auto* ck = app.add_subcommand("calibrate", "Camera intrinsics and distortion from photos of a board");
  ck->add_option("IMAGES_OR_MANIFEST", kf.inputs, "Photos and/or manifest.json files (their cameras are ignored)")
      ->required();
  ck->add_option("--board", kf.board, "Board file: ours (.json) or a Kalibr aprilgrid (.yaml)")->required();
  ck->add_option("-o,--output", kf.output, "Output camera.json")->required();
  ck->add_option("--model", ko.model, "radtan (k1, k2, p1, p2, k3) | fisheye (k1..k4)");
  auto* kfam = ck->add_option("--family", ko.detector.family, "Tag family (default: the board's)");
  auto* kbb = ck->add_option("--border-bits", ko.detector.border_bits, "Black tag border, modules (default: the board's)");
  ck->add_option("--min-markers", ko.min_markers, "Photos with fewer board markers are left out");
  ck->add_option("--min-corners", ko.min_corners, "Photos with fewer corners (marker or ChArUco) are left out");
  ck->add_flag("--charuco-corners", ko.charuco_corners, "ChArUco board: calibrate on its chessboard corners, not its markers'");
  ck->add_option("--min-views", ko.min_views, "Fewer usable photos is an error");
  ck->add_option("--outlier-factor", ko.outlier_factor,
                 "Photos with RMS over this x the median (and 0.2 px) are outliers, left out and the camera fitted again");
  ck->add_flag("--keep-outliers", kf.keep_outliers, "Keep outlier photos in the fit (only name them)");
  add_input_flags(ck, ko.input, kf.input_gamma);

  // run
  RunFlags rf;
  btf::RegisterOptions& ro = rf.options;
  auto* cr = app.add_subcommand("run", "Register every photo of a manifest into a BTF dataset");
  cr->add_option("MANIFEST", rf.manifest, "manifest.json (btf-synth photos writes one)")->required();
  cr->add_option("-o,--output", rf.output, "Output dataset (.h5)")->required();
  cr->add_option("--resolution", ro.rectify.resolution, "Normtexture side N in texels");
  cr->add_option("--report", rf.report, "Write the registration report (JSON) here");
  cr->add_option("--contact-sheet", rf.sheet, "Write a PNG contact sheet of the rectified views here");
  cr->add_option("--thumb", ro.contact_sheet_thumb, "Contact-sheet thumbnail side, px");
  cr->add_flag("--tile-average", ro.tile_average, "Estimate the weave lattice and average all unit tiles");
  cr->add_option("--tile-output", ro.tile_output, "With --tile-average: 'tiling' (N x N) or 'tile' (the averaged tile)");
  cr->add_option("--tile-method", ro.tile_method,
                 "With --tile-average: 'average' (trimmed mean of the rectified repeats) or 'reconstruct' (least "
                 "squares from every photo pixel)");
  cr->add_option("--tile-samples-per-texel", ro.reconstruct.samples_per_texel,
                 "reconstruct: tile grid samples per texel along each lattice axis");
  cr->add_option("--tile-pixel-samples", ro.reconstruct.pixel_samples,
                 "reconstruct: sub-samples per pixel axis integrating each pixel's box");
  cr->add_option("--tile-smoothness", ro.reconstruct.smoothness, "reconstruct: relative Laplacian (smoothness) weight");
  cr->add_option("--trim", ro.tiles.trim_fraction, "Trimmed-mean fraction dropped at each end when averaging tiles");
  cr->add_option("--lattice-resolution", ro.lattice_resolution,
                 "With --tile-average: estimate the lattice on the reference view rectified at this side (0 = max(N, 128))");
  cr->add_option("--max-yarns", ro.lattice.max_yarns_per_repeat, "Largest yarns-per-repeat searched (twill, satin)");
  cr->add_flag("--allow-missing", rf.allow_missing, "Exit 0 even if some photos fail (they are still reported)");
  cr->add_option("--truth", ro.truth, "truth.json (btf-synth photos): add errors against the truth to the report");
  cr->add_option("--family", rf.family, "Tag family (default: the board's)");
  cr->add_option("--border-bits", ro.detector.border_bits, "With --family: black tag border, modules");
  cr->add_option("--camera", ro.camera, "camera.json (btf-register calibrate): replaces the manifest's intrinsics");
  add_input_flags(cr, ro.input, rf.input_gamma);
  cr->add_flag("--no-intrinsics", rf.no_intrinsics, "Ignore the manifest's camera: one homography per photo");
  cr->add_flag("--no-radiometry", rf.no_radiometry, "Store pixel / exposure (units 'relative') instead of BRDF");
  cr->add_option("--hdr-response", ro.hdr.response,
                 "Exposure brackets: linear (decoded values are linear) | debevec (recover the camera response "
                 "from the first bracket; 8-bit photos)");
  cr->add_option("--hdr-samples", ro.hdr.debevec_samples, "--hdr-response debevec: pixels sampled for the fit");
  cr->add_option("--hdr-lambda", ro.hdr.debevec_lambda, "--hdr-response debevec: smoothness weight");
  cr->add_option("--hdr-saturation", ro.hdr.saturation, "Brackets: stored value >= this fraction of full scale is clipped");
  cr->add_option("--hdr-dark", ro.hdr.dark, "Brackets: stored value <= this fraction of full scale is dark (left out)");
  cr->add_option("--samples-per-px", ro.rectify.samples_per_px, "Anti-aliasing: samples per photo pixel per axis");
  cr->add_option("--max-samples", ro.rectify.max_samples_per_axis, "Anti-aliasing: cap on samples per texel axis");
  cr->add_option("--filter", ro.rectify.filter,
                 "Photo reconstruction: area (nearest pixel where a texel covers >= 1 px) | bilinear | spline "
                 "(quadratic spline with the pixels' box averages: undoes the pixel integration)");
  cr->add_option("--min-markers", ro.geometry.min_markers, "Fewer usable markers fail the photo");
  cr->add_option("--ransac-px", ro.geometry.ransac_threshold_px, "Outlier threshold for wrong markers, px");
  cr->add_option("--max-rms", ro.geometry.max_rms_px, "Larger reprojection RMS fails the photo, px");
  cr->add_option("--max-invalid", ro.max_invalid_fraction, "Fraction of texels allowed outside the photo");
  cr->add_flag("--half", rf.half, "Store float16 (default float32)");

  return btf::cli::Main(argc, argv, app, [&] {
    df.family_given = fam->count() > 0 || bb->count() > 0;
    kf.family_given = kfam->count() > 0 || kbb->count() > 0;
    if (*cd) return RunDetect(app, common, df);
    if (*ck) return RunCalibrate(app, common, kf);
    return RunRegister(app, common, rf);
  });
}
