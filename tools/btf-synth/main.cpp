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
  cmd->add_option("--model", f.model, "irawan2006 | irawan2012 | sadeghi2013")->capture_default_str();
  cmd->add_option("--preset", f.preset, "Preset name (irawan2006 default: twill; see docs/btf-synth.md)");
  cmd->add_option("--params", f.params, "JSON object overriding preset parameters, e.g. '{\"ks\": 0.5}'");
  cmd->add_option("--directions", f.directions, "Direction sampling: bonn81, ubo151 or a file")->capture_default_str();
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

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Ground-truth BTFs, far-field BRDFs and synthetic measurement photos from cloth models.", "btf-synth"};
  app.require_subcommand(1);
  app.fallthrough();
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  // btf
  ModelFlags bf;
  btf::BtfOptions bo;
  std::string b_out;
  auto* cb = app.add_subcommand("btf", "Ground-truth BTF dataset (supersampled texel footprints)");
  AddModelFlags(cb, bf);
  cb->add_option("--resolution", bo.resolution, "Texels per side")->capture_default_str();
  cb->add_option("--tiles", bo.tiles, "Tiles per image side")->capture_default_str();
  cb->add_option("--samples", bo.samples, "Stratified samples per texel per axis (S x S)")->capture_default_str();
  cb->add_option("--seed", bo.seed, "Jitter seed")->capture_default_str();
  cb->add_option("--irregularity", bo.irregularity, "RMS displacement of the thread pattern, tiles")
      ->capture_default_str();
  cb->add_option("-o,--output", b_out, "Output dataset (.h5)")->required();

  // brdf
  ModelFlags rf;
  std::string r_out, r_json;
  auto* cr = app.add_subcommand("brdf", "Far-field (tile-average) BRDF on a direction sampling");
  AddModelFlags(cr, rf);
  cr->add_option("-o,--output", r_out, "Output dataset (.h5, 1 x 1 texel)");
  cr->add_option("--json-out", r_json, "Also/instead write the values as JSON");

  // photos
  ModelFlags pf;
  btf::PhotoOptions po;
  std::string p_out;
  auto* cp = app.add_subcommand("photos", "Synthetic measurement photos with AprilTag markers, manifest and truth");
  AddModelFlags(cp, pf);
  cp->add_option("--max-photos", po.max_photos, "At most N photos, evenly spread (0 = all)")->capture_default_str();
  cp->add_option("--width", po.width, "Image width, px")->capture_default_str();
  cp->add_option("--height", po.height, "Image height, px")->capture_default_str();
  cp->add_option("--camera-distance", po.camera_distance_mm, "Camera distance from the plate centre, mm")
      ->capture_default_str();
  cp->add_option("--focal", po.focal_px, "Focal length, px (0 = plate fills 90% of the image at 0 deg)")
      ->capture_default_str();
  cp->add_option("--k1", po.k1, "Radial distortion k1")->capture_default_str();
  cp->add_option("--k2", po.k2, "Radial distortion k2")->capture_default_str();
  cp->add_option("--pixel-samples", po.pixel_samples, "Samples per pixel per axis")->capture_default_str();
  cp->add_option("--light-distance", po.light_distance_mm, "Point light distance, mm (0 = directional)")
      ->capture_default_str();
  cp->add_option("--light-intensity", po.light_intensity,
                 "Directional: irradiance at normal incidence; point: intensity (0 = 1 or distance^2)")
      ->capture_default_str();
  cp->add_flag("--true-directions", po.true_directions,
               "Evaluate the BTF with per-point view/light directions (default: the photo's nominal ones)");
  cp->add_option("--format", po.format, "png16 | png8 | exr (linear)")->capture_default_str();
  cp->add_option("--exposure", po.exposure, "Pixel value = exposure x radiance (0 = auto)")->capture_default_str();
  cp->add_option("--noise", po.noise, "Gaussian read noise SD, fraction of full scale")->capture_default_str();
  cp->add_option("--seed", po.seed, "Noise seed")->capture_default_str();
  cp->add_option("--sample-tiles", po.sample_tiles, "Sample side in tiles")->capture_default_str();
  cp->add_option("--module-mm", po.module_mm, "Marker module size, mm (0 = sample side / 20)")->capture_default_str();
  cp->add_option("--marker-height", po.marker_height_mm, "Marker plane above the material, mm")->capture_default_str();
  cp->add_option("--irregularity", po.irregularity, "RMS displacement of the thread pattern, tiles")
      ->capture_default_str();
  cp->add_option("-o,--output", p_out, "Output folder")->required();

  return btf::cli::Main(argc, argv, app, [&] {
    btf::InstallSignalCleanup();
    const btf::Reporter reporter = btf::cli::MakeReporter(common);
    nlohmann::json j;
    if (*cb) {
      const auto model = BuildModel(bf);
      const auto s = btf::Sampling::Named(bf.directions);
      bo.views = Subset(s, bf.views, "--views");
      bo.lights = Subset(s, bf.lights, "--lights");
      bo.Check();
      reporter.Info("{}: {} x {} directions, {}^2 texels, {}^2 samples per texel", model->name(), bo.views.size(),
                    bo.lights.size(), bo.resolution, bo.samples);
      const btf::BtfSummary sum = btf::WriteGeneratedBtf(*model, bo, b_out, reporter);
      j = sum.ToJson();
      j["output"] = b_out;
      j["model"] = model->name();
      if (!common.json)
        fmt::print("{}: {} views x {} lights x {}^2 texels, {:.3g} texel values/s, {:.1f} s -> {}\n", model->name(),
                   sum.views, sum.lights, sum.resolution, sum.seconds > 0 ? sum.texel_values / sum.seconds : 0.0,
                   sum.seconds, b_out);
    } else if (*cr) {
      if (r_out.empty() && r_json.empty()) btf::ThrowUsage("brdf: give -o FILE.h5 and/or --json-out FILE.json");
      const auto model = BuildModel(rf);
      const auto s = btf::Sampling::Named(rf.directions);
      const auto views = Subset(s, rf.views, "--views"), lights = Subset(s, rf.lights, "--lights");
      const btf::Dataset ds = btf::GenerateBrdf(*model, views, lights);
      if (!r_out.empty()) {
        btf::DatasetWriteOptions wo;
        wo.creator = "btf-synth";
        btf::WriteDataset(r_out, ds, wo);
      }
      if (!r_json.empty()) {
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
        btf::WriteTextFileAtomic(r_json, out.dump(1) + "\n");
      }
      j = {{"model", model->name()}, {"views", views.size()}, {"lights", lights.size()}};
      if (!common.json)
        fmt::print("{}: far-field BRDF on {} x {} directions\n", model->name(), views.size(), lights.size());
    } else if (*cp) {
      const auto model = BuildModel(pf);
      po.views = po.lights = btf::Sampling::Named(pf.directions);
      if (!pf.views.empty()) po.view_indices = btf::cli::ParseIndexList(pf.views, "--views");
      if (!pf.lights.empty()) po.light_indices = btf::cli::ParseIndexList(pf.lights, "--lights");
      po.Check();
      const btf::PhotoSummary sum = btf::SynthesizePhotos(
          *model, po, p_out, reporter, {{"generator_command", "btf-synth photos"}, {"preset", pf.preset}});
      j = sum.ToJson();
      j["output"] = p_out;
      j["model"] = model->name();
      if (!common.json)
        fmt::print("{}: {} photos ({:.2f} s each) -> {}/manifest.json\n", model->name(), sum.photos,
                   sum.photos ? sum.seconds / sum.photos : 0.0, p_out);
    }
    if (common.json) btf::cli::PrintJson(j);
    return 0;
  });
}
