#include "tools/common/cli.h"

#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <mutex>
#include <set>
#include <sstream>
#include <vector>

#include <fmt/ranges.h>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/eigen_setup.h"
#include "libbtf/core/error.h"
#include "libbtf/io/hdf5.h"
#include "libbtf/core/version.h"

namespace btf::cli {

void Configure(CLI::App& app) {
  FixEigenBlocking();
  app.set_version_flag("--version", fmt::format("{} {}", app.get_name(), Version()),
                       "Print the libbtf version and exit");
  app.option_defaults()->always_capture_default();
}

void AddCommonFlags(CLI::App& app, CommonFlags& flags) {
  app.add_flag("--json", flags.json, "Print a JSON summary on stdout (logs stay on stderr)");
  app.add_flag("-q,--quiet", flags.quiet, "No progress or info messages; warnings and errors only");
  app.add_flag("-v,--verbose", flags.verbose, "Also print debug messages");
}

namespace {

class ProgressDisplay {
 public:
  explicit ProgressDisplay(bool quiet) : quiet_(quiet), tty_(::isatty(STDERR_FILENO) == 1) {}

  bool Update(std::size_t done, std::size_t total, std::string_view stage) {
    if (quiet_ || total == 0) return true;
    std::lock_guard lock(mu_);
    const auto now = std::chrono::steady_clock::now();
    const bool new_stage = stage != stage_;
    if (new_stage) {
      if (tty_ && !stage_.empty()) std::fputc('\n', stderr);
      stage_ = std::string(stage);
      last_percent_ = -1;
      start_ = now;
    }
    const int percent = static_cast<int>(100.0 * done / total);
    if (tty_) {
      // Redraw at most 10 times a second, and always at the end.
      if (!new_stage && done < total && now - last_draw_ < std::chrono::milliseconds(100)) return true;
      last_draw_ = now;
      const int width = 30, filled = static_cast<int>(width * done / total);
      const double elapsed = std::chrono::duration<double>(now - start_).count();
      const double eta = done > 0 ? elapsed * (double(total) / done - 1) : 0;
      line_ = fmt::format("{:<24.24} [{:#<{}}{:{}}] {:3d}% {}/{}  {:5.1f}s  eta {:5.1f}s", stage_, "", filled, "",
                          width - filled, percent, done, total, elapsed, eta);
      std::fprintf(stderr, "\r%s", line_.c_str());
      if (done == total) std::fputc('\n', stderr), stage_.clear(), line_.clear();
      std::fflush(stderr);
    } else if (percent / 10 != last_percent_ / 10 || done == total) {
      // Plain lines: one per 10 % step, so logs stay readable.
      last_percent_ = percent;
      std::fprintf(stderr, "[%zu/%zu] %s\n", done, total, stage_.c_str());
    }
    return true;
  }

  // A log line while a bar is drawn on a terminal: the bar's line is cleared, the message written
  // on its own line, and the bar drawn again below it, so the two never share a line.
  template <typename F>
  void Log(F&& write) {
    std::lock_guard lock(mu_);
    const bool bar = tty_ && !line_.empty();
    if (bar) std::fputs("\r\033[K", stderr), std::fflush(stderr);
    write();
    if (bar) std::fprintf(stderr, "\r%s", line_.c_str()), std::fflush(stderr);
  }

