#include "tests/test_util.h"

#include "tests/fault_shim.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <fstream>

namespace btf::test {

std::filesystem::path TempDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "btf";
  for (auto& ch : name)
    if (ch == '/') ch = '_';
  const auto dir = std::filesystem::temp_directory_path() / ("libbtf-test-" + std::to_string(::getpid())) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

std::string Slurp(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

int RunCommand(const std::string& command, std::string* out) {
  FILE* p = ::popen(command.c_str(), "r");
  if (!p) return -1;
  std::array<char, 4096> buf{};
  std::string text;
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) text.append(buf.data(), n);
  const int status = ::pclose(p);
  if (out) *out = text;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

std::string Tool(const std::string& name) { return std::string(BTF_TOOLS_DIR) + "/" + name; }

std::string SourceDir() { return BTF_SOURCE_DIR; }

std::string FaultShim() { return BTF_FAULT_SHIM; }

Dataset MakeTestDataset(int views, int lights, int height, int width, int channels) {
  const Sampling all = Sampling::Bonn81();
  std::vector<int> vi, li;
  for (int i = 0; i < views; ++i) vi.push_back(i % all.size());
  for (int i = 0; i < lights; ++i) li.push_back((i * 7) % all.size());
  Dataset d(all.Subset(vi), all.Subset(li), height, width, channels);
  for (int v = 0; v < views; ++v)
    for (int l = 0; l < lights; ++l)
      for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
          for (int c = 0; c < channels; ++c)
            d.at(v, l, y, x, c) = float(v) + 0.01f * float(l) + 1e-3f * float(y) + 1e-5f * float(x) + 0.3f * float(c);
  return d;
}

}  // namespace btf::test
