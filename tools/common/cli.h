#pragma once
// Shared plumbing for the libbtf command-line tools: common flags, logging to stderr, a
// TTY-aware progress display, JSON on stdout, and one top-level error handler that maps
// btf::Error to the documented exit codes (docs/errors.md).
#include <cstdio>
#include <functional>
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/progress.h"
#include "libbtf/io/dataset_io.h"
#include "tools/common/tool_main.h"

namespace btf::cli {

struct CommonFlags {
  bool json = false;   // machine-readable summary on stdout
  bool quiet = false;  // no progress and no info logs (warnings and errors still go to stderr)
  bool verbose = false;
};

// Call right after constructing a tool's app, before declaring options: --version, and every
// option's default captured from the options struct it binds (so --help and the JSON show it).
void Configure(CLI::App& app);

// Dataset reading as the environment asks: BTF_RAW_CHUNKS=0 reads through H5Dread instead of
// the raw chunks (DatasetReadOptions::raw_chunks; A/B timings). The library reads no variable.
DatasetReadOptions DatasetReadOptionsFromEnvironment();

void AddCommonFlags(CLI::App& app, CommonFlags& flags);

// Reporter that logs to stderr and shows progress: a redrawn bar on a terminal, plain
// "[i/N] stage" lines otherwise; silent with --quiet.
Reporter MakeReporter(const CommonFlags& flags);

// The options as the tool applied them: every option of the app and of the subcommands that ran
// (given or default), keyed by long name without dashes (positionals by name, lower case);
// subcommands nest under their name. Common flags (--json, --quiet, ...) are left out.
nlohmann::json EffectiveOptions(const CLI::App& app);

// Marks a command (a subcommand, or the app itself) as one that splits its work over MPI ranks
// (docs/scaling.md). Started under an MPI launcher with more than one rank, any other command
// refuses to run: N copies of a single-process command would each do all the work and race on
// its outputs.
void MarkDistributed(CLI::App* command);
// For a marked command whose work splits only in some modes (btf-compress: --method pca-view and
// lpca, not fmf): refuses, as an unmarked command would, to run `what` on more than one rank.
void RequireSingleRank(const std::string& what);

// Prints one --json document on stdout: {"tool", "version", "schema_version", "options",
// "ranks", "per_rank"} followed by the summary's keys (docs/architecture.md, "JSON output");
// "per_rank" lists each rank's seconds and peak memory (one entry outside a distributed run). In
// a distributed run it is collective: every rank calls it, rank 0 prints.
void PrintJson(const CLI::App& app, const nlohmann::json& summary);

// The document PrintJson prints.
nlohmann::json JsonDocument(const CLI::App& app, const nlohmann::json& summary);

// Runs a tool: `setup` declares options and subcommands on the app; after parsing, `run` does
// the work and returns the exit code. Errors are printed as "<tool>: error: <message>" and
// mapped to exit codes; CLI parse errors give 2 (0 for --help).
int Main(int argc, char** argv, CLI::App& app, const std::function<int()>& run);

// Parses "1,2,5-7" into indices.
std::vector<int> ParseIndexList(const std::string& text, const std::string& option);

// True on the rank that prints results (rank 0; the only rank outside a distributed run).
bool PrintingRank();

// Prints a summary: its text report, or with --json the JSON document (collective, as PrintJson).
template <typename Summary>
void PrintSummary(const CLI::App& app, const CommonFlags& flags, const Summary& summary,
                  const nlohmann::json& extra = nlohmann::json::object()) {
  if (flags.json) {
    nlohmann::json j = summary.ToJson();
    j.update(extra);
    PrintJson(app, j);
  } else if (PrintingRank()) {
    std::fputs(summary.Report().c_str(), stdout);
  }
}

}  // namespace btf::cli
