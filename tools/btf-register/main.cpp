// btf-register: fiducial registration of measurement photos into a BTF dataset (docs/btf-register.md).
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
                    {"centre_px", {d.centre.x(), d.centre.y()}},
                    {"corners_px", c}});
  }
  return {{"image", path},
          {"family", family},
          {"corner_order", "left-bottom, right-bottom, right-top, left-top of the upright tag"},
          {"pixel_convention", "OpenCV: (0,0) is the centre of the top-left pixel, y down"},
          {"tags", tags}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Register measurement photos (AprilTag markers) into a rectified BTF dataset, or detect markers.",
               "btf-register"};
  app.require_subcommand(1);
  app.fallthrough();  // common flags may follow the subcommand
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  // detect
  std::string d_image;
  btf::TagDetectorOptions dopt;
  auto* cd = app.add_subcommand("detect", "Detect AprilTag markers in one image and print ids and corners");
  cd->add_option("IMAGE", d_image, "Image file (any format OpenImageIO reads)")->required();
  cd->add_option("--family", dopt.family, "Tag family")->capture_default_str();
  cd->add_option("--max-hamming", dopt.max_hamming, "Drop detections correcting more bits")->capture_default_str();
  cd->add_option("--min-margin", dopt.min_decision_margin, "Drop detections with a lower decision margin")
      ->capture_default_str();
  cd->add_option("--decimate", dopt.quad_decimate, "libapriltag quad_decimate")->capture_default_str();
  cd->add_flag("--apriltag-refine", dopt.refine_edges, "Use libapriltag's refine_edges (biased in 3.3.0)");
  bool no_refine = false;
  cd->add_flag("--no-refine", no_refine, "Skip our sub-pixel edge fit (raw libapriltag corners)");

  // run
  std::string manifest, output, report, sheet, truth, tile_output = "tiling", family;
  btf::RegisterOptions ro;
  bool allow_missing = false, no_intrinsics = false, no_radiometry = false, half = false;
  auto* cr = app.add_subcommand("run", "Register every photo of a manifest into a BTF dataset");
  cr->add_option("MANIFEST", manifest, "manifest.json (btf-synth photos writes one)")->required();
  cr->add_option("-o,--output", output, "Output dataset (.h5)")->required();
  cr->add_option("--resolution", ro.rectify.resolution, "Normtexture side N in texels")->capture_default_str();
  cr->add_option("--report", report, "Write the registration report (JSON) here");
  cr->add_option("--contact-sheet", sheet, "Write a PNG contact sheet of the rectified views here");
  cr->add_option("--thumb", ro.contact_sheet_thumb, "Contact-sheet thumbnail side, px")->capture_default_str();
  cr->add_flag("--tile-average", ro.tile_average, "Estimate the weave lattice and average all unit tiles");
  cr->add_option("--tile-output", tile_output, "With --tile-average: 'tiling' (N x N) or 'tile' (the averaged tile)")
      ->capture_default_str();
  cr->add_option("--trim", ro.tiles.trim_fraction, "Trimmed-mean fraction dropped at each end when averaging tiles")
      ->capture_default_str();
  cr->add_option("--max-yarns", ro.lattice.max_yarns_per_repeat, "Largest yarns-per-repeat searched (twill, satin)")
      ->capture_default_str();
  cr->add_flag("--allow-missing", allow_missing, "Exit 0 even if some photos fail (they are still reported)");
  cr->add_option("--truth", truth, "truth.json (btf-synth photos): add errors against the truth to the report");
  cr->add_option("--family", family, "Tag family (default: the board's)");
  cr->add_flag("--no-intrinsics", no_intrinsics, "Ignore the manifest's camera: one homography per photo");
  cr->add_flag("--no-radiometry", no_radiometry, "Store pixel / exposure (units 'relative') instead of BRDF");
  cr->add_option("--samples-per-px", ro.rectify.samples_per_px, "Anti-aliasing: samples per photo pixel per axis")
      ->capture_default_str();
  cr->add_option("--max-samples", ro.rectify.max_samples_per_axis, "Anti-aliasing: cap on samples per texel axis")
      ->capture_default_str();
  cr->add_option("--min-markers", ro.geometry.min_markers, "Fewer usable markers fail the photo")->capture_default_str();
  cr->add_option("--ransac-px", ro.geometry.ransac_threshold_px, "Outlier threshold for wrong markers, px")
      ->capture_default_str();
  cr->add_option("--max-rms", ro.geometry.max_rms_px, "Larger reprojection RMS fails the photo, px")
      ->capture_default_str();
  cr->add_option("--max-invalid", ro.max_invalid_fraction, "Fraction of texels allowed outside the photo")
      ->capture_default_str();
  cr->add_flag("--half", half, "Store float16 (default float32)");

  return btf::cli::Main(argc, argv, app, [&] {
    btf::InstallSignalCleanup();
    const btf::Reporter reporter = btf::cli::MakeReporter(common);
    if (*cd) {
      dopt.refine_corners = !no_refine;
      const auto dets = btf::DetectInImage(d_image, dopt);
      const nlohmann::json j = DetectionsJson(d_image, dets, dopt.family);
      if (common.json) {
        btf::cli::PrintJson(j);
      } else {
        fmt::print("{}: {} {} tag(s); corners px (OpenCV centres), order LB RB RT LT\n", d_image, dets.size(),
                   dopt.family);
        for (const auto& d : dets)
          fmt::print("  id {:4d}  hamming {}  margin {:6.1f}  ({:.2f}, {:.2f}) ({:.2f}, {:.2f}) ({:.2f}, {:.2f}) "
                     "({:.2f}, {:.2f})\n",
                     d.id, d.hamming, d.decision_margin, d.corners[0].x(), d.corners[0].y(), d.corners[1].x(),
                     d.corners[1].y(), d.corners[2].x(), d.corners[2].y(), d.corners[3].x(), d.corners[3].y());
      }
      return 0;
    }
    ro.tile_output = tile_output;
    ro.truth = truth;
    ro.use_intrinsics = !no_intrinsics;
    ro.radiometry = !no_radiometry;
    if (!family.empty()) ro.detector.family = family, ro.family_override = true;
    if (half) ro.write.storage = btf::h5::Storage::kFloat16;
    ro.Check();
    const btf::RegisterSummary sum = btf::RegisterPhotos(manifest, output, ro, reporter);
    const nlohmann::json rep = sum.ToJson();
    if (!report.empty()) btf::WriteTextFileAtomic(report, rep.dump(2) + "\n");
    if (!sheet.empty() && sum.contact_sheet.width > 0) {
      btf::ImageWriteOptions wo;
      wo.has_format = true;
      wo.format = btf::PixelFormat::kUint8;
      wo.srgb = true;
      btf::WriteImage(sheet, sum.contact_sheet, wo);
    }
    nlohmann::json failures = nlohmann::json::array();
    for (const auto& r : sum.reports)
      if (!r.ok) failures.push_back({{"file", r.file}, {"error", r.error}});
    if (common.json) {
      nlohmann::json j = {{"output", output},       {"photos_total", sum.photos}, {"photos_ok", sum.photos_ok},
                          {"photos_failed", sum.photos_failed}, {"failures", failures},
                          {"shape", rep["shape"]},  {"filled", rep["filled"]},  {"times_s", rep["times_s"]}};
      if (rep.contains("lattice")) j["lattice"] = rep["lattice"];
      if (!report.empty()) j["report"] = report;
      if (!sheet.empty()) j["contact_sheet"] = sheet;
      btf::cli::PrintJson(j);
    } else {
      fmt::print("registered {}/{} photos -> {} ({} views x {} lights x {}x{} texels, {} filled) in {:.1f} s\n",
                 sum.photos_ok, sum.photos, output, sum.views, sum.lights, sum.width, sum.height, sum.filled.size(),
                 sum.times.Total());
      if (sum.lattice)
        fmt::print("lattice: a1 = ({:.3f}, {:.3f}), a2 = ({:.3f}, {:.3f}) texels, {} yarn cell(s) per repeat\n",
                   sum.lattice->a1.x(), sum.lattice->a1.y(), sum.lattice->a2.x(), sum.lattice->a2.y(),
                   sum.lattice->yarn_cells_per_repeat);
      for (const auto& f : failures)
        fmt::print("FAILED {}: {}\n", f["file"].get<std::string>(), f["error"].get<std::string>());
    }
    if (sum.photos_failed > 0 && !allow_missing) {
      fmt::print(stderr, "btf-register: error: {} of {} photos failed (listed above{}); pass --allow-missing to accept\n",
                 sum.photos_failed, sum.photos, report.empty() ? "" : " and in the report");
      return static_cast<int>(btf::ExitCode::kBadInput);
    }
    return 0;
  });
}
