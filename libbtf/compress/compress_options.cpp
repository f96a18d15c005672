#include "libbtf/compress/compress_options.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>

#include "libbtf/core/error.h"

namespace btf {

std::uint64_t LpcaMemoryLimit() {
  std::uint64_t limit = MaxAllocationBytes();
  std::ifstream meminfo("/proc/meminfo");
  std::string key;
  std::uint64_t kib = 0;
  while (meminfo >> key >> kib)
    if (key == "MemAvailable:") return std::min(limit, kib * 1024);
    else meminfo.ignore(std::numeric_limits<std::streamsize>::max(), '\n');
  return limit;
}

// The fields are named as in the provenance and the Python keywords (ToJson's flat names).
void LpcaOptions::Check() const {
  BTF_CHECK_OPTION(max_iterations >= 0 && max_iterations <= 1000, "max_iterations", "must be 0..1000");
  BTF_CHECK_OPTION(min_improvement >= 0 && min_improvement < 1, "min_improvement", "must be in [0, 1)");
  BTF_CHECK_OPTION(memory == "auto" || memory == "in-core" || memory == "out-of-core", "lpca_memory",
                   "must be auto, in-core or out-of-core");
  BTF_CHECK_OPTION(matrix == "half" || matrix == "float", "lpca_matrix", "must be half or float");
  BTF_CHECK_OPTION(gram_limit >= 1, "gram_limit", "must be >= 1");
  BTF_CHECK_OPTION(sample >= 1, "lpca_sample", "must be >= 1");
  BTF_CHECK_OPTION(splits >= 0 && splits <= 1000, "lpca_splits", "must be 0..1000");
  BTF_CHECK_OPTION(subspace >= 0 && subspace <= 65536, "lpca_subspace", "must be 0..65536");
}

void LpcaTensorOptions::Check() const {
  BTF_CHECK_OPTION(quant_bits == 8 || quant_bits == 16, "quant_bits", "must be 8 or 16");
  BTF_CHECK_OPTION(growth >= 0 && std::isfinite(growth), "tensor_growth", "must be >= 0");
}

void NeuralOptions::Check() const {
  BTF_CHECK_OPTION(latent >= 0 && latent <= 256, "neural_latent", "must be 0..256");
  BTF_CHECK_OPTION(hidden.size() <= 16, "neural_hidden", "at most 16 layers");
  for (const int h : hidden) BTF_CHECK_OPTION(h >= 1 && h <= 4096, "neural_hidden", "widths must be 1..4096");
  BTF_CHECK_OPTION(fourier >= 0 && fourier <= 8, "neural_fourier", "must be 0..8");
  BTF_CHECK_OPTION(latent_storage == "uint8" || latent_storage == "half", "neural_latent_storage",
                   "must be uint8 or half");
  BTF_CHECK_OPTION(samples >= 1 && samples <= (std::int64_t(1) << 31) - 1, "neural_samples", "must be 1..2^31-1");
  BTF_CHECK_OPTION(steps >= 0 && steps <= 100000000, "neural_steps", "must be 0..1e8");
  BTF_CHECK_OPTION(epochs > 0 && epochs <= 1e6, "neural_epochs", "must be in (0, 1e6]");
  BTF_CHECK_OPTION(batch >= 1 && batch <= (1 << 20), "neural_batch", "must be 1..2^20");
  BTF_CHECK_OPTION(learning_rate > 0 && learning_rate <= 1, "neural_learning_rate", "must be in (0, 1]");
  BTF_CHECK_OPTION(linear_loss >= 0 && linear_loss <= 1, "neural_linear_loss", "must be in [0, 1]");
}

void CompressOptions::Check() const {
  BTF_CHECK_OPTION(components >= 1 && components <= 4096, "components", "must be 1..4096");
  BTF_CHECK_OPTION(clusters >= 1 && clusters <= 65535, "clusters", "must be 1..65535");
  BTF_CHECK_OPTION(target_error >= 0 && target_error < 1, "error", "a relative RMS error in [0, 1)");
  BTF_CHECK_OPTION(retained_energy >= 0 && retained_energy <= 1, "energy", "a fraction in [0, 1]");
  BTF_CHECK_OPTION(!(target_error > 0 && retained_energy > 0), "error/energy", "give at most one of the two");
  BTF_CHECK_OPTION(max_bytes == 0 || (target_error == 0 && retained_energy == 0), "bytes",
                   "give at most one of --bytes, --error and --energy");
  tensor.Check();
  BTF_CHECK_OPTION(method != CodecMethod::kLpcaTensor || retained_energy == 0, "energy",
                   "lpca-tensor takes --error or --bytes (its terms are chosen by the codec's error)");
  BTF_CHECK_OPTION(method != CodecMethod::kLpcaTensor || storage == CodecStorage::kFloat, "storage",
                   "lpca-tensor stores quantised codes (--quant-bits), not float or half arrays");
  BTF_CHECK_OPTION(log_epsilon > 0 && std::isfinite(log_epsilon), "log_epsilon", "must be > 0");
  lpca.Check();
  neural.Check();
  BTF_CHECK_OPTION(method != CodecMethod::kNeural || (target_error == 0 && retained_energy == 0), "error/energy",
                   "the neural codec takes --bytes or its own sizes (--neural-latent, --neural-hidden): its error is "
                   "known only after training");
  BTF_CHECK_OPTION(method != CodecMethod::kNeural || storage == CodecStorage::kFloat, "storage",
                   "the neural codec stores its latents as --neural-latent-storage uint8|half and its decoder as float");
  BTF_CHECK_OPTION(storage == CodecStorage::kFloat || !IsFullMatrixFactorisation(method), "storage",
                   "half storage is for pca-view and lpca codecs (fmf/dfmf factors are stored as float)");
}

nlohmann::json CompressOptions::ToJson() const {
  nlohmann::json j = {{"method", MethodName(method)},   {"components", components},
          {"clusters", clusters},           {"target_error", target_error},
          {"retained_energy", retained_energy}, {"seed", seed},
          {"log_transform", log_transform}, {"log_epsilon", log_epsilon},
          {"max_iterations", lpca.max_iterations}, {"min_improvement", lpca.min_improvement},
          {"lpca_memory", lpca.memory},     {"lpca_sample", lpca.sample},
          {"lpca_splits", lpca.splits},     {"lpca_subspace", lpca.subspace},
          {"lpca_matrix", lpca.matrix},
          {"gram_limit", lpca.gram_limit},  {"lpca_warm_start", lpca.warm_start},
          {"lpca_prune", lpca.prune},       {"storage", StorageName(storage)},
          {"max_bytes", max_bytes},         {"quant_bits", tensor.quant_bits},
          {"tensor_growth", tensor.growth}};
  if (method != CodecMethod::kNeural) return j;
  j["log_transform"] = LogTransform();
  j["neural_latent"] = neural.latent;
  j["neural_hidden"] = neural.hidden;
  j["neural_fourier"] = neural.fourier;
  j["neural_latent_storage"] = neural.latent_storage;
  j["neural_samples"] = neural.samples;
  j["neural_steps"] = neural.steps;
  j["neural_epochs"] = neural.epochs;
  j["neural_batch"] = neural.batch;
  j["neural_learning_rate"] = neural.learning_rate;
  j["neural_linear_loss"] = neural.linear_loss;
  return j;
}

}  // namespace btf
