#pragma once
// The numerical stability suite (docs/btf-eval.md, "stability"): stiff and extreme inputs run
// through the real synth, compress, metric and render code. Each case passes or fails on a stated
// criterion and reports the figure it measured.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"

namespace btf {

struct StabilityCase {
  std::string name;       // e.g. "grazing/irawan2006"
  std::string stage;      // "synth", "compress", "metrics", "render", "directions"
  std::string criterion;  // what must hold
  bool passed = false;
  std::string figure;     // what was measured, in words and numbers
  double seconds = 0;
};

struct StabilityOptions {
  // Run only cases whose name starts with one of these prefixes (empty = all).
  std::vector<std::string> only;
  void Check() const;
};

struct StabilitySummary {
  std::vector<StabilityCase> cases;
  int passed = 0, failed = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;  // one block per case, then the counts
};

// Runs the suite. A case that throws where it must not is a failed case (the message is its
// figure), never an escaped exception; Cancelled is passed through.
StabilitySummary RunStability(const StabilityOptions& options = {}, const Reporter& reporter = {});

// The case names, in run order.
std::vector<std::string> StabilityCaseNames();

}  // namespace btf
