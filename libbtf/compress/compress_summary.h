#pragma once
// What a compression did (btf-compress's text report and --json document, and the "summary"
// stored in a codec's provenance).
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/timer.h"

namespace btf {

struct CompressSummary {
  std::string method;
  std::string storage = "float";  // StorageName of the coefficient arrays; lpca-tensor: "uint8" / "uint16" codes
  std::string input;  // dataset path or "in-memory dataset"
  int views = 0, lights = 0, height = 0, width = 0, channels = 0;
  int components = 0;                  // the maximum stored per slot / cluster
  std::vector<int> slot_components;    // pca-view: per view slot; lpca: per cluster
  int clusters = 0;                    // lpca
  std::vector<double> iteration_errors;  // lpca: relative error after each PCA/reassignment round
  std::vector<int> iteration_changes;    // lpca: texels that changed cluster in each round
  // lpca: clusters whose residual was computed per texel (mean over all texels) in each
  // reassignment of all texels (the first from the sample's models): K without lpca_prune.
  std::vector<double> lpca_compared;
  // lpca: the sample's relative error after each local-PCA round on it (the first: Lloyd's
  // clusters; the sample is all texels when there are no more than lpca_sample), and after each
  // split/merge trial's rounds (kept only if lower).
  std::vector<double> sample_errors, split_errors;
  std::string lpca_memory;               // lpca: "in-core" or "out-of-core" (the mode used)
  std::string lpca_matrix;               // lpca: "half" or "float" (the texel matrix's storage)
  int lpca_passes = 0;                   // lpca: passes over the input's view slots
  std::uint64_t peak_rss_bytes = 0;      // lpca: the process's peak resident memory after compressing
  // lpca-tensor: rank-1 terms kept, quantisation bits, the LPCA stage's relative error and the
  // predicted error of the factorised codec (transformed domain, before quantisation of weights).
  int tensor_terms = 0, quant_bits = 0;
  double lpca_stage_error = 0, predicted_error = 0;
  // neural: training samples drawn, steps run, the first and last step's loss (mean squared error
  // in the log domain), the decoder's hidden widths and parameter count.
  std::int64_t neural_samples = 0, neural_steps = 0, neural_parameters = 0;
  double neural_first_loss = 0, neural_last_loss = 0;
  std::vector<int> neural_hidden;
  std::uint64_t codec_bytes = 0;         // Codec::StoredBytes() (float arrays at 2 bytes with half storage)
  std::uint64_t raw_float32_bytes = 0, raw_half_bytes = 0;  // of the encoded (possibly reduced) BTF
  double ratio_float32 = 0, ratio_half = 0;
  // Errors of the decoded codec against its input, in the original (untransformed) domain.
  double rmse = 0, relative_error = 0, max_abs_error = 0;
  double psnr_db = 0, psnr_peak = 0;  // PSNR = 20 log10(peak / rmse), peak = max |input value|
  std::string psnr_peak_definition = "max |input value|";
  std::vector<std::string> warnings;
  // With a scene: what the full (scene-less) input would have taken at the same components.
  bool scene_used = false;
  int input_views = 0, input_lights = 0, input_height = 0, input_width = 0, input_channels = 0;
  std::uint64_t full_codec_bytes = 0, bytes_saved = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;  // what btf-compress prints
};


}  // namespace btf
