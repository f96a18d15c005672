#include "libbtf/compress/value_transform.h"

#include <cmath>

#include "libbtf/core/error.h"

namespace btf {

void ValueMap::Apply(const std::string& source, int view, float* data, std::size_t n) const {
  if (!log()) return;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(data[i] > -epsilon))
      ThrowBadInput("'{}' view {}: value {} is <= -epsilon ({}), outside the log transform's domain; raise "
                    "--log-epsilon or drop --log",
                    source, view, data[i], epsilon);
    data[i] = static_cast<float>(std::log(double(data[i]) + epsilon));
  }
}

}  // namespace btf
