#include "libbtf/io/image_plugin.h"

#include <dlfcn.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "libbtf/core/error.h"

// Where the plugin sits relative to the folder of a program or library holding libbtf's code
// (':'-separated), and the install prefix's plugin folder: set by libbtf/CMakeLists.txt from the
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

// The folders to look in, in order: $BTF_PLUGIN_DIR alone when set; else, for the file holding
// this code (a program or the Python module linking the static archives, or libbtf_io.so) and for
// the running program, each relative folder; then the install prefix's.
std::vector<fs::path> SearchDirs() {
  std::vector<fs::path> dirs;
  if (const char* env = std::getenv("BTF_PLUGIN_DIR"); env && *env) {
    AddDir(dirs, env);
    return dirs;
  }
  std::vector<fs::path> bases;
  Dl_info info{};
  // dladdr names the main program by its argv[0], which may be a bare name found on PATH:
  // only a name with a folder is used; /proc/self/exe covers the program.
  if (dladdr(reinterpret_cast<void*>(&LoadImagePlugin), &info) != 0 && info.dli_fname &&
      std::string(info.dli_fname).find('/') != std::string::npos)
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

const ImagePlugin* Load() {
  const std::vector<fs::path> dirs = SearchDirs();
  std::string tried;
  for (const fs::path& dir : dirs) {
    const fs::path file = dir / kImagePluginFile;
    tried += (tried.empty() ? "" : ", ") + dir.string();
    std::error_code ec;
    if (!fs::is_regular_file(file, ec)) continue;
    // RTLD_LOCAL: OpenImageIO's symbols stay out of the global scope. Never closed.
    void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* why = dlerror();
      ThrowIo("cannot load the image plugin {}: {} (it needs OpenImageIO; Debian: libopenimageio2.4)", file.string(),
              why ? why : "unknown error");
    }
    auto entry = reinterpret_cast<ImagePluginEntry>(dlsym(handle, kImagePluginEntry));
    const ImagePlugin* plugin = entry ? entry(kImagePluginAbi) : nullptr;
    if (!plugin)
      ThrowIo("the image plugin {} is not the one of this libbtf (interface version {}): reinstall libbtf",
              file.string(), kImagePluginAbi);
    return plugin;
  }
  ThrowIo("reading or writing images needs libbtf's image plugin {}, which is in none of these folders: {}; it is "
          "built and installed with libbtf (cmake --install puts it in <prefix>/<libdir>/libbtf): set BTF_PLUGIN_DIR "
          "to the folder holding it",
          kImagePluginFile, tried.empty() ? "(none)" : tried);
}

}  // namespace

const ImagePlugin& LoadImagePlugin() {
  static const ImagePlugin* const plugin = Load();  // a throw leaves it unset: the next call tries again
  return *plugin;
}

}  // namespace btf
