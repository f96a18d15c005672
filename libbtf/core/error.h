#pragma once
// One error type for everything a user can cause (bad input, bad options, failed I/O).
// Programming errors are not reported this way; they are assertions.
#include <stdexcept>
#include <string>
#include <string_view>

#include <fmt/format.h>

namespace btf {

// Process exit codes shared by every tool (docs/errors.md).
enum class ExitCode : int {
  kOk = 0,
  kFailedCheck = 1,  // ran, but a requested check or threshold failed
  kUsage = 2,        // bad command line or option value
  kBadInput = 3,     // an input file or value is malformed, inconsistent or unsupported
  kIo = 4,           // a file could not be read or written
  kInternal = 5,     // a bug in libbtf: please report it
  kInterrupted = 130,
};

class Error : public std::runtime_error {
 public:
  Error(ExitCode code, std::string message) : std::runtime_error(std::move(message)), code_(code) {}
  ExitCode code() const { return code_; }

 private:
  ExitCode code_;
};

// Raised when a progress callback asks to stop.
class Cancelled : public Error {
 public:
  Cancelled() : Error(ExitCode::kInterrupted, "cancelled") {}
};

template <typename... Args>
[[noreturn]] void ThrowBadInput(fmt::format_string<Args...> f, Args&&... args) {
  throw Error(ExitCode::kBadInput, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
[[noreturn]] void ThrowIo(fmt::format_string<Args...> f, Args&&... args) {
  throw Error(ExitCode::kIo, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
[[noreturn]] void ThrowUsage(fmt::format_string<Args...> f, Args&&... args) {
  throw Error(ExitCode::kUsage, fmt::format(f, std::forward<Args>(args)...));
}

// Programming errors (a broken invariant of libbtf, never something a user can cause): throws
// btf::Error with ExitCode::kInternal naming the condition and the source line, so the tool's
// handler reports "internal error ... please report this" and atomic outputs are cleaned up.
#define BTF_CHECK(cond)                                                                          \
  do {                                                                                           \
    if (!(cond))                                                                                 \
      throw ::btf::Error(::btf::ExitCode::kInternal,                                             \
                         ::fmt::format("check failed: {} ({}:{})", #cond, __FILE__, __LINE__));  \
  } while (0)

// Option checks: `Check()` methods of XxxOptions call this so the message names the field and
// says what it must be (in words: the C++ condition is not for users).
#define BTF_CHECK_OPTION(cond, field, msg)                                                                 \
  do {                                                                                                      \
    if (!(cond)) ::btf::ThrowUsage("invalid option '{}': {}{}", field, ::btf::MustBePrefix(msg), msg); \
  } while (0)

// "must be " where an option message is a bare range or bound (">= 0", "1..16"), else "".
inline const char* MustBePrefix(std::string_view msg) {
  return !msg.empty() && std::string_view("<>=|(0123456789").find(msg[0]) != std::string_view::npos ? "must be " : "";
}

}  // namespace btf
