// btf-compress: per-view PCA and local-PCA codecs, decoding, renderer export (docs/btf-compress.md).
//   btf-compress DATASET --method pca-view|lpca [...] -o codec.h5
//   btf-compress decode CODEC -o dataset.h5
//   btf-compress export CODEC --format schneider -o DIR
#include <fmt/format.h>

#include "libbtf/compress/codec.h"
#include "libbtf/export/schneider.h"
#include "libbtf/io/file_kind.h"
#include "tools/common/cli.h"

namespace {

std::string Bytes(std::uint64_t b) {
  if (b >= (1ull << 30)) return fmt::format("{:.2f} GiB", double(b) / (1ull << 30));
  if (b >= (1ull << 20)) return fmt::format("{:.2f} MiB", double(b) / (1ull << 20));
  if (b >= (1ull << 10)) return fmt::format("{:.1f} KiB", double(b) / (1ull << 10));
  return fmt::format("{} B", b);
}

void PrintSummary(const btf::CompressSummary& s, const std::string& out) {
  fmt::print("{} -> {} ({})\n", s.input, out, s.method);
  fmt::print("  shape                 {} views x {} lights x {} x {} texels x {} channels\n", s.views, s.lights, s.width,
             s.height, s.channels);
  if (s.method == "lpca")
    fmt::print("  clusters x components {} x {} (max per cluster)\n", s.clusters, s.components);
  else
    fmt::print("  components            {} (max per view slot)\n", s.components);
  fmt::print("  codec size            {} (coefficients)\n", Bytes(s.codec_bytes));
  fmt::print("  ratio                 {:.2f}:1 vs float32 raw ({}), {:.2f}:1 vs half raw ({})\n", s.ratio_float32,
             Bytes(s.raw_float32_bytes), s.ratio_half, Bytes(s.raw_half_bytes));
  fmt::print("  RMSE                  {:.6g}\n", s.rmse);
  fmt::print("  relative error        {:.6g} (||decoded - input|| / ||input||)\n", s.relative_error);
  fmt::print("  PSNR                  {:.2f} dB (peak = max |input value| = {:.6g})\n", s.psnr_db, s.psnr_peak);
  if (s.method == "lpca") {
    std::string it;
    for (std::size_t i = 0; i < s.iteration_errors.size(); ++i) it += fmt::format("{}{:.5f}", i ? " " : "", s.iteration_errors[i]);
    fmt::print("  iteration errors      {}\n", it);
  }
  if (s.scene_used)
    fmt::print("  scene                 kept {}/{} views, {}/{} lights; full codec {} -> saved {}; error on used "
               "directions {:.6g}\n",
               s.views, s.input_views, s.lights, s.input_lights, Bytes(s.full_codec_bytes), Bytes(s.bytes_saved),
               s.relative_error);
  std::string t;
  for (const auto& [name, sec] : s.times.phases()) t += fmt::format("{} {:.2f} s, ", name, sec);
  fmt::print("  time                  {}total {:.2f} s\n", t, s.times.Total());
  for (const auto& w : s.warnings) fmt::print("  warning               {}\n", w);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Compress a BTF dataset with per-view PCA (Sattler 2003) or local PCA (Mueller 2003); decode codecs; "
               "export LPCA codecs for real-time rendering (Schneider 2004).",
               "btf-compress"};
  app.require_subcommand(0, 1);
  app.fallthrough();
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  std::string dataset, out, method = "pca-view", scene;
  btf::CompressOptions co;
  app.add_option("DATASET", dataset, "Input dataset (.h5, libbtf-dataset)");
  app.add_option("--method", method, "pca-view | lpca")->capture_default_str();
  app.add_option("--components,-c", co.components,
                 "Components per view slot (pca-view) or per cluster (lpca); the maximum with --error/--energy")
      ->capture_default_str();
  app.add_option("--clusters,-k", co.clusters, "LPCA clusters")->capture_default_str();
  app.add_option("--error", co.target_error, "Target relative RMS error per slot/cluster (0 = use --components)")
      ->capture_default_str();
  app.add_option("--energy", co.retained_energy, "Retained fraction of centred energy per slot/cluster (0 = off)")
      ->capture_default_str();
  app.add_option("--seed", co.seed, "Seed of k-means++ and the randomised SVD")->capture_default_str();
  app.add_flag("--log", co.log_transform, "Compress log(x + epsilon) (HDR data); recorded in the codec");
  app.add_option("--log-epsilon", co.log_epsilon, "Epsilon of --log, in data units")->capture_default_str();
  app.add_option("--max-iterations", co.max_iterations, "LPCA: PCA/reassignment rounds at most")->capture_default_str();
  app.add_option("--min-improvement", co.min_improvement, "LPCA: stop when a round improves the error by less")
      ->capture_default_str();
  app.add_option("--scene", scene, "scene.json: keep only the directions, mip level and channels a scene uses");
  app.add_option("-o,--output", out, "Output codec file (.h5)");

