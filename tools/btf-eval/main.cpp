// btf-eval: compare BTFs, sweep codec settings (error against size and run time), stability suite,
// the WebGL2 viewer and renders of one scene on the CPU and in headless Chromium (docs/btf-eval.md).
#include "libbtf/compress/codec_source.h"
#include "libbtf/eval/metrics.h"
#include "libbtf/eval/sweep.h"
#include "libbtf/stability/stability.h"
#include "libbtf/web/web.h"
#include "tools/common/cli.h"

namespace {

struct CompareFlags {
  std::string reference, test, metric = "rel", maps_dir;
  std::optional<double> warn, fail;
  btf::CompareOptions options;
};

struct SweepFlags {
  std::string dataset, output;
  bool no_render = false, no_codecs = false, viewer = false;
  btf::SweepOptions options;
};

struct StabilityFlags {
  bool list = false;
  btf::StabilityOptions options;
};

// view, render-web and render: one set of flags (docs/btf-eval.md, "Viewer and renders").
struct SceneFlags {
  std::string source, output, scene = "patch-point", size = "280x224";
  double exposure = 1, tiles = 3;
  int port = 8000, frames = 0;
  bool page = false;
  btf::BrowserOptions browser;
  int width = 0, height = 0;  // from size
  void Check() {
    const auto x = size.find('x');
    try {
      if (x == std::string::npos) throw std::invalid_argument("no x");
      std::size_t used = 0;
      width = std::stoi(size.substr(0, x), &used);
      if (used != x) throw std::invalid_argument("trailing");
      height = std::stoi(size.substr(x + 1), &used);
      if (used != size.size() - x - 1) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      btf::ThrowUsage("invalid option '--size': '{}' is not WIDTHxHEIGHT (e.g. 1280x720)", size);
    }
    if (!(std::isfinite(exposure) && exposure > 0)) btf::ThrowUsage("invalid option '--exposure': must be > 0");
    if (!(std::isfinite(tiles) && tiles > 0 && tiles <= 1000)) btf::ThrowUsage("invalid option '--tiles': must be in (0, 1000]");
    if (frames < 0 || frames > 10000) btf::ThrowUsage("invalid option '--frames': must be 0..10000");
    browser.Check();
  }
  btf::RenderOptions Scene() const {
    btf::RenderOptions o = btf::WebSceneOptions(scene, width, height);
    o.tiles = tiles;
    return o;
  }
};

int RunView(SceneFlags& f) {
  f.Check();
  fmt::print("btf-eval view: serving {} at {} (Ctrl-C to stop)\n", f.source, btf::ViewerUrl(f.port));
  std::fflush(stdout);
  return btf::ServeViewer(f.browser, f.source, f.port, f.Scene(), f.exposure);
}

int RunRenderWeb(const CLI::App& app, const btf::cli::CommonFlags& common, SceneFlags& f) {
  f.Check();
  btf::CheckOutput(f.output, {f.source, f.scene});
  btf::WebRenderSummary s = btf::RenderWeb(f.browser, f.Scene(), f.exposure, f.source, f.output, f.scene, f.page);
  if (f.frames > 0) s.benchmark = btf::BenchmarkWeb(f.browser, f.Scene(), f.exposure, f.source, f.frames);
  btf::cli::PrintSummary(app, common, s);
  return 0;
}

int RunRender(const CLI::App& app, const btf::cli::CommonFlags& common, SceneFlags& f) {
  f.Check();
  btf::CheckOutput(f.output, {f.source, f.scene});
  btf::cli::PrintSummary(app, common, btf::RenderCpu(f.source, f.Scene(), f.exposure, f.output, f.scene));
  return 0;
}

int RunCompare(const CLI::App& app, const btf::cli::CommonFlags& common, CompareFlags& f) {
  const btf::Reporter reporter = btf::cli::MakeReporter(common);
  f.options.error_maps_dir = f.maps_dir;
  if (!f.maps_dir.empty()) std::filesystem::create_directories(f.maps_dir);
  const auto ref = btf::OpenSource(f.reference, btf::cli::DatasetReadOptionsFromEnvironment());
  const auto test = btf::OpenSource(f.test, btf::cli::DatasetReadOptionsFromEnvironment());
  const btf::CompareSummary s = btf::Compare(f.options, *ref, *test, reporter);
  // Thresholds: rmse and rel are errors (bigger is worse), psnr is a quality (smaller is worse).
  const bool higher_is_better = f.metric == "psnr";
  auto worse = [&](double value, double limit) { return higher_is_better ? value < limit : value > limit; };
  std::string verdict = "ok";
  if (f.warn || f.fail) {
    const double value = s.Metric(f.metric);
    if (f.fail && worse(value, *f.fail))
      verdict = "fail";
    else if (f.warn && worse(value, *f.warn))
      verdict = "warn";
    if (verdict == "warn" && btf::cli::PrintingRank())
      reporter.Warn("{} = {:.6g} is worse than the warning threshold {:.6g}", f.metric, value, *f.warn);
    if (verdict == "fail" && btf::cli::PrintingRank())
      reporter.Warn("{} = {:.6g} is worse than the failure threshold {:.6g}: exit 1", f.metric, value, *f.fail);
  }
  btf::cli::PrintSummary(app, common, s,
                         {{"metric", f.metric},
                          {"warn", f.warn ? nlohmann::json(*f.warn) : nlohmann::json(nullptr)},
                          {"fail", f.fail ? nlohmann::json(*f.fail) : nlohmann::json(nullptr)},
                          {"verdict", verdict}});
  if (!common.json && btf::cli::PrintingRank()) fmt::print("verdict    {}\n", verdict);
  return verdict == "fail" ? static_cast<int>(btf::ExitCode::kFailedCheck) : 0;
}

int RunSweep(const CLI::App& app, const btf::cli::CommonFlags& common, SweepFlags& f, int argc, char** argv) {
  btf::SweepOptions& o = f.options;
  o.render = !f.no_render;
  o.keep_codecs = !f.no_codecs;
  if (f.viewer) o.viewer_dir = btf::ViewerDir(btf::BrowserOptions{}, /*need_playwright=*/false).string();
  o.render_options.height = std::max(8, o.render_options.width * 4 / 5);
  for (int i = 0; i < argc; ++i) o.command_line += (i ? " " : "") + std::string(i ? argv[i] : "btf-eval");
  btf::CheckOutput(f.output, {f.dataset}, btf::OutputKind::kFolder);
  const btf::SweepSummary s = btf::RunSweep(o, f.dataset, f.output, btf::cli::MakeReporter(common));
  btf::cli::PrintSummary(app, common, s);
  return 0;
}

int RunStability(const CLI::App& app, const btf::cli::CommonFlags& common, const StabilityFlags& f) {
  if (f.list) {
    for (const auto& n : btf::StabilityCaseNames()) fmt::print("{}\n", n);
    return 0;
  }
  const btf::StabilitySummary s = btf::RunStability(f.options, btf::cli::MakeReporter(common));
  btf::cli::PrintSummary(app, common, s);
  return s.failed ? static_cast<int>(btf::ExitCode::kFailedCheck) : 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Evaluate BTF codecs: compare two BTFs, sweep codec settings (error against size and run time, "
               "HTML report), run the numerical stability suite, view and render exports (CPU and headless Chromium).",
               "btf-eval"};
  btf::cli::Configure(app);
  app.require_subcommand(1);
  btf::cli::CommonFlags common;

  CompareFlags cf;
  auto* compare = app.add_subcommand("compare", "Error metrics of TEST against REFERENCE (datasets or codecs)");
  compare->add_option("REFERENCE", cf.reference, "Reference dataset or codec file")->required();
  compare->add_option("TEST", cf.test, "Dataset or codec file to evaluate")->required();
  compare->add_option("--metric", cf.metric, "Metric the thresholds apply to: rmse, rel or psnr (dB; fails BELOW the "
                                             "threshold)")
      ->check(CLI::IsMember({"rmse", "rel", "psnr"}));
  compare->add_option("--warn", cf.warn, "Print a warning when the metric is worse than this");
  compare->add_option("--fail", cf.fail, "Exit 1 when the metric is worse than this");
  compare->add_option("--peak", cf.options.peak, "Peak for PSNR and SSIM; 0 = max |reference value|");
  compare->add_option("--ssim-sigma", cf.options.ssim_sigma, "SSIM Gaussian window sigma in texels");
  compare->add_flag("--no-ssim", [&](std::int64_t) { cf.options.ssim = false; }, "Skip SSIM");
  compare->add_option("--error-maps", cf.maps_dir, "Write false-color error maps of the worst images to this folder");
  compare->add_option("--maps", cf.options.error_maps, "Number of error maps");
  btf::cli::AddCommonFlags(*compare, common);
  btf::cli::MarkDistributed(compare);

  SweepFlags sf;
  btf::SweepOptions& so = sf.options;
  auto* sweep = app.add_subcommand("sweep", "Compress DATASET with each setting; error against size and run time; "
                                            "results.json, plots and report.html in DIR");
  sweep->add_option("DATASET", sf.dataset, "Dataset file (read into memory)")->required();
  sweep->add_option("-o,--output", sf.output, "Output folder (replaced as a whole when complete)")->required();
  sweep->add_option("--methods", so.methods, "Comma-separated codec methods (neural: --components is its latent width)")->delimiter(',');
  sweep->add_option("--components", so.components, "Components c to try (comma-separated, e.g. 1,2,4)")->delimiter(',');
  sweep->add_option("--clusters", so.clusters, "Cluster counts k to try (lpca, comma-separated)")->delimiter(',');
  sweep->add_option("--runs", so.runs, "Timed runs per setting (median reported)");
  sweep->add_option("--error", so.error_metric, "Error on the plots and Pareto fronts: rel or rmse")
      ->check(CLI::IsMember({"rel", "rmse"}));
  sweep->add_flag("--log", so.log_transform, "Compress with the log transform");
  sweep->add_option("--seed", so.seed, "Compression seed");
  sweep->add_option("--neural-samples", so.neural.samples,
                    "neural: training samples (at most the BTF's texel x light x view count; default as btf-compress)");
  sweep->add_option("--neural-epochs", so.neural.epochs, "neural: passes over the samples (default as btf-compress)");
  sweep->add_flag("--no-ssim", [&](std::int64_t) { so.ssim = false; }, "Skip SSIM");
  sweep->add_flag("--no-render", sf.no_render, "Leave the rendered comparison out of the report");
  sweep->add_flag("--no-codecs", sf.no_codecs, "Do not keep the codec files in DIR/codecs");
  sweep->add_flag("--viewer", sf.viewer,
                  "Export the rendered lpca/pca-view codecs into DIR/viewer/exports and copy the WebGL2 viewer beside "
                  "the report, which links it");
  sweep->add_option("--render-size", so.render_options.width, "Width of each rendered image in pixels (height = 4/5)");
  btf::cli::AddCommonFlags(*sweep, common);

  StabilityFlags tf;
  auto* stability = app.add_subcommand("stability", "Run the numerical stability suite (stiff and extreme cases "
                                                    "through synth, compress, metrics and render); exit 1 if any fails");
  stability->add_option("--only", tf.options.only, "Run only cases whose name starts with one of these prefixes");
  stability->add_flag("--list", tf.list, "List the case names and exit");
  btf::cli::AddCommonFlags(*stability, common);

  // The viewer (docs/viewer.md) and the two renders of one scene.
  SceneFlags vf, wf, rf;
  vf.tiles = 12;  // the interactive viewer starts with the material repeating at a cloth-like scale
  auto add_scene = [](CLI::App* c, SceneFlags& f) {
    c->add_option("--scene", f.scene, "Scene: patch-point (flat patch, point light) or cylinder-env (cylinder, sampled sky)")
        ->check(CLI::IsMember(btf::WebSceneNames()));
    c->add_option("--size", f.size, "Image size WIDTHxHEIGHT in pixels");
    c->add_option("--exposure", f.exposure, "Display value = sRGB(clamp(exposure * radiance, 0, 1))");
    c->add_option("--tiles", f.tiles, "Texture repeats along each side of the plane (the cylinder and the cloth at the same texel size)");
  };
  auto add_browser = [](CLI::App* c, SceneFlags& f) {
    c->add_option("--chromium", f.browser.chromium, "Chromium executable");
    c->add_option("--node", f.browser.node, "node executable");
    c->add_option("--viewer-dir", f.browser.viewer_dir, "Viewer folder (default: $BTF_VIEWER_DIR, else the source tree's viewer/)");
  };
  auto* view = app.add_subcommand("view", "Serve the WebGL2 viewer of EXPORT_DIR on localhost and print its URL");
  view->add_option("EXPORT_DIR", vf.source, "Export folder (btf-compress export)")->required();
  view->add_option("--port", vf.port, "TCP port on 127.0.0.1");
  add_scene(view, vf);
  add_browser(view, vf);
  auto* web = app.add_subcommand("render-web", "Render a scene of EXPORT_DIR in headless Chromium (software WebGL2) to a PNG");
  web->add_option("EXPORT_DIR", wf.source, "Export folder (btf-compress export)")->required();
  web->add_option("-o,--output", wf.output, "PNG to write (sRGB)")->required();
  web->add_option("--frames", wf.frames, "Also time this many frames and report ms per frame (0 = no benchmark)");
  web->add_option("--timeout", wf.browser.timeout_s, "Seconds allowed for one browser run");
  web->add_flag("--page", wf.page, "Write a screenshot of the interactive page (controls, ms per frame) instead of the frame");
  add_scene(web, wf);
  add_browser(web, wf);
  btf::cli::AddCommonFlags(*web, common);
  auto* render = app.add_subcommand("render", "Render a scene of an export folder, codec or dataset on the CPU to a PNG");
  render->add_option("SOURCE", rf.source, "Export folder, codec or dataset file")->required();
  render->add_option("-o,--output", rf.output, "PNG to write (sRGB)")->required();
  add_scene(render, rf);
  btf::cli::AddCommonFlags(*render, common);

  return btf::cli::Main(argc, argv, app, [&]() -> int {
    if (*view) return RunView(vf);
    if (*web) return RunRenderWeb(app, common, wf);
    if (*render) return RunRender(app, common, rf);
    if (*stability) return RunStability(app, common, tf);
    if (*sweep) return RunSweep(app, common, sf, argc, argv);
    return RunCompare(app, common, cf);
  });
}
