#include "libbtf/compress/compress_summary.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "libbtf/compress/codec.h"

namespace btf {

nlohmann::json CompressSummary::ToJson() const {
  nlohmann::json j;
  j["method"] = method;
  j["storage"] = storage;
  j["input"] = input;
  j["shape"] = {{"views", views}, {"lights", lights}, {"height", height}, {"width", width}, {"channels", channels}};
  j["components"] = components;
  const bool lpca_like = method == "lpca" || method == "lpca-tensor";
  j[lpca_like                            ? "cluster_components"
    : method == "fmf" || method == "dfmf" ? "matrix_components"
    : method == "neural"                  ? "latent_components"
                                          : "slot_components"] = slot_components;
  if (lpca_like) {
    j["clusters"] = clusters;
    j["iteration_relative_errors"] = iteration_errors;
    j["iteration_reassigned_texels"] = iteration_changes;
    j["reassignment_clusters_compared"] = lpca_compared;
    j["sample_round_relative_errors"] = sample_errors;
    j["split_merge_relative_errors"] = split_errors;
    j["lpca_memory"] = {{"mode", lpca_memory}, {"matrix", lpca_matrix}, {"input_passes", lpca_passes},
                        {"peak_rss_bytes", peak_rss_bytes}};
  }
  if (method == "lpca-tensor")
    j["tensor"] = {{"terms", tensor_terms},
                   {"quant_bits", quant_bits},
                   {"lpca_stage_relative_error", lpca_stage_error},
                   {"predicted_relative_error", predicted_error}};
  if (method == "neural")
    j["neural"] = {{"samples", neural_samples},       {"steps", neural_steps},
                   {"hidden", neural_hidden},         {"decoder_parameters", neural_parameters},
                   {"first_loss", neural_first_loss}, {"last_loss", neural_last_loss}};
  j["codec_bytes"] = codec_bytes;
  j["raw_float32_bytes"] = raw_float32_bytes;
  j["raw_half_bytes"] = raw_half_bytes;
  j["ratio_vs_float32"] = ratio_float32;
  j["ratio_vs_half"] = ratio_half;
  j["rmse"] = rmse;
  j["relative_error"] = relative_error;
  j["max_abs_error"] = max_abs_error;
  j["psnr_db"] = psnr_db;
  j["psnr_peak"] = psnr_peak;
  j["psnr_peak_definition"] = psnr_peak_definition;
  j["warnings"] = warnings;
  if (scene_used) {
    j["scene"] = {{"input_shape",
                   {{"views", input_views}, {"lights", input_lights}, {"height", input_height},
                    {"width", input_width}, {"channels", input_channels}}},
                  {"full_codec_bytes", full_codec_bytes},
                  {"bytes_saved", bytes_saved},
                  {"error_on_used_directions", relative_error}};
  }
  j["seconds"] = times.ToJson();
  return j;
}

std::string CompressSummary::Report() const {
  std::string r = fmt::format("{} ({})\n", input, method);
  r += fmt::format("  shape                 {} views x {} lights x {} x {} texels x {} channels\n", views, lights, width,
                   height, channels);
  if (method == "lpca" || method == "lpca-tensor")
    r += fmt::format("  clusters x components {} x {} (max per cluster)\n", clusters, components);
  if (method == "lpca-tensor")
    r += fmt::format("  factor terms          {} ({}-bit codes; LPCA stage error {:.6g}, predicted {:.6g})\n", tensor_terms,
                     quant_bits, lpca_stage_error, predicted_error);
  else if (method == "neural")
    r += fmt::format("  latent, decoder       {} values per texel; hidden {} ({} parameters); {} samples, {} steps, "
                     "loss {:.4g} -> {:.4g}\n",
                     components, fmt::join(neural_hidden, ","), neural_parameters, neural_samples, neural_steps,
                     neural_first_loss, neural_last_loss);
  else if (method == "fmf" || method == "dfmf")
    r += fmt::format("  components            {} (per matrix: {})\n", components, fmt::join(slot_components, " "));
  else
    r += fmt::format("  components            {} (max per view slot)\n", components);
  r += fmt::format("  codec size            {} ({} bytes; coefficients, {} storage)\n", FormatBytes(codec_bytes), codec_bytes,
                   storage);
  r += fmt::format("  ratio                 {:.2f}:1 vs float32 raw ({}), {:.2f}:1 vs half raw ({})\n", ratio_float32,
                   FormatBytes(raw_float32_bytes), ratio_half, FormatBytes(raw_half_bytes));
  r += fmt::format("  RMSE                  {:.6g}\n", rmse);
  r += fmt::format("  relative error        {:.6g} (||decoded - input|| / ||input||)\n", relative_error);
  r += fmt::format("  PSNR                  {:.2f} dB (peak = {} = {:.6g})\n", psnr_db, psnr_peak_definition, psnr_peak);
  if (method == "lpca" || method == "lpca-tensor")
    r += fmt::format("  iteration errors      {:.5f}\n", fmt::join(iteration_errors, " "));
  if (!lpca_compared.empty())
    r += fmt::format("  clusters compared     {:.2f} (per texel, each reassignment)\n", fmt::join(lpca_compared, " "));
  if (!sample_errors.empty())
    r += fmt::format("  sample round errors   {:.5f}\n", fmt::join(sample_errors, " "));
  if (!split_errors.empty())
    r += fmt::format("  split/merge errors    {:.5f}\n", fmt::join(split_errors, " "));
  if (!lpca_memory.empty())
    r += fmt::format("  lpca memory           {}, {} texel matrix, {} passes over the input, peak memory {}\n", lpca_memory,
                     lpca_matrix, lpca_passes, FormatBytes(peak_rss_bytes));
  if (scene_used)
    r += fmt::format("  scene                 kept {}/{} views, {}/{} lights; full codec {} -> saved {}; error on used "
                     "directions {:.6g}\n",
                     views, input_views, lights, input_lights, FormatBytes(full_codec_bytes), FormatBytes(bytes_saved),
                     relative_error);
  r += fmt::format("  time                  {}\n", times.Report());
  for (const auto& w : warnings) r += fmt::format("  warning               {}\n", w);
  return r;
}

}  // namespace btf
