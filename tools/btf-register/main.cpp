// btf-register: fiducial registration of measurement photos into a BTF dataset (docs/btf-register.md).
#include <optional>
#include <vector>

#include <fmt/format.h>

#include "libbtf/core/atomic_file.h"
#include "libbtf/register/register.h"
#include "tools/common/cli.h"

namespace {

nlohmann::json DetectionsJson(const std::string& path, const std::vector<btf::TagDetection>& dets,
                              const std::string& family) {
  nlohmann::json tags = nlohmann::json::array();
  for (const auto& d : dets) {
    nlohmann::json c = nlohmann::json::array();
    for (const auto& p : d.corners) c.push_back({p.x(), p.y()});
    tags.push_back({{"id", d.id},
                    {"hamming", d.hamming},
                    {"decision_margin", d.decision_margin},
                    {"center_px", {d.center.x(), d.center.y()}},
                    {"corners_px", c}});
  }
  return {{"image", path},
          {"family", family},
          {"corner_order", "left-bottom, right-bottom, right-top, left-top of the upright tag"},
          {"pixel_convention", "OpenCV: (0,0) is the center of the top-left pixel, y down"},
          {"tags", tags}};
}

struct RunFlags {
  std::string manifest, output, report, sheet, family;
  bool allow_missing = false, no_intrinsics = false, no_radiometry = false, half = false;
  btf::RegisterOptions options;
};

int RunDetect(const CLI::App& app, const btf::cli::CommonFlags& common, const std::string& image,
              btf::TagDetectorOptions options, bool no_refine) {
  options.refine_corners = !no_refine;
  const auto dets = btf::DetectInImage(image, options);
  if (common.json) {
    btf::cli::PrintJson(app, DetectionsJson(image, dets, options.family));
    return 0;
  }
  fmt::print("{}: {} {} tag(s); corners px (OpenCV centers), order LB RB RT LT\n", image, dets.size(), options.family);
  for (const auto& d : dets)
    fmt::print("  id {:4d}  hamming {}  margin {:6.1f}  ({:.2f}, {:.2f}) ({:.2f}, {:.2f}) ({:.2f}, {:.2f}) "
               "({:.2f}, {:.2f})\n",
               d.id, d.hamming, d.decision_margin, d.corners[0].x(), d.corners[0].y(), d.corners[1].x(),
               d.corners[1].y(), d.corners[2].x(), d.corners[2].y(), d.corners[3].x(), d.corners[3].y());
  return 0;
}

int RunRegister(const CLI::App& app, const btf::cli::CommonFlags& common, RunFlags& f) {
  btf::RegisterOptions& ro = f.options;
  ro.use_intrinsics = !f.no_intrinsics;
  ro.radiometry = !f.no_radiometry;
  if (!f.family.empty()) ro.detector.family = f.family, ro.family_override = true;
  if (f.half) ro.write.storage = btf::h5::Storage::kFloat16;
  ro.Check();
  // The dataset, report and contact sheet are all written under temporary names first and renamed
  // together at the end, so a failure in any of them leaves every earlier output as it was.
  btf::AtomicOutput data_out(f.output);
  const btf::RegisterSummary sum =
      btf::RegisterPhotos(ro, f.manifest, data_out.temp_path(), btf::cli::MakeReporter(common));
  const nlohmann::json report = sum.ToJson();
  std::optional<btf::AtomicOutput> report_out, sheet_out;
  if (!f.report.empty()) {
    report_out.emplace(f.report);
    btf::WriteTextFileAtomic(report_out->temp_path(), btf::cli::JsonDocument(app, report).dump(2) + "\n");
  }
  if (!f.sheet.empty() && sum.contact_sheet.width > 0) {
    btf::ImageWriteOptions wo;
    wo.has_format = true;
    wo.format = btf::PixelFormat::kUint8;
    wo.srgb = true;
    sheet_out.emplace(f.sheet);
    btf::WriteImage(sheet_out->temp_path(), sum.contact_sheet, wo);
  }
  std::vector<btf::AtomicOutput*> outputs = {&data_out};
  if (report_out) outputs.push_back(&*report_out);
  if (sheet_out) outputs.push_back(&*sheet_out);
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
    fmt::print(stderr, "btf-register: error: {} of {} photos failed (listed above{}); pass --allow-missing to accept\n",
               sum.photos_failed, sum.photos, f.report.empty() ? "" : " and in the report");
    return static_cast<int>(btf::ExitCode::kBadInput);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Register measurement photos (AprilTag markers) into a rectified BTF dataset, or detect markers.",
               "btf-register"};
  btf::cli::Configure(app);
  app.require_subcommand(1);
  app.fallthrough();  // common flags may follow the subcommand
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  // detect
  std::string d_image;
  btf::TagDetectorOptions dopt;
  bool no_refine = false;
  auto* cd = app.add_subcommand("detect", "Detect AprilTag markers in one image and print ids and corners");
  cd->add_option("IMAGE", d_image, "Image file (any format OpenImageIO reads)")->required();
  cd->add_option("--family", dopt.family, "Tag family");
  cd->add_option("--max-hamming", dopt.max_hamming, "Drop detections correcting more bits");
  cd->add_option("--min-margin", dopt.min_decision_margin, "Drop detections with a lower decision margin");
  cd->add_option("--decimate", dopt.quad_decimate, "libapriltag quad_decimate");
  cd->add_flag("--apriltag-refine", dopt.refine_edges, "Use libapriltag's refine_edges (biased in 3.3.0)");
  cd->add_flag("--no-refine", no_refine, "Skip our sub-pixel edge fit (raw libapriltag corners)");

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
  cr->add_option("--trim", ro.tiles.trim_fraction, "Trimmed-mean fraction dropped at each end when averaging tiles");
  cr->add_option("--max-yarns", ro.lattice.max_yarns_per_repeat, "Largest yarns-per-repeat searched (twill, satin)");
  cr->add_flag("--allow-missing", rf.allow_missing, "Exit 0 even if some photos fail (they are still reported)");
  cr->add_option("--truth", ro.truth, "truth.json (btf-synth photos): add errors against the truth to the report");
  cr->add_option("--family", rf.family, "Tag family (default: the board's)");
  cr->add_flag("--no-intrinsics", rf.no_intrinsics, "Ignore the manifest's camera: one homography per photo");
  cr->add_flag("--no-radiometry", rf.no_radiometry, "Store pixel / exposure (units 'relative') instead of BRDF");
  cr->add_option("--samples-per-px", ro.rectify.samples_per_px, "Anti-aliasing: samples per photo pixel per axis");
  cr->add_option("--max-samples", ro.rectify.max_samples_per_axis, "Anti-aliasing: cap on samples per texel axis");
  cr->add_option("--min-markers", ro.geometry.min_markers, "Fewer usable markers fail the photo");
  cr->add_option("--ransac-px", ro.geometry.ransac_threshold_px, "Outlier threshold for wrong markers, px");
  cr->add_option("--max-rms", ro.geometry.max_rms_px, "Larger reprojection RMS fails the photo, px");
  cr->add_option("--max-invalid", ro.max_invalid_fraction, "Fraction of texels allowed outside the photo");
  cr->add_flag("--half", rf.half, "Store float16 (default float32)");

  return btf::cli::Main(argc, argv, app, [&] {
    if (*cd) return RunDetect(app, common, d_image, dopt, no_refine);
    return RunRegister(app, common, rf);
  });
}