  std::string d_codec, d_out;
  auto* cd = app.add_subcommand("decode", "Decode a codec into a dataset file");
  cd->add_option("CODEC", d_codec, "Codec file")->required();
  cd->add_option("-o,--output", d_out, "Output dataset (.h5)")->required();

  std::string e_codec, e_out, e_format = "schneider";
  btf::SchneiderExportOptions eo;
  auto* ce = app.add_subcommand("export", "Export an LPCA codec for a renderer");
  ce->add_option("CODEC", e_codec, "Codec file (lpca)")->required();
  ce->add_option("--format", e_format, "Export format (schneider)")->capture_default_str();
  ce->add_option("--view-grid", eo.view_grid, "Samples per side of the (s_v, t_v) square")->capture_default_str();
  ce->add_option("--light-grid", eo.light_grid, "Samples per side of the (s_l, t_l) square")->capture_default_str();
  ce->add_option("--components", eo.components, "Eigen-ABRDFs per cluster to export (-1 = all)")->capture_default_str();
  ce->add_option("-o,--output", e_out, "Output folder")->required();

  return btf::cli::Main(argc, argv, app, [&] {
    const btf::Reporter rep = btf::cli::MakeReporter(common);
    if (cd->parsed()) {
      const btf::Codec codec = btf::ReadCodec(d_codec);
      btf::Timer t;
      btf::DecodeToDatasetFile(codec, d_out, rep);
      nlohmann::json j = {{"codec", d_codec}, {"output", d_out}, {"method", btf::MethodName(codec.method())},
                          {"bytes_decoded", codec.RawBytes(4)}, {"seconds", t.Seconds()}};
      if (common.json)
        btf::cli::PrintJson(j);
      else
        fmt::print("{} -> {} ({} decoded in {:.2f} s)\n", d_codec, d_out, Bytes(codec.RawBytes(4)), t.Seconds());
      return 0;
    }
    if (ce->parsed()) {
      if (e_format != "schneider") btf::ThrowUsage("unknown export format '{}' (available: schneider)", e_format);
      const btf::Codec codec = btf::ReadCodec(e_codec);
      const btf::SchneiderExportSummary s = btf::ExportSchneider(codec, e_out, eo, rep);
      if (common.json)
        btf::cli::PrintJson(s.ToJson());
      else
        fmt::print("{} -> {}/ : {} clusters x {} functions on a {}^2 x {}^2 grid; textures {}, weights {}, index {}\n",
                   e_codec, e_out, s.clusters, s.functions, s.view_grid, s.light_grid, Bytes(s.texture_bytes),
                   Bytes(s.weight_bytes), Bytes(s.index_bytes));
      return 0;
    }
    if (dataset.empty()) btf::ThrowUsage("give a DATASET to compress, or a subcommand (decode, export); see --help");
    if (out.empty()) btf::ThrowUsage("-o/--output is required when compressing");
    co.method = btf::ParseMethod(method);
    if (!scene.empty()) co.scene = btf::SceneSpec::Load(scene);
    // Claim the output before the work: an unwritable folder fails now, not after the compression.
    btf::AtomicOutput target(out);
    target.Reserve();
    btf::CompressSummary s;
    const btf::Codec codec = btf::CompressFile(dataset, co, rep, &s);
    btf::WriteCodec(target, codec, "btf-compress");
    if (common.json) {
      nlohmann::json j = s.ToJson();
      j["output"] = out;
      btf::cli::PrintJson(j);
    } else {
      PrintSummary(s, out);
    }
    return 0;
  });
}