 private:
  bool quiet_, tty_;
  std::mutex mu_;
  std::string stage_, line_;  // the current stage; the bar as last drawn (a terminal, until it ends)
  int last_percent_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

}  // namespace

DatasetReadOptions DatasetReadOptionsFromEnvironment() {
  DatasetReadOptions o;
  const char* env = std::getenv("BTF_RAW_CHUNKS");
  o.raw_chunks = !(env && std::string(env) == "0");
  return o;
}

Reporter MakeReporter(const CommonFlags& flags) {
  // --quiet keeps warnings and errors only; --verbose adds debug lines. In a distributed run only
  // rank 0 shows progress and info lines; every rank's warnings are shown, tagged with the rank.
  const bool quiet = flags.quiet || !PrintingRank();
  spdlog::set_level(quiet ? spdlog::level::warn : flags.verbose ? spdlog::level::debug : spdlog::level::info);
  auto display = std::make_shared<ProgressDisplay>(quiet);
  return Reporter(
      [display](LogLevel level, std::string_view msg) {
        display->Log([&] {
          switch (level) {
            case LogLevel::kDebug: spdlog::debug("{}", msg); break;
            case LogLevel::kInfo: spdlog::info("{}", msg); break;
            case LogLevel::kWarning: spdlog::warn("{}", msg); break;
          }
          spdlog::default_logger()->flush();
        });
      },
      [display](std::size_t done, std::size_t total, std::string_view stage) {
        return display->Update(done, total, stage);
      });
}

namespace {

bool IsCommonFlag(const std::string& name) {
  return name == "help" || name == "version" || name == "json" || name == "quiet" || name == "verbose";
}

// A CLI11 value (given or default) as JSON: numbers, booleans and lists typed, the rest strings.
nlohmann::json ValueJson(const std::string& text) {
  if (text == "true" || text == "false") return text == "true";
  if (!text.empty()) {
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (end && *end == '\0') {
      if (text.find_first_of(".eEn") == std::string::npos && std::abs(v) < 9e15) return static_cast<std::int64_t>(v);
      return v;
    }
  }
  if (text.size() >= 2 && text.front() == '[' && text.back() == ']') {
    nlohmann::json a = nlohmann::json::array();
    std::size_t pos = 1;
    while (pos < text.size() - 1) {
      const std::size_t comma = std::min(text.find(',', pos), text.size() - 1);
      a.push_back(ValueJson(text.substr(pos, comma - pos)));
      pos = comma + 1;
    }
    return a;
  }
  return text;
}

std::string OptionKey(const CLI::Option& o) {
  std::string name = !o.get_lnames().empty() ? o.get_lnames().front()
                     : !o.get_snames().empty() ? o.get_snames().front() : o.get_name();
  for (auto& c : name) c = c == '-' ? '_' : static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

}  // namespace

nlohmann::json EffectiveOptions(const CLI::App& app) {
  nlohmann::json j = nlohmann::json::object();
  for (const CLI::Option* o : app.get_options()) {
    const std::string key = OptionKey(*o);
    if (IsCommonFlag(key)) continue;
    if (o->get_expected_max() == 0) {  // a flag
      j[key] = o->count() > 0;
      continue;
    }
    if (o->count() > 0) {
      const auto& r = o->results();
      if (r.size() == 1 && o->get_expected_max() <= 1) {
        j[key] = ValueJson(r.front());
      } else {
        nlohmann::json a = nlohmann::json::array();
        for (const auto& v : r) a.push_back(ValueJson(v));
        j[key] = a;
      }
    } else {
      j[key] = o->get_default_str().empty() ? nlohmann::json(nullptr) : ValueJson(o->get_default_str());
    }
  }
  for (const CLI::App* sub : app.get_subcommands())
    if (sub->parsed()) j[sub->get_name()] = EffectiveOptions(*sub);
  return j;
}

nlohmann::json JsonDocument(const CLI::App& app, const nlohmann::json& summary) {
  nlohmann::json j = {{"tool", app.get_name()},
                      {"version", Version()},
                      {"schema_version", kJsonSchemaVersion},
                      {"options", EffectiveOptions(app)},
                      {"ranks", dist::Size()}};
  for (const auto& [k, v] : summary.items()) j[k] = v;
  return j;
}

namespace {
std::set<const CLI::App*>& DistributedCommands() {
  static std::set<const CLI::App*> commands;
  return commands;
}
std::chrono::steady_clock::time_point g_start = std::chrono::steady_clock::now();

// Refuses a command that does not split its work when more than one rank runs it.
void CheckDistributable(const CLI::App& app) {
  if (!dist::Distributed()) return;
  const CLI::App* command = &app;
  while (!command->get_subcommands().empty()) command = command->get_subcommands().front();
  for (const CLI::App* c = command; c; c = c->get_parent())
    if (DistributedCommands().count(c)) return;
  ThrowUsage("'{}' does not run distributed, but {} MPI ranks started it: run it without mpirun (docs/scaling.md "
             "lists the distributed commands)",
             command == &app ? app.get_name() : app.get_name() + " " + command->get_name(), dist::Size());
}

// In a distributed run every message names the rank that reports it.
std::string RankTag() {
  return dist::Distributed() ? fmt::format("rank {} of {}: ", dist::Rank(), dist::Size()) : std::string();
}
}  // namespace

void MarkDistributed(CLI::App* command) { DistributedCommands().insert(command); }

void RequireSingleRank(const std::string& what) {
  if (dist::Distributed())
    ThrowUsage("'{}' does not run distributed, but {} MPI ranks started it: run it without mpirun (docs/scaling.md "
               "lists the distributed commands)",
               what, dist::Size());
}

bool PrintingRank() { return dist::Rank() == 0; }

void PrintJson(const CLI::App& app, const nlohmann::json& summary) {
  nlohmann::json doc = JsonDocument(app, summary);
  doc["per_rank"] = dist::GatherRankStats(std::chrono::duration<double>(std::chrono::steady_clock::now() - g_start).count());
  if (PrintingRank()) std::cout << doc.dump(2) << std::endl;
}

namespace {
// "<tool>: error: [rank r of N: ]message" on stderr.
void PrintError(const CLI::App& app, const char* kind, const std::string& message) {
  std::fprintf(stderr, "%s: %s: %s%s\n", app.get_name().c_str(), kind, RankTag().c_str(), message.c_str());
}

// Edit distance (insertions, deletions, substitutions) between a and b.
std::size_t EditDistance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] != b[j - 1])});
      diagonal = up;
    }
  }
  return row[b.size()];
}

