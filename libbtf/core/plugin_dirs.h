#pragma once
// Where libbtf looks for the modules it loads with dlopen(): the image plugin libbtf_oiio.so
// (io/image_plugin.h) and the tool modules libbtf_tool_<tool>.so that the btf-register and
// btf-synth launchers load (tools/common/launcher.cpp; docs/architecture.md, "Tool modules").
// Depends on nothing but the C++ and C libraries: the launchers compile it alone.
#include <filesystem>
#include <vector>

namespace btf {

// The folders to look in, in order: $BTF_PLUGIN_DIR alone when it is set and not empty; else,
// for the file holding `code` (dladdr: a program, the Python module or a shared library; null
// for none) and for the running program (/proc/self/exe), each folder where the install layout
// puts the modules relative to it (../lib/libbtf from bin/; the build tree mirrors that layout);
// then the configured install prefix's module folder (<prefix>/<libdir>/libbtf). Each once.
std::vector<std::filesystem::path> PluginSearchDirs(const void* code);

}  // namespace btf
