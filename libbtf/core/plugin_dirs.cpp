#include "libbtf/core/plugin_dirs.h"

#include <dlfcn.h>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <system_error>

// Where the modules sit relative to the folder of a program or library holding libbtf's code
// (':'-separated), and the install prefix's module folder: set by libbtf/CMakeLists.txt from the
// install layout, which the build tree mirrors for its programs (build/bin -> build/lib/libbtf).
#ifndef BTF_PLUGIN_RELATIVE_DIRS
#define BTF_PLUGIN_RELATIVE_DIRS "../lib/libbtf"
#endif
#ifndef BTF_PLUGIN_INSTALL_DIR
#define BTF_PLUGIN_INSTALL_DIR ""
#endif

namespace btf {
namespace {

namespace fs = std::filesystem;

void AddDir(std::vector<fs::path>& dirs, const fs::path& dir) {
  if (dir.empty()) return;
  std::error_code ec;
  fs::path canonical = fs::weakly_canonical(dir, ec);
  if (ec) canonical = dir.lexically_normal();
  for (const fs::path& d : dirs)
    if (d == canonical) return;
  dirs.push_back(canonical);
}

}  // namespace

std::vector<fs::path> PluginSearchDirs(const void* code) {
  std::vector<fs::path> dirs;
  if (const char* env = std::getenv("BTF_PLUGIN_DIR"); env && *env) {
    AddDir(dirs, env);
    return dirs;
  }
  std::vector<fs::path> bases;
  Dl_info info{};
  // dladdr names the main program by its argv[0], which may be a bare name found on PATH:
  // only a name with a folder is used; /proc/self/exe covers the program.
  if (code && dladdr(code, &info) != 0 && info.dli_fname && std::string(info.dli_fname).find('/') != std::string::npos)
    bases.push_back(fs::path(info.dli_fname).parent_path());
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) bases.push_back(exe.parent_path());
  const std::string relative = BTF_PLUGIN_RELATIVE_DIRS;
  for (const fs::path& base : bases) {
    for (std::size_t begin = 0; begin <= relative.size();) {
      const std::size_t end = std::min(relative.find(':', begin), relative.size());
      if (end > begin) AddDir(dirs, base / relative.substr(begin, end - begin));
      begin = end + 1;
    }
  }
  AddDir(dirs, BTF_PLUGIN_INSTALL_DIR);
  return dirs;
}

}  // namespace btf
