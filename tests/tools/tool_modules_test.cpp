// The tool modules (docs/architecture.md, "Tool modules"): btf-register and btf-synth are
// launchers that load libbtf_tool_<tool>.so, except in the sanitizer build (plain executables).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "libbtf/core/version.h"
#include "tests/test_util.h"

namespace btf {
namespace {

const char* const kModuleTools[] = {"btf-register", "btf-synth"};

std::string Q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

// A command each tool runs only through its module (btf-synth's would write `out`).
std::string Command(const std::string& tool, const std::filesystem::path& out) {
  return tool == "btf-synth" ? " btf --views 0 --lights 0 --resolution 4 --samples 1 -q -o " + Q(out)
                             : " detect " + Q(out.parent_path() / "photo.png") + " -q";
}

#ifdef BTF_SANITIZER_BUILD
#define SKIP_IN_SANITIZER_BUILD() GTEST_SKIP() << "the sanitizer build has no tool modules"
#else
#define SKIP_IN_SANITIZER_BUILD() (void)0
#endif

TEST(ToolModules, WithoutItsModuleAToolSaysWhereItLookedAndVersionNeedsNone) {
  SKIP_IN_SANITIZER_BUILD();
  const auto dir = test::TempDir();
  std::filesystem::create_directories(dir / "empty");
  for (const std::string tool : kModuleTools) {
    const std::string module = "libbtf_tool_" + tool + ".so";
    const std::string no_module = "BTF_PLUGIN_DIR=" + Q(dir / "empty") + " " + test::Tool(tool);
    std::string out;
    EXPECT_EQ(test::RunCommand(no_module + Command(tool, dir / "out.h5") + " 2>&1", &out), 4) << tool << ": " << out;
    for (const std::string& part : {tool + ": error: ", module, (dir / "empty").string(), std::string("BTF_PLUGIN_DIR")})
      EXPECT_NE(out.find(part), std::string::npos) << out << " / " << part;
    EXPECT_EQ(out.find('\n'), out.size() - 1) << "one line: " << out;
    EXPECT_FALSE(std::filesystem::exists(dir / "out.h5")) << tool;
    // --version is the launcher's own: it needs no module.
    EXPECT_EQ(test::RunCommand(no_module + " --version 2>&1", &out), 0) << tool << ": " << out;
    EXPECT_EQ(out, tool + " " + Version() + "\n");
  }
}

TEST(ToolModules, AModuleThatCannotBeLoadedGivesTheLoadersReason) {
  SKIP_IN_SANITIZER_BUILD();
  const auto dir = test::TempDir();
  for (const std::string tool : kModuleTools) {
    const auto module = dir / ("libbtf_tool_" + tool + ".so");
    std::ofstream(module) << std::string(256, 'x');  // longer than an ELF header, and not one
    std::string out;
    EXPECT_EQ(test::RunCommand("BTF_PLUGIN_DIR=" + Q(dir) + " " + test::Tool(tool) + Command(tool, dir / "out.h5") + " 2>&1", &out), 4)
        << tool << ": " << out;
    // dlerror()'s words for a file that is no ELF object.
    for (const std::string& part : {tool + ": error: cannot load its module " + module.string(),
                                    std::string("invalid ELF header"), std::string("BTF_PLUGIN_DIR=" + dir.string())})
      EXPECT_NE(out.find(part), std::string::npos) << out << " / " << part;
  }
}

TEST(ToolModules, TheLauncherPrintsTheToolsOwnVersionAndLinksNoneOfItsLibraries) {
  SKIP_IN_SANITIZER_BUILD();
  for (const std::string tool : kModuleTools) {
    std::string launcher, module;
    EXPECT_EQ(test::RunCommand(test::Tool(tool) + " --version", &launcher), 0) << tool;
    // Two arguments: the module parses them, and CLI11 prints the version as in every tool.
    EXPECT_EQ(test::RunCommand(test::Tool(tool) + " --version --quiet", &module), 0) << tool;
    EXPECT_EQ(launcher, module) << tool;
    EXPECT_EQ(launcher, tool + " " + Version() + "\n");
    std::string needed;
    ASSERT_EQ(test::RunCommand("readelf -d " + test::Tool(tool) + " | grep NEEDED", &needed), 0) << tool;
    EXPECT_NE(needed.find("libc.so"), std::string::npos) << needed;
    for (const char* library : {"opencv", "libbtf", "mpi", "hdf5", "OpenImageIO", "apriltag", "gomp"})
      EXPECT_EQ(needed.find(library), std::string::npos) << tool << " links " << library << ":\n" << needed;
  }
}

}  // namespace
}  // namespace btf
