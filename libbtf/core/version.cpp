#include "libbtf/core/version.h"

namespace btf {

std::string Version() { return BTF_VERSION; }

}  // namespace btf
