#pragma once
// Codec sweeps: compress a dataset with each setting, time compression and decoding, measure the
// error and the size, then write results.json, SVG plots, rendered comparisons (PNG) and a
// self-contained HTML report with the plots inline (docs/btf-eval.md, "sweep").
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/compress/compress.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/eval/render.h"

namespace btf {

// The point light of the sweep's patch render (world, z up; the patch is |x|, |y| <= 1 at z = 0,
// the camera at (0, -3.2, 2.6) looking at the origin): far behind the patch as the camera sees it
// and low, 11 degrees above the horizon seen from the patch center. Under this grazing light the
// yarns' specular highlights show, which an overhead light leaves as small spots.
inline const Vec3 kSweepPointLight{0.5, 5.0, 1.0};

struct SweepOptions {
  std::vector<std::string> methods{"pca-view", "lpca", "lpca-tensor", "neural"};  // codec methods (libbtf/compress)
  // c per view slot / per cluster; neural: the latent width (NeuralOptions::latent).
  std::vector<int> components{1, 2, 4, 8, 16};
  std::vector<int> clusters{8, 16, 32};                   // k, lpca only
  int runs = 3;                 // timed runs per setting; the median is reported
  bool log_transform = false;   // compress with the log transform (CompressOptions::log_transform)
  // The neural codec's options (its latent width comes from `components`). Its training samples
  // are capped at the BTF's value count / channels (texel, light, view triples), so that a small
  // dataset trains in proportion to its size.
  NeuralOptions neural;
  std::uint64_t seed = 1;       // CompressOptions::seed
  // The error on the plots' y axis and for the Pareto fronts: "rel" (relative L2) or "rmse".
  std::string error_metric = "rel";
  bool ssim = true;             // compute mean SSIM for every point
  bool keep_codecs = true;      // write every codec to DIR/codecs/<method>_k<k>_c<c>.h5
  bool render = true;           // rendered comparisons in the report
  // Which setting of each method is rendered: the smallest (fewest bytes) whose relative L2 error
  // is <= render_max_rel_error, or the most accurate one if none is (or the error is undefined).
  double render_max_rel_error = 0.02;
  // Size, environment and point light of the renders (scene and lighting are set per panel: the
  // patch under the point light, the cylinder under the environment). The point light defaults
  // to kSweepPointLight, not RenderOptions' overhead light.
  RenderOptions render_options = [] {
    RenderOptions r;
    r.light_position = kSweepPointLight;
    return r;
  }();
  std::string command_line;     // shown in the report (how it was made)
  // Non-empty: the WebGL2 viewer folder (viewer/, with node_modules/three from npm ci). Each
  // method's rendered codec that a renderer export takes (lpca: schneider, pca-view: sattler;
  // default export options) is exported into DIR/viewer/exports/<setting>/, the viewer's page and
  // the three.js files it loads are copied into DIR/viewer/, and the report links them (needs
  // render: the rendered codecs are the chosen ones).
  std::string viewer_dir;
  void Check() const;
};

struct SweepPoint {
  std::string method;
  int components = 0;  // requested c
  int clusters = 0;    // requested k (lpca), 0 for pca-view
  int stored_components = 0, stored_clusters = 0;  // after clamping
  std::uint64_t bytes = 0;       // Codec::StoredBytes(): coefficient arrays
  std::uint64_t file_bytes = 0;  // size of the codec file (0 if not kept)
  double ratio_float32 = 0, ratio_half = 0;
  std::vector<double> compress_runs, decode_runs;  // seconds
  double compress_s = 0, decode_s = 0;             // medians
  double rmse = 0, max_abs = 0;
  std::optional<double> rel_l2, psnr_db, mean_ssim;
  double error = 0;  // the chosen error metric
  bool pareto_bytes = false, pareto_compress = false, pareto_decode = false;
  std::vector<std::string> warnings;
  std::string codec_file;
  nlohmann::json ToJson() const;
};

struct SweepRender {
  std::string method, label, scene, lighting, file;
  double max_rel_diff = 0;  // largest |decoded - truth| luminance relative to truth's 99th percentile
  double mean_rel_diff = 0;
};

struct SweepViewerExport {
  std::string method, label, layout, directory, page;  // page: relative to the report, with ?export=
};

struct SweepSummary {
  std::string dataset, output_dir, error_metric;
  int views = 0, lights = 0, height = 0, width = 0, channels = 0;
  std::uint64_t raw_float32_bytes = 0;
  double psnr_peak = 0;
  std::vector<SweepPoint> points;
  std::vector<SweepRender> renders;
  std::vector<SweepViewerExport> viewer_exports;  // with SweepOptions::viewer_dir
  std::vector<std::string> files;  // everything written, report last
  std::string report;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;  // the settings table and where the report is
};

// Reads the dataset into memory, sweeps, writes the folder output_dir atomically as a whole
// (AtomicDirectory: an earlier sweep there is replaced only once the new one is complete).
SweepSummary RunSweep(const SweepOptions& options, const std::filesystem::path& dataset,
                      const std::filesystem::path& output_dir, const Reporter& reporter = {});

}  // namespace btf
