#pragma once
// Shared plumbing for the libbtf command-line tools: common flags, logging to stderr, a
// TTY-aware progress display, JSON on stdout, and one top-level error handler that maps
// btf::Error to the documented exit codes (docs/errors.md).
#include <functional>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"

namespace btf::cli {

struct CommonFlags {
  bool json = false;   // machine-readable summary on stdout
  bool quiet = false;  // no progress and no info logs (warnings and errors still go to stderr)
  bool verbose = false;
};

void AddCommonFlags(CLI::App& app, CommonFlags& flags);

// Reporter that logs to stderr and shows progress: a redrawn bar on a terminal, plain
// "[i/N] stage" lines otherwise; silent with --quiet.
Reporter MakeReporter(const CommonFlags& flags);

// Prints one JSON document on stdout.
void PrintJson(const nlohmann::json& j);

// Runs a tool: `setup` declares options and subcommands on the app; after parsing, `run` does
// the work and returns the exit code. Errors are printed as "<tool>: error: <message>" and
// mapped to exit codes; CLI parse errors give 2 (0 for --help).
int Main(int argc, char** argv, CLI::App& app, const std::function<int()>& run);

// Parses "1,2,5-7" into indices.
std::vector<int> ParseIndexList(const std::string& text, const std::string& option);

}  // namespace btf::cli
