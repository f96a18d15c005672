// btf-synth: ground-truth BTFs, far-field BRDFs and synthetic measurement photos from the cloth
// models (docs/btf-synth.md).
#include <fmt/format.h>

#include <fstream>

#include "libbtf/core/atomic_file.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/synth/btf_generator.h"
#include "libbtf/synth/photo_synth.h"
#include "tools/common/cli.h"

namespace {

struct ModelFlags {
  std::string model = "irawan2006";
  std::string preset;
  std::string params;  // JSON object of parameter overrides
  std::string directions = "bonn81";
  std::string views, lights;  // index lists
};

void AddModelFlags(CLI::App* cmd, ModelFlags& f) {
  cmd->add_option("--model", f.model, "irawan2006 | irawan2012 | sadeghi2013");
  cmd->add_option("--preset", f.preset, "Preset name (irawan2006 default: twill; see docs/btf-synth.md)");
  cmd->add_option("--params", f.params, "JSON object overriding preset parameters, e.g. '{\"ks\": 0.5}'");
  cmd->add_option("--directions", f.directions, "Direction sampling: bonn81, ubo151 or a file");
  cmd->add_option("--views", f.views, "View indices into the sampling, e.g. 0,1,7-9 (default: all)");
  cmd->add_option("--lights", f.lights, "Light indices into the sampling (default: all)");
}

std::unique_ptr<btf::SvbrdfModel> BuildModel(const ModelFlags& f) {
  std::string preset = f.preset;
  if (preset.empty()) {
    if (f.model == "irawan2006")
      preset = "twill";
    else
      btf::ThrowUsage("--preset is required for model '{}' (docs/btf-synth.md lists the presets)", f.model);
  }
  nlohmann::json params;
  if (!f.params.empty()) {
    try {
      params = nlohmann::json::parse(f.params);
    } catch (const nlohmann::json::exception& e) {
      btf::ThrowUsage("--params is not valid JSON: {}", e.what());
    }
  }
  return btf::MakeModel(f.model, preset, params);
}

btf::Sampling Subset(const btf::Sampling& s, const std::string& list, const char* option) {
  if (list.empty()) return s;
  const auto idx = btf::cli::ParseIndexList(list, option);
  for (int i : idx)
    if (i < 0 || i >= s.size())
      btf::ThrowUsage("{} index {} is outside sampling '{}' (0..{})", option, i, s.name(), s.size() - 1);
  return s.Subset(idx);
}

struct BtfFlags {
  ModelFlags model;
  btf::BtfOptions options;
  std::string output;
};

struct BrdfFlags {
  ModelFlags model;
  std::string output, json_output;
};

struct PhotoFlags {
  ModelFlags model;
  btf::PhotoOptions options;
  std::string output;
};

int RunBtf(const CLI::App& app, const btf::cli::CommonFlags& common, BtfFlags& f) {
  const auto model = BuildModel(f.model);
  btf::CheckOutput(f.output, {f.model.directions});
  const auto s = btf::Sampling::Named(f.model.directions);
  f.options.views = Subset(s, f.model.views, "--views");
  f.options.lights = Subset(s, f.model.lights, "--lights");
  f.options.Check();
  const btf::Reporter reporter = btf::cli::MakeReporter(common);
  reporter.Info("{}: {} x {} directions, {}^2 texels, {}^2 samples per texel", model->name(), f.options.views.size(),
                f.options.lights.size(), f.options.resolution, f.options.samples);
  const btf::BtfSummary sum = btf::WriteGeneratedBtf(f.options, *model, f.output, reporter);
  btf::cli::PrintSummary(app, common, sum, {{"output", f.output}, {"model", model->name()}});
  if (!common.json && btf::cli::PrintingRank()) fmt::print("{} -> {}\n", model->name(), f.output);
  return 0;
}

int RunBrdf(const CLI::App& app, const btf::cli::CommonFlags& common, const BrdfFlags& f) {
  if (f.output.empty() && f.json_output.empty()) btf::ThrowUsage("brdf: give -o FILE.h5 and/or --json-out FILE.json");
  for (const std::string& out : {f.output, f.json_output}) btf::CheckOutput(out, {f.model.directions});
  const auto model = BuildModel(f.model);
  const auto s = btf::Sampling::Named(f.model.directions);
  const auto views = Subset(s, f.model.views, "--views"), lights = Subset(s, f.model.lights, "--lights");
  btf::Timer t;
  const btf::Dataset ds = btf::GenerateBrdf(*model, views, lights);
  if (!f.output.empty()) {
    btf::DatasetWriteOptions wo;
    wo.creator = "btf-synth";
    btf::WriteDataset(f.output, ds, wo);
  }
  if (!f.json_output.empty()) {
    nlohmann::json out = {{"model", model->Describe()}, {"units", "brdf_per_sr"}, {"values", nlohmann::json::array()}};
    for (int v = 0; v < views.size(); ++v)
      for (int l = 0; l < lights.size(); ++l) {
        const auto va = views.angles(v), la = lights.angles(l);
        const auto img = ds.image(v, l);
        out["values"].push_back({{"view", v},
                                 {"light", l},
                                 {"view_theta_phi_deg", {btf::RadToDeg(va.theta), btf::RadToDeg(va.phi)}},
                                 {"light_theta_phi_deg", {btf::RadToDeg(la.theta), btf::RadToDeg(la.phi)}},
                                 {"value", std::vector<float>(img.begin(), img.end())}});
      }
    btf::WriteTextFileAtomic(f.json_output, out.dump(1) + "\n");
  }
  btf::PhaseTimes times;
  times.Add("evaluate_and_write", t.Seconds());
  if (common.json)
    btf::cli::PrintJson(app, {{"model", model->name()}, {"views", views.size()}, {"lights", lights.size()},
                              {"seconds", times.ToJson()}});
  else
    fmt::print("{}: far-field BRDF on {} x {} directions\n", model->name(), views.size(), lights.size());
  return 0;
}

int RunPhotos(const CLI::App& app, const btf::cli::CommonFlags& common, PhotoFlags& f) {
  btf::CheckOutput(f.output, {f.model.directions}, btf::OutputKind::kFolder);
  const auto model = BuildModel(f.model);
  btf::PhotoOptions& po = f.options;
  po.views = po.lights = btf::Sampling::Named(f.model.directions);
  if (!f.model.views.empty()) po.view_indices = btf::cli::ParseIndexList(f.model.views, "--views");
  if (!f.model.lights.empty()) po.light_indices = btf::cli::ParseIndexList(f.model.lights, "--lights");
  po.Check();
  const btf::PhotoSummary sum =
      btf::SynthesizePhotos(po, *model, f.output, btf::cli::MakeReporter(common),
                            {{"generator_command", "btf-synth photos"}, {"preset", f.model.preset}});
  btf::cli::PrintSummary(app, common, sum, {{"output", f.output}, {"model", model->name()}});
  if (!common.json) fmt::print("{} -> {}/manifest.json\n", model->name(), f.output);
  return 0;
}

}  // namespace

