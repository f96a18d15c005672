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
}

void LpcaTensorOptions::Check() const {
  BTF_CHECK_OPTION(quant_bits == 8 || quant_bits == 16, "quant_bits", "must be 8 or 16");
  BTF_CHECK_OPTION(growth >= 0 && std::isfinite(growth), "tensor_growth", "must be >= 0");
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
  BTF_CHECK_OPTION(storage == CodecStorage::kFloat || !IsFullMatrixFactorisation(method), "storage",
                   "half storage is for pca-view and lpca codecs (fmf/dfmf factors are stored as float)");
}

nlohmann::json CompressOptions::ToJson() const {
  return {{"method", MethodName(method)},   {"components", components},
          {"clusters", clusters},           {"target_error", target_error},
          {"retained_energy", retained_energy}, {"seed", seed},
          {"log_transform", log_transform}, {"log_epsilon", log_epsilon},
          {"max_iterations", lpca.max_iterations}, {"min_improvement", lpca.min_improvement},
          {"lpca_memory", lpca.memory},     {"lpca_sample", lpca.sample},
          {"lpca_splits", lpca.splits},     {"lpca_matrix", lpca.matrix},
          {"gram_limit", lpca.gram_limit},  {"lpca_warm_start", lpca.warm_start},
          {"lpca_prune", lpca.prune},       {"storage", StorageName(storage)},
          {"max_bytes", max_bytes},         {"quant_bits", tensor.quant_bits},
          {"tensor_growth", tensor.growth}};
}

}  // namespace btf
