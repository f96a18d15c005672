#pragma once
// How library code reports: it never prints. Long operations take a Reporter, which forwards log
// lines to a sink and progress to a callback that may cancel the work.
#include <functional>
#include <string>
#include <string_view>

#include <fmt/format.h>

#include "libbtf/core/error.h"

namespace btf {

enum class LogLevel { kDebug, kInfo, kWarning };

// Return false to cancel; the library then throws btf::Cancelled at the next safe point.
using ProgressCallback = std::function<bool(std::size_t done, std::size_t total, std::string_view stage)>;
using LogCallback = std::function<void(LogLevel, std::string_view)>;

class Reporter {
 public:
  Reporter() = default;
  Reporter(LogCallback log, ProgressCallback progress) : log_(std::move(log)), progress_(std::move(progress)) {}

  template <typename... Args>
  void Info(fmt::format_string<Args...> f, Args&&... args) const {
    if (log_) log_(LogLevel::kInfo, fmt::format(f, std::forward<Args>(args)...));
  }
  template <typename... Args>
  void Warn(fmt::format_string<Args...> f, Args&&... args) const {
    if (log_) log_(LogLevel::kWarning, fmt::format(f, std::forward<Args>(args)...));
  }
  // Reports progress; throws Cancelled if the callback asks to stop. Call from one thread only.
  void Progress(std::size_t done, std::size_t total, std::string_view stage) const {
    if (progress_ && !progress_(done, total, stage)) throw Cancelled();
  }

 private:
  LogCallback log_;
  ProgressCallback progress_;
};

}  // namespace btf