BTF_TOOL_MAIN(int argc, char** argv) {
  CLI::App app{"Ground-truth BTFs, far-field BRDFs and synthetic measurement photos from cloth models.", "btf-synth"};
  btf::cli::Configure(app);
  app.require_subcommand(1);
  app.fallthrough();
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  // btf
  BtfFlags bf;
  btf::BtfOptions& bo = bf.options;
  auto* cb = app.add_subcommand("btf", "Ground-truth BTF dataset (supersampled texel footprints)");
  AddModelFlags(cb, bf.model);
  cb->add_option("--resolution", bo.resolution, "Texels per side");
  cb->add_option("--tiles", bo.tiles, "Tiles per image side");
  cb->add_option("--samples", bo.samples, "Stratified samples per texel per axis (S x S)");
  cb->add_option("--seed", bo.seed, "Jitter seed");
  cb->add_option("--irregularity", bo.irregularity, "RMS displacement of the thread pattern, tiles");
  cb->add_option("-o,--output", bf.output, "Output dataset (.h5)")->required();
  btf::cli::MarkDistributed(cb);

  // brdf
  BrdfFlags rf;
  auto* cr = app.add_subcommand("brdf", "Far-field (tile-average) BRDF on a direction sampling");
  AddModelFlags(cr, rf.model);
  cr->add_option("-o,--output", rf.output, "Output dataset (.h5, 1 x 1 texel)");
  cr->add_option("--json-out", rf.json_output, "Also/instead write the values as JSON");

  // photos
  PhotoFlags pf;
  btf::PhotoOptions& po = pf.options;
  auto* cp = app.add_subcommand("photos", "Synthetic measurement photos with AprilTag markers, manifest and truth");
  AddModelFlags(cp, pf.model);
  cp->add_option("--max-photos", po.max_photos, "At most N photos, evenly spread (0 = all)");
  cp->add_option("--width", po.width, "Image width, px");
  cp->add_option("--height", po.height, "Image height, px");
  cp->add_option("--camera-distance", po.camera_distance_mm, "Camera distance from the plate centre, mm");
  cp->add_option("--focal", po.focal_px, "Focal length, px (0 = plate fills 90% of the image at 0 deg)");
  cp->add_option("--pixel-aspect", po.pixel_aspect, "Non-square pixels: fy / fx (fx = the focal length), 0.5..2");
  cp->add_option("--lens", po.lens, "Lens model: radtan (--k1, --k2) | fisheye (OpenCV cv::fisheye, --fisheye-k)");
  cp->add_option("--k1", po.k1, "Radial distortion k1 (radtan)");
  cp->add_option("--k2", po.k2, "Radial distortion k2 (radtan)");
  cp->add_option("--fisheye-k", po.fisheye_k, "Fisheye k1,k2,k3,k4 (with --lens fisheye)")->delimiter(',')->expected(4);
  cp->add_option("--pixel-samples", po.pixel_samples, "Samples per pixel per axis");
  cp->add_option("--light-distance", po.light_distance_mm, "Point light distance, mm (0 = directional)");
  cp->add_option("--light-intensity", po.light_intensity,
                 "Directional: irradiance at normal incidence; point: intensity (0 = 1 or distance^2)");
  cp->add_flag("--true-directions", po.true_directions,
               "Evaluate the BTF with per-point view/light directions (default: the photo's nominal ones)");
  cp->add_option("--format", po.format, "png16 | png8 | jpeg | exr");
  cp->add_option("--transfer", po.transfer, "Integer encoding: linear | srgb (the sRGB curve, tagged in the file)");
  cp->add_option("--jpeg-quality", po.jpeg_quality, "JPEG quality 1..100 (with --format jpeg)");
  cp->add_option("--psf", po.psf, "Optical blur (PSF): gaussian (--blur sigma) | disc (--disc-radius)");
  cp->add_option("--blur", po.blur_px, "Gaussian optical blur (PSF) sigma, px (0 = none)");
  cp->add_option("--disc-radius", po.disc_radius_px, "Disc PSF radius, px (with --psf disc)");
  cp->add_option("--target", po.target, "ring (sample with 8 markers) | aprilgrid (Kalibr AprilGrid) | charuco (ChArUco board); the last two: no sample");
  cp->add_option("--family", po.family, "Tag family of the markers");
  cp->add_option("--border-bits", po.border_bits, "Black tag border, modules (0 = 1 for ring, 2 for aprilgrid)");
  cp->add_option("--grid-rows", po.grid_rows, "AprilGrid: tag rows");
  cp->add_option("--grid-cols", po.grid_cols, "AprilGrid: tag columns");
  cp->add_option("--grid-tag-mm", po.grid_tag_mm,
                 "AprilGrid: tag side, mm (0 = grid spans 85% of the image at 0 deg with --focal, else 88)");
  cp->add_option("--grid-spacing", po.grid_spacing, "AprilGrid: gap between tags / tag side");
  cp->add_option("--charuco-squares-x", po.charuco_squares_x, "ChArUco: chessboard squares across");
  cp->add_option("--charuco-squares-y", po.charuco_squares_y, "ChArUco: chessboard squares down");
  cp->add_option("--charuco-square-mm", po.charuco_square_mm,
                 "ChArUco: square side, mm (0 = board spans 85% of the image at 0 deg with --focal, else 20)");
  cp->add_option("--charuco-marker-mm", po.charuco_marker_mm, "ChArUco: marker side, mm (0 = 0.75 x the square)");
  cp->add_option("--charuco-dictionary", po.charuco_dictionary,
                 "ChArUco: ArUco dictionary, DICT_4X4_50 .. DICT_7X7_1000 or DICT_ARUCO_ORIGINAL");
  cp->add_option("--exposure", po.exposure, "Pixel value = exposure x radiance (0 = auto)");
  cp->add_option("--brackets", po.brackets,
                 "Exposure bracket: factors on the exposure, comma-separated (e.g. 0.25,1,4); one photo each, "
                 "clipped at the white level")
      ->delimiter(',');
  cp->add_option("--response-gamma", po.response_gamma,
                 "Camera response: code = bias(x^(1/G)) (0 = none; png8/jpeg with --transfer linear)");
  cp->add_option("--response-bias", po.response_bias, "Camera response: Schlick bias b in (0, 1) (0.5 = none)");
  cp->add_option("--noise", po.noise, "Gaussian read noise SD, fraction of full scale");
  cp->add_option("--vignetting", po.vignetting,
                 "Lens relative illumination 1 - v (r / r_corner)^2 (0 = none; writes flat.EXT, named in the manifest)");
  cp->add_option("--dark-level", po.dark_level,
                 "Sensor black level with a fixed pattern, fraction of full scale (0 = none; writes dark.EXT)");
  cp->add_option("--seed", po.seed, "Noise seed");
  cp->add_option("--sample-tiles", po.sample_tiles, "Sample side in tiles");
  cp->add_option("--module-mm", po.module_mm, "Marker module size, mm (0 = sample side / 20)");
  cp->add_option("--marker-height", po.marker_height_mm, "Marker plane above the material, mm");
  cp->add_option("--irregularity", po.irregularity, "RMS displacement of the thread pattern, tiles");
  cp->add_option("-o,--output", pf.output, "Output folder")->required();

  return btf::cli::Main(argc, argv, app, [&] {
    if (*cb) return RunBtf(app, common, bf);
    if (*cr) return RunBrdf(app, common, rf);
    return RunPhotos(app, common, pf);
  });
}
