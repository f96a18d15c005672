// btf-eval: compare BTFs, sweep codec settings (error against size and run time), stability suite
// (docs/btf-eval.md).
#include <fmt/format.h>

#include "libbtf/eval/metrics.h"
#include "libbtf/eval/stability.h"
#include "libbtf/eval/sweep.h"
#include "tools/common/cli.h"

namespace {

void PrintCompareHuman(const btf::CompareSummary& s, const btf::SlotSource& ref) {
  fmt::print("reference  {}\ntest       {}\n", s.reference, s.test);
  fmt::print("shape      {} views x {} lights x {}x{} texels x {} channels ({} values)\n", s.views, s.lights,
             s.width, s.height, s.channels, s.values);
  fmt::print("rmse       {:.6g}\n", s.rmse);
  fmt::print("rel_l2     {}\n", s.rel_l2 ? fmt::format("{:.6g}", *s.rel_l2) : "undefined (reference all zero)");
  fmt::print("psnr       {} (peak {:.6g}, {})\n", s.psnr_db ? fmt::format("{:.3f} dB", *s.psnr_db) : "inf (identical)",
             s.peak, s.peak_source);
  fmt::print("max_abs    {:.6g} at view {} light {} texel (y {}, x {}) channel {}\n", s.max_abs, s.max_view,
             s.max_light, s.max_y, s.max_x, s.max_channel);
  if (s.mean_ssim) fmt::print("mean_ssim  {:.6f}\n", *s.mean_ssim);
  fmt::print("\n{:>5} {:>9} {:>9} {:>12}   per-view RMSE\n", "view", "theta", "phi", "rmse");
  for (int v = 0; v < s.views; ++v) {
    const auto a = ref.views().angles(v);
    fmt::print("{:>5} {:>9.2f} {:>9.2f} {:>12.6g}\n", v, btf::RadToDeg(a.theta), btf::RadToDeg(a.phi), s.view_rmse[v]);
  }
  fmt::print("\n{:>5} {:>9} {:>9} {:>12}   per-light RMSE\n", "light", "theta", "phi", "rmse");
  for (int l = 0; l < s.lights; ++l) {
    const auto a = ref.lights().angles(l);
    fmt::print("{:>5} {:>9.2f} {:>9.2f} {:>12.6g}\n", l, btf::RadToDeg(a.theta), btf::RadToDeg(a.phi), s.light_rmse[l]);
  }
  fmt::print("\nworst images\n");
  for (const auto& w : s.worst)
    fmt::print("  view {:>3} light {:>3}  rmse {:.6g}  max_abs {:.6g}\n", w.view, w.light, w.rmse, w.max_abs);
  for (const auto& f : s.error_map_files) fmt::print("error map  {}\n", f);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Evaluate BTF codecs: compare two BTFs, sweep codec settings (error against size and run time, "
               "HTML report), run the numerical stability suite.",
               "btf-eval"};
  app.require_subcommand(1);
  btf::cli::CommonFlags common;

  // compare
  auto* compare = app.add_subcommand("compare", "Error metrics of TEST against REFERENCE (datasets or codecs)");
  std::string ref_path, test_path, metric = "rel", maps_dir;
  std::optional<double> warn, fail;
  btf::CompareOptions copt;
  compare->add_option("REFERENCE", ref_path, "Reference dataset or codec file")->required();
  compare->add_option("TEST", test_path, "Dataset or codec file to evaluate")->required();
  compare->add_option("--metric", metric, "Metric the thresholds apply to: rmse, rel or psnr (dB; fails BELOW the "
                                          "threshold)")
      ->check(CLI::IsMember({"rmse", "rel", "psnr"}))
      ->capture_default_str();
  compare->add_option("--warn", warn, "Print a warning when the metric is worse than this");
  compare->add_option("--fail", fail, "Exit 1 when the metric is worse than this");
  compare->add_option("--peak", copt.peak, "Peak for PSNR and SSIM; 0 = the reference's maximum")->capture_default_str();
  compare->add_option("--ssim-sigma", copt.ssim_sigma, "SSIM Gaussian window sigma in texels")->capture_default_str();
  compare->add_flag("--no-ssim", [&](std::int64_t) { copt.ssim = false; }, "Skip SSIM");
  compare->add_option("--error-maps", maps_dir, "Write false-colour error maps of the worst images to this folder");
  compare->add_option("--maps", copt.error_maps, "Number of error maps")->capture_default_str();
  btf::cli::AddCommonFlags(*compare, common);


  // sweep
  auto* sweep = app.add_subcommand("sweep", "Compress DATASET with each setting; error against size and run time; "
                                            "results.json, plots and report.html in DIR");
  std::string sweep_dataset, sweep_dir, methods = "pca-view,lpca", components = "1,2,4,8,16", clusters = "8,16,32";
  btf::SweepOptions sopt;
  bool no_render = false, no_codecs = false;
  sweep->add_option("DATASET", sweep_dataset, "Dataset file (read into memory)")->required();
  sweep->add_option("-o,--output", sweep_dir, "Output folder (created if missing)")->required();
  sweep->add_option("--methods", methods, "Comma-separated codec methods")->capture_default_str();
  sweep->add_option("--components", components, "Components c to try (list, e.g. 1,2,4 or 1-8)")->capture_default_str();
  sweep->add_option("--clusters", clusters, "Cluster counts k to try (lpca)")->capture_default_str();
  sweep->add_option("--runs", sopt.runs, "Timed runs per setting (median reported)")->capture_default_str();
  sweep->add_option("--error", sopt.error_metric, "Error on the plots and Pareto fronts: rel or rmse")
      ->check(CLI::IsMember({"rel", "rmse"}))
      ->capture_default_str();
  sweep->add_flag("--log", sopt.log_transform, "Compress with the log transform");
  sweep->add_option("--seed", sopt.seed, "Compression seed")->capture_default_str();
  sweep->add_flag("--no-ssim", [&](std::int64_t) { sopt.ssim = false; }, "Skip SSIM");
  sweep->add_flag("--no-render", no_render, "Leave the rendered comparison out of the report");
  sweep->add_flag("--no-codecs", no_codecs, "Do not keep the codec files in DIR/codecs");
  sweep->add_option("--render-size", sopt.render_options.width, "Width of each rendered image in pixels (height = 4/5)")
      ->capture_default_str();
  btf::cli::AddCommonFlags(*sweep, common);

  // stability
  auto* stability = app.add_subcommand("stability", "Run the numerical stability suite (stiff and extreme cases "
                                                    "through synth, compress, metrics and render); exit 1 if any fails");
  btf::StabilityOptions stab;
  bool list_cases = false;
  stability->add_option("--only", stab.only, "Run only cases whose name starts with one of these prefixes");
  stability->add_flag("--list", list_cases, "List the case names and exit");
  btf::cli::AddCommonFlags(*stability, common);

  return btf::cli::Main(argc, argv, app, [&]() -> int {
    const btf::Reporter reporter = btf::cli::MakeReporter(common);
    if (*stability) {
      if (list_cases) {
        for (const auto& n : btf::StabilityCaseNames()) fmt::print("{}\n", n);
        return 0;
      }
      const btf::StabilitySummary s = btf::RunStability(stab, reporter);
      if (common.json) {
        btf::cli::PrintJson(s.ToJson());
      } else {
        for (const auto& c : s.cases)
          fmt::print("{} {:<34} {:>6.2f} s  {}\n     criterion: {}\n", c.passed ? "PASS" : "FAIL", c.name, c.seconds,
                     c.figure, c.criterion);
        fmt::print("{} passed, {} failed\n", s.passed, s.failed);
      }
      return s.failed ? static_cast<int>(btf::ExitCode::kFailedCheck) : 0;
    }
    if (*sweep) {
      auto split = [](const std::string& text) {
        std::vector<std::string> out;
        std::size_t pos = 0;
        while (pos <= text.size()) {
          const std::size_t comma = std::min(text.find(',', pos), text.size());
          if (comma > pos) out.push_back(text.substr(pos, comma - pos));
          pos = comma + 1;
        }
        return out;
      };
      sopt.methods = split(methods);
      sopt.components = btf::cli::ParseIndexList(components, "--components");
      sopt.clusters = btf::cli::ParseIndexList(clusters, "--clusters");
      sopt.render = !no_render;
      sopt.keep_codecs = !no_codecs;
      sopt.render_options.height = std::max(8, sopt.render_options.width * 4 / 5);
      for (int i = 0; i < argc; ++i) sopt.command_line += (i ? " " : "") + std::string(i ? argv[i] : "btf-eval");
      const btf::SweepSummary s = btf::RunSweep(sweep_dataset, sweep_dir, sopt, reporter);
      if (common.json) {
        btf::cli::PrintJson(s.ToJson());
      } else {
        fmt::print("{:<22} {:>10} {:>7} {:>11} {:>11} {:>11} {:>8} {:>9}\n", "setting", "bytes", "ratio", "compress s",
                   "decode s", s.error_metric, "PSNR dB", "Pareto");
        for (const auto& p : s.points)
          fmt::print("{:<22} {:>10} {:>7.1f} {:>11.4g} {:>11.4g} {:>11.4g} {:>8} {:>9}\n",
                     p.method == "lpca" ? fmt::format("lpca k={} c={}", p.clusters, p.components)
                                        : fmt::format("{} c={}", p.method, p.components),
                     p.bytes, p.ratio_float32, p.compress_s, p.decode_s, p.error,
                     p.psnr_db ? fmt::format("{:.2f}", *p.psnr_db) : "inf",
                     std::string(p.pareto_bytes ? "B" : "") + (p.pareto_compress ? "C" : "") + (p.pareto_decode ? "D" : ""));
        fmt::print("report: {}\n", s.report);
      }
      return 0;
    }

    copt.error_maps_dir = maps_dir;
    if (!maps_dir.empty()) std::filesystem::create_directories(maps_dir);
    const auto ref = btf::OpenSource(ref_path);
    const auto test = btf::OpenSource(test_path);
    const btf::CompareSummary s = btf::Compare(*ref, *test, copt, reporter);
    // Thresholds: rmse and rel are errors (bigger is worse), psnr is a quality (smaller is worse).
    const bool higher_is_better = metric == "psnr";
    auto worse = [&](double value, double limit) { return higher_is_better ? value < limit : value > limit; };
    std::string verdict = "ok";
    if (warn || fail) {
      const double value = s.Metric(metric);
      if (fail && worse(value, *fail))
        verdict = "fail";
      else if (warn && worse(value, *warn))
        verdict = "warn";
      if (verdict == "warn")
        reporter.Warn("{} = {:.6g} is worse than the warning threshold {:.6g}", metric, value, *warn);
      if (verdict == "fail")
        reporter.Warn("{} = {:.6g} is worse than the failure threshold {:.6g}: exit 1", metric, value, *fail);
    }
    if (common.json) {
      auto j = s.ToJson();
      j["metric"] = metric;
      j["warn"] = warn ? nlohmann::json(*warn) : nlohmann::json(nullptr);
      j["fail"] = fail ? nlohmann::json(*fail) : nlohmann::json(nullptr);
      j["verdict"] = verdict;
      btf::cli::PrintJson(j);
    } else {
      PrintCompareHuman(s, *ref);
      fmt::print("verdict    {}\n", verdict);
    }
    return verdict == "fail" ? static_cast<int>(btf::ExitCode::kFailedCheck) : 0;
  });
}
