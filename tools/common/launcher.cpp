// The launcher of a tool built as a tool module (tools/common/tool_main.h; docs/architecture.md,
// "Tool modules"): the executables btf-register and btf-synth are this program, compiled once per
// tool with BTF_TOOL_NAME, BTF_TOOL_MODULE_FILE and BTF_VERSION defined (tools/CMakeLists.txt).
// It links nothing of libbtf, OpenCV, MPI or HDF5, so `--version` costs only its own start; any
// other command line is the tool's: its module is loaded with dlopen() from where libbtf keeps
// its modules (libbtf/core/plugin_dirs.h) and its btf_tool_main runs with the same arguments.
#include <dlfcn.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>

#include "libbtf/core/plugin_dirs.h"
#include "tools/common/tool_main.h"

namespace {

// The exit code of a file that cannot be read (btf::ExitCode::kIo, docs/errors.md).
constexpr int kExitIo = 4;

// Whether an MPI launcher started this process as one of its ranks, as libbtf/core/distributed.cpp
// decides: then --version is left to the tool, which prints it on rank 0 alone.
bool LaunchedAsRank() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(v)) return true;
  return false;
}

// One line on stderr, as the tools print errors ("<tool>: error: <message>"); the I/O exit code.
int Fail(const std::string& message) {
  std::fprintf(stderr, "%s: error: %s\n", BTF_TOOL_NAME, message.c_str());
  return kExitIo;
}

}  // namespace

int main(int argc, char** argv) {
  // What the tool's own --version prints (tools/common/cli.cpp, Configure), without loading it.
  if (argc == 2 && std::strcmp(argv[1], "--version") == 0 && !LaunchedAsRank()) {
    std::printf("%s %s\n", BTF_TOOL_NAME, BTF_VERSION);
    return 0;
  }
  namespace fs = std::filesystem;
  const char* env = std::getenv("BTF_PLUGIN_DIR");
  const std::string env_text = env && *env ? std::string("BTF_PLUGIN_DIR=") + env : std::string("BTF_PLUGIN_DIR unset");
  std::string tried;
  for (const fs::path& dir : btf::PluginSearchDirs(nullptr)) {
    tried += (tried.empty() ? "" : ", ") + dir.string();
    const fs::path file = dir / BTF_TOOL_MODULE_FILE;
    std::error_code ec;
    if (!fs::is_regular_file(file, ec)) continue;
    // RTLD_GLOBAL: Open MPI loads its own components with dlopen(), and they need libmpi's
    // symbols in the global scope, where they are when libmpi is loaded with the program.
    // Never closed: the process ends in it.
    void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_GLOBAL);
    const auto entry = handle ? reinterpret_cast<BtfToolEntry>(dlsym(handle, BTF_TOOL_ENTRY)) : nullptr;
    if (!entry) {
      const char* why = dlerror();
      return Fail("cannot load its module " + file.string() + ": " + (why ? why : "unknown error") + " (" + env_text +
                  "); reinstall libbtf, or set BTF_PLUGIN_DIR to the folder holding the module of this libbtf");
    }
    return entry(argc, argv);
  }
  return Fail(std::string("its module ") + BTF_TOOL_MODULE_FILE + " is in none of these folders: " +
              (tried.empty() ? "(none)" : tried) + " (" + env_text +
              "); it is built and installed with the tool (cmake --install puts it in <prefix>/<libdir>/libbtf): "
              "set BTF_PLUGIN_DIR to the folder holding it");
}
