#include "tools/common/cli.h"

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <iostream>
#include <mutex>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"

namespace btf::cli {

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
      std::fprintf(stderr, "\r%-24.24s [%.*s%*s] %3d%% %zu/%zu  %5.1fs  eta %5.1fs", stage_.c_str(), filled,
                   "##############################", width - filled, "", percent, done, total, elapsed, eta);
      if (done == total) std::fputc('\n', stderr), stage_.clear();
      std::fflush(stderr);
    } else if (percent / 10 != last_percent_ / 10 || done == total) {
      // Plain lines: one per 10 % step, so logs stay readable.
      last_percent_ = percent;
      std::fprintf(stderr, "[%zu/%zu] %s\n", done, total, stage_.c_str());
    }
    return true;
  }

 private:
  bool quiet_, tty_;
  std::mutex mu_;
  std::string stage_;
  int last_percent_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

}  // namespace

Reporter MakeReporter(const CommonFlags& flags) {
  // --quiet keeps warnings and errors only; --verbose adds debug lines.
  spdlog::set_level(flags.quiet ? spdlog::level::warn : flags.verbose ? spdlog::level::debug : spdlog::level::info);
  auto display = std::make_shared<ProgressDisplay>(flags.quiet);
  return Reporter(
      [](LogLevel level, std::string_view msg) {
        switch (level) {
          case LogLevel::kDebug: spdlog::debug("{}", msg); break;
          case LogLevel::kInfo: spdlog::info("{}", msg); break;
          case LogLevel::kWarning: spdlog::warn("{}", msg); break;
        }
      },
      [display](std::size_t done, std::size_t total, std::string_view stage) {
        return display->Update(done, total, stage);
      });
}

void PrintJson(const nlohmann::json& j) { std::cout << j.dump(2) << std::endl; }

int Main(int argc, char** argv, CLI::App& app, const std::function<int()>& run) {
  InstallSignalCleanup();
  auto logger = spdlog::stderr_color_mt("btf");
  logger->set_pattern(std::string(app.get_name()) + ": %^%l%$: %v");
  spdlog::set_default_logger(logger);
  try {
    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      const int rc = app.exit(e);  // prints help or the parse error
      return rc == 0 ? 0 : static_cast<int>(ExitCode::kUsage);
    }
    return run();
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", app.get_name().c_str(), e.what());
    return static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: error: out of memory; use a smaller input or subset\n", app.get_name().c_str());
    return static_cast<int>(ExitCode::kIo);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: internal error: %s (please report this)\n", app.get_name().c_str(), e.what());
    return static_cast<int>(ExitCode::kInternal);
  }
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
