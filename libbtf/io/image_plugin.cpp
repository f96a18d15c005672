#include "libbtf/io/image_plugin.h"

#include <dlfcn.h>

#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/core/plugin_dirs.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

const ImagePlugin* Load() {
  // Relative to the file holding this code (a program or the Python module linking the static
  // archives, or libbtf_io.so) and to the running program (core/plugin_dirs.h).
  const std::vector<fs::path> dirs = PluginSearchDirs(reinterpret_cast<const void*>(&LoadImagePlugin));
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
