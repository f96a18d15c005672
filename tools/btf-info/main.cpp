// btf-info FILE: summary of a libbtf dataset or codec file, or a Bonn .btf file (docs/btf-info.md).
#include <fmt/format.h>

#include "libbtf/compress/codec_source.h"
#include "tools/common/cli.h"

namespace {

void PrintHuman(const nlohmann::json& j) {
  fmt::print("{}\n", j["path"].get<std::string>());
  for (const auto& [key, value] : j.items()) {
    if (key == "path" || key == "provenance") continue;
    if (key.ends_with("_sampling"))
      fmt::print("  {:<22} {} ({} directions)\n", key, value["name"].get<std::string>(), value["count"].get<int>());
    else
      fmt::print("  {:<22} {}\n", key, value.dump());
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Print the summary of a libbtf dataset or codec file, or a Bonn .btf file: shape, samplings, conventions, size on disk, "
               "value range and NaN count.",
               "btf-info"};
  btf::cli::Configure(app);
  btf::cli::CommonFlags common;
  std::string path;
  bool no_stats = false;
  app.add_option("FILE", path, "Dataset (.h5), codec file or Bonn .btf file")->required();
  app.add_flag("--no-stats", no_stats, "Skip the value scan (min/max/NaN count), which reads every value");
  btf::cli::AddCommonFlags(app, common);
  return btf::cli::Main(argc, argv, app, [&] {
    const btf::Reporter reporter = btf::cli::MakeReporter(common);
    const nlohmann::json j = btf::DescribeFile(path, !no_stats, reporter);
    if (common.json)
      btf::cli::PrintJson(app, j);
    else
      PrintHuman(j);
    return 0;
  });
}
