#pragma once
// Helpers shared by the test suites.
#include <filesystem>
#include <functional>
#include <string>

#include <gtest/gtest.h>

#include "libbtf/core/dataset.h"
#include "libbtf/core/error.h"

namespace btf::test {

// A fresh empty directory for the current test (removed at process exit is not needed: under /tmp).
std::filesystem::path TempDir();

// Runs a command line through the shell; returns the exit code, stdout in *out (if non-null).
int RunCommand(const std::string& command, std::string* out = nullptr);

// The whole content of a file ("" if it cannot be read).
std::string Slurp(const std::filesystem::path& path);

// Path of a built tool, e.g. Tool("btf-info").
std::string Tool(const std::string& name);
// The source tree (sample_data/, viewer/, tests/golden/).
std::string SourceDir();

// The message of the btf::Error that f throws ("" if it throws none); its exit code in *code.
inline std::string ErrorOf(const std::function<void()>& f, ExitCode* code = nullptr) {
  try {
    f();
  } catch (const Error& e) {
    if (code) *code = e.code();
    return e.what();
  }
  return "";
}

// The message of the bad-input error f throws; a test failure when f throws none or another kind.
inline std::string BadInputOf(const std::function<void()>& f) {
  ExitCode code = ExitCode::kOk;
  const std::string message = ErrorOf(f, &code);
  EXPECT_EQ(code, ExitCode::kBadInput) << (message.empty() ? "no error" : message);
  return message;
}

// A small deterministic dataset with distinct values per (v, l, y, x, c).
Dataset MakeTestDataset(int views, int lights, int height, int width, int channels = 3);

}  // namespace btf::test
