// module: synth
// Fuzzes the `.wv` weave-pattern parser and validator. Whatever it accepts must survive a round
// trip through FormatWeavePattern unchanged (the writer's promise in weave_pattern.h).
#include <string>

#include "libbtf/core/error.h"
#include "libbtf/synth/weave_pattern.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const nlohmann::json kVariables = {{"a", 0.5}, {"kd", {0.1, 0.2, 0.3}}, {"bad", "text"}};
  const std::string text(reinterpret_cast<const char*>(data), size);
  btf::WeavePattern p;
  try {
    p = btf::ParseWeavePattern(text, "fuzz.wv", kVariables);
  } catch (const btf::Error&) {
    return 0;
  }
  const std::string once = btf::FormatWeavePattern(p);
  std::string twice;
  try {
    twice = btf::FormatWeavePattern(btf::ParseWeavePattern(once, "formatted.wv"));
  } catch (const btf::Error&) {
    __builtin_trap();  // the writer produced text its own parser refuses
  }
  if (once != twice) __builtin_trap();
  return 0;
}
