#pragma once
// The one value transform of libbtf's codecs: what the compressors apply to every input value
// before the decomposition and what the decoders undo (docs/format.md, "Codec file":
// /codec@transform and @log_epsilon).
#include <cmath>
#include <cstddef>
#include <string>

namespace btf {

// kLog: y = log(x + epsilon); decoding gives exp(y) - epsilon. Inputs must be > -epsilon.
enum class ValueTransform { kNone, kLog };

struct ValueMap {
  ValueTransform kind = ValueTransform::kNone;
  double epsilon = 0;  // of the log transform, in data units (1/sr); 0 without it

  static ValueMap Log(double epsilon) { return {ValueTransform::kLog, epsilon}; }
  bool log() const { return kind == ValueTransform::kLog; }
  // The inverse (the decoders' last step), in double, rounded to float.
  float Inverse(float y) const { return log() ? static_cast<float>(std::exp(double(y)) - epsilon) : y; }
  // The forward transform of `n` values of view slot `view` of source `source`, in place.
  // Refuses (bad input, naming the source, view and value) a value outside the log's domain.
  void Apply(const std::string& source, int view, float* data, std::size_t n) const;
};

}  // namespace btf
