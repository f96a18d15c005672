#pragma once
// The libbtf version (the CMake project version), reported by every tool's --version and in every
// --json document (docs/architecture.md, "Tools").
#include <string>

namespace btf {

// "MAJOR.MINOR.PATCH".
std::string Version();

// Version of the --json documents the tools print (docs/architecture.md, "JSON output"). Bumped
// when a key is renamed or removed; adding keys does not bump it.
inline constexpr int kJsonSchemaVersion = 1;

}  // namespace btf
