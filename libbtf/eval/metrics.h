#pragma once
// Error metrics between a reference BTF and a test BTF (docs/btf-eval.md, "Metrics").
//
// All sums are accumulated in double, one view slot at a time, so inputs larger than memory work.
// NaN or Inf in either input is refused (btf::Error, bad input) before any figure is reported.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/slot_source.h"
#include "libbtf/io/image_io.h"

namespace btf {

struct CompareOptions {
  // Peak value for PSNR and for the SSIM constants. 0 (default) = max |reference value| (found in
  // a first pass over the reference; the definition compression summaries use too); an all-zero
  // reference then uses 1.
  double peak = 0;
  // SSIM: standard deviation of the Gaussian window in texels (default 1.5, Wang et al. 2004); the
  // window is truncated at 3 sigma and renormalized at image borders. K1 = 0.01, K2 = 0.03.
  double ssim_sigma = 1.5;
  bool ssim = true;  // false skips SSIM (the most expensive metric)
  // Error maps: false-color PNGs of the `error_maps` worst images (by RMSE) written to
  // `error_maps_dir` (must exist); empty dir = none.
  std::filesystem::path error_maps_dir;
  int error_maps = 4;
  int worst_images = 8;  // how many worst images the summary lists
  void Check() const;
};

struct ImageError {
  int view = 0, light = 0;
  double rmse = 0, max_abs = 0;
};

struct CompareSummary {
  std::string reference, test;
  // The test is a codec whose directions differ from the reference's, decoded at the reference's
  // directions (CodecAtDirections: Codec::Value at texel centres).
  bool test_at_reference_directions = false;
  int views = 0, lights = 0, height = 0, width = 0, channels = 0;
  std::uint64_t values = 0;
  double rmse = 0;
  // ||test - ref||_2 / ||ref||_2; empty when the reference is all zero.
  std::optional<double> rel_l2;
  double peak = 0;
  std::string peak_source;  // "max |reference value|", "option", or "1 (reference all zero)"
  // 10 log10(peak^2 / MSE); empty when MSE = 0 (identical inputs).
  std::optional<double> psnr_db;
  double max_abs = 0;
  int max_view = 0, max_light = 0, max_y = 0, max_x = 0, max_channel = 0;
  std::optional<double> mean_ssim;  // empty when SSIM was skipped or undefined (all-zero reference, no peak)
  // Why a figure is undefined or says less than it seems (all-zero reference; a few values
  // dominating the reference: ErrorStats::PeakDominance).
  std::vector<std::string> notes;
  // Images left out because either input marks them missing (a dataset imported with
  // --allow-missing): every figure is over the other images.
  int skipped_images = 0;
  std::vector<double> view_rmse, light_rmse;
  std::vector<Angles> view_angles, light_angles;  // of the reference's samplings
  std::vector<ImageError> worst;             // worst images first
  std::vector<std::string> error_map_files;  // written PNGs
  PhaseTimes times;

  // Value of a named metric for thresholds: "rmse", "rel" or "psnr". Throws btf::Error (bad input)
  // when it is undefined for these inputs (rel of an all-zero reference).
  double Metric(const std::string& metric) const;
  nlohmann::json ToJson() const;
  // The human-readable report btf-eval compare prints.
  std::string Report() const;
};

// Compares two BTFs with equal shapes and samplings (else btf::Error, bad input). A codec test
// (CodecSource) whose view or light directions differ from the reference's is decoded at the
// reference's directions instead (CodecAtReferenceDirections, codec_at_directions.h: its decoder
// there for the neural codec, the barycentric blend of sampled directions for the others) and the
// summary says so; datasets with other samplings are refused.
CompareSummary Compare(const CompareOptions& options, const SlotSource& reference, const SlotSource& test,
                       const Reporter& reporter = {});

// Mean SSIM of one image pair (height x width x channels), averaged over texels and channels.
double MeanSsim(const float* reference, const float* test, int height, int width, int channels, double peak,
                double sigma = 1.5);

// False-color error map of one image pair: per-texel RMS over channels through the "viridis"
// map (FalseColorImage: dark blue 0, yellow `scale`), upscaled by an integer factor to at least
// `min_size` pixels, with a color bar labelled 0 and `scale` (DejaVu Sans through OpenImageIO;
// without a font, see LabelFont, the bar has no numbers). Returns linear values: write them with
// srgb = true.
Image ErrorMapImage(const float* reference, const float* test, int height, int width, int channels, double scale,
                    int min_size = 256);

}  // namespace btf