// The option names (`--long`, `-s`) of an app and its subcommands, and the subcommand names.
void CollectNames(const CLI::App& app, std::vector<std::string>& options, std::vector<std::string>& commands) {
  for (const CLI::Option* o : app.get_options()) {
    for (const std::string& n : o->get_lnames()) options.push_back("--" + n);
    for (const std::string& n : o->get_snames()) options.push_back("-" + n);
  }
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) {
    commands.push_back(sub->get_name());
    CollectNames(*sub, options, commands);
  }
}

// " (did you mean 'X'?)" for the nearest name within a third of the word's length, else "".
std::string Nearest(const std::string& word, const std::vector<std::string>& names) {
  std::string best;
  std::size_t best_d = std::max<std::size_t>(2, word.size() / 3) + 1;
  for (const std::string& n : names)
    if (const std::size_t d = EditDistance(word, n); d < best_d) best = n, best_d = d;
  return best.empty() ? "" : fmt::format(" (did you mean '{}'?)", best);
}

// CLI11's parse errors in docs/errors.md's style: what is wrong, the nearest valid name, where to
// look.
std::string ParseErrorMessage(const CLI::App& app, const CLI::ParseError& e, int argc, char** argv) {
  std::vector<std::string> options, commands;
  CollectNames(app, options, commands);
  std::string what = e.what();
  // An option and its value quoted together ("--log-epsilon 1" as one argument, as a script's
  // variable gives them): CLI11 reads one unknown option and reports its words apart.
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const std::size_t space = arg.find_first_of(" \t");
    if (arg.rfind('-', 0) != 0 || space == std::string::npos) continue;
    const std::string name = arg.substr(0, space), value = arg.substr(space + 1);
    if (std::find(options.begin(), options.end(), name) != options.end())
      return fmt::format("'{}' is one argument: give the option and its value as two ({} {}) or as {}={}; see {} --help",
                         arg, name, value, name, value, app.get_name());
  }
  if (dynamic_cast<const CLI::ExtrasError*>(&e)) {
    const std::size_t colon = what.find(": ");
    std::vector<std::string> unknown, positional;
    std::istringstream words(colon == std::string::npos ? what : what.substr(colon + 2));
    for (std::string w; words >> w;) (w.rfind('-', 0) == 0 ? unknown : positional).push_back(w);
    // With an unknown option, the extra words are most likely its values: the option is the error.
    std::string message;
    for (const std::string& w : unknown.empty() ? positional : unknown) {
      const bool option = w.rfind('-', 0) == 0;
      const std::string name = option ? w.substr(0, w.find('=')) : w;
      std::string hint = Nearest(name, option ? options : commands);
      if (hint.empty() && !option && !commands.empty()) hint = fmt::format(" (commands: {})", fmt::join(commands, ", "));
      message += fmt::format("{}unknown {} '{}'{}", message.empty() ? "" : "; ", option ? "option" : "argument", name, hint);
    }
    what = message;
  } else if (what == "A subcommand is required" && !commands.empty()) {
    // The first word that is not an option is what was meant as the command.
    std::string given;
    for (int i = 1; i < argc && given.empty(); ++i)
      if (argv[i][0] != '-') given = argv[i];
    const std::string hint = given.empty() ? "" : Nearest(given, commands);
    what = !given.empty() ? fmt::format("unknown command '{}'{}; one of {}", given, hint, fmt::join(commands, ", "))
                          : fmt::format("a command is required: one of {}", fmt::join(commands, ", "));
  }
  return fmt::format("{}; see {} --help", what, app.get_name());
}

