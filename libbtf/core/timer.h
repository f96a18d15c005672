#pragma once
// Wall-clock timing of summaries (XxxSummary::times).
#include <chrono>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace btf {

class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()) {}
  double Seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  void Restart() { start_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point start_;
};

// Wall-clock seconds per named phase, in the order the phases ran (for XxxSummary).
class PhaseTimes {
 public:
  void Add(const std::string& phase, double seconds) {
    for (auto& [name, s] : phases_)
      if (name == phase) {
        s += seconds;
        return;
      }
    phases_.emplace_back(phase, seconds);
  }
  double Total() const {
    double t = 0;
    for (const auto& p : phases_) t += p.second;
    return t;
  }
  const std::vector<std::pair<std::string, double>>& phases() const { return phases_; }
  // The one timing schema of every summary and --json document: {"phase": s, ..., "total": s},
  // stored under the key "seconds" (docs/architecture.md, "JSON output").
  nlohmann::json ToJson() const {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& [name, s] : phases_) j[name] = s;
    j["total"] = Total();
    return j;
  }
  // "phase 1.23 s, ..., total 4.56 s" for text reports.
  std::string Report() const;

 private:
  std::vector<std::pair<std::string, double>> phases_;
};

inline std::string PhaseTimes::Report() const {
  std::string t;
  for (const auto& [name, s] : phases_) t += fmt::format("{} {:.2f} s, ", name, s);
  return t + fmt::format("total {:.2f} s", Total());
}

}  // namespace btf