// A tool is one process doing one job, and the memory it frees between view slots it needs again
// for the next. glibc by default gives the top of the heap back to the kernel beyond 128 KiB and
// maps blocks of 128 KiB and more afresh, so each slot's buffers were page-faulted in again: the
// 64^2 twill's per-view PCA took 1.0-1.1 s with 49,000 faults, 0.44 s with 6,100 with these
// settings (page faults are dear on a virtual machine). Blocks of 32 MiB and more are still mapped
// and returned when freed (Bonn-size slots, texel matrices), and at most 64 MiB of free heap is
// kept (peak memory +3 MB on that run). GLIBC_TUNABLES, when set, is left to decide.
void KeepFreedMemory() {
  if (std::getenv("GLIBC_TUNABLES") != nullptr) return;
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 64 << 20);
}

int RunTool(int argc, char** argv, CLI::App& app, const std::function<int()>& run) {
  KeepFreedMemory();
  InstallSignalCleanup();
  auto logger = spdlog::stderr_color_mt("btf");
  try {
    dist::Init(&argc, &argv);
    logger->set_pattern(std::string(app.get_name()) + ": %^%l%$: " + RankTag() + "%v");
    spdlog::set_default_logger(logger);
    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      // Every rank parses the same command line: rank 0 alone prints help or the error.
      if (e.get_exit_code() == 0) return PrintingRank() ? app.exit(e) : 0;  // --help, --version
      if (PrintingRank()) PrintError(app, "error", ParseErrorMessage(app, e, argc, argv));
      return static_cast<int>(ExitCode::kUsage);
    }
    CheckDistributable(app);
    return run();
  } catch (const Error& thrown) {
    // A file read as damaged after a failed read system call is a failing disk, not bad data.
    const Error e = h5::ReportedError(thrown);
    // A usage error is the same on every rank: rank 0 alone prints it.
    if (e.code() != ExitCode::kUsage || PrintingRank())
      PrintError(app, e.code() == ExitCode::kInternal ? "internal error" : "error",
                 e.code() == ExitCode::kInternal ? fmt::format("{} (please report this)", e.what()) : e.what());
    return static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {
    PrintError(app, "error", "out of memory; use a smaller input or subset");
    return static_cast<int>(ExitCode::kIo);
  } catch (const std::exception& e) {
    PrintError(app, "internal error", fmt::format("{} (please report this)", e.what()));
    return static_cast<int>(ExitCode::kInternal);
  }
}
}  // namespace

int Main(int argc, char** argv, CLI::App& app, const std::function<int()>& run) {
  const int rc = RunTool(argc, argv, app, run);
  std::fflush(stdout);
  // A rank that fails ends the whole job (the other ranks may wait for its data); its message,
  // tagged with the rank, is already on stderr. A usage error or a failed threshold is the same
  // on every rank and needs no abort.
  if (dist::Distributed() && rc != 0 && rc != static_cast<int>(ExitCode::kUsage) &&
      rc != static_cast<int>(ExitCode::kFailedCheck))
    dist::AbortJob(rc);
  dist::Finalize();
  return rc;
}

std::vector<int> ParseIndexList(const std::string& text, const std::string& option) {
  std::vector<int> out;
  std::size_t pos = 0;
  while (pos <= text.size()) {
    const std::size_t comma = std::min(text.find(',', pos), text.size());
    const std::string item = text.substr(pos, comma - pos);
    const std::size_t dash = item.find('-', 1);
    try {
      std::size_t used = 0;
      if (dash == std::string::npos) {
        out.push_back(std::stoi(item, &used));
        if (used != item.size()) throw std::invalid_argument(item);
      } else {
        const int a = std::stoi(item.substr(0, dash)), b = std::stoi(item.substr(dash + 1));
        if (b < a) throw std::invalid_argument(item);
        for (int i = a; i <= b; ++i) out.push_back(i);
      }
    } catch (const std::logic_error&) {
      ThrowUsage("{}: '{}' is not an index list like '0,3,5-9'", option, item);
    }
    pos = comma + 1;
  }
  return out;
}

}  // namespace btf::cli
