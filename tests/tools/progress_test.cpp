// Progress on a terminal (a pseudo-terminal from script(1)): every LPCA phase shows a bar that ends
// at 100 %, and log lines never share a line with a bar. Off a terminal: plain "[i/N]" lines.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "tests/test_util.h"

namespace btf {
namespace {

// What a terminal shows of each line: the text after the last carriage return or erase-line.
std::vector<std::string> VisibleLines(const std::string& raw) {
  std::vector<std::string> lines;
  std::istringstream in(raw);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line.back() == '\r') line.pop_back();  // the terminal's line end is CR LF
    std::size_t from = 0;
    for (const std::string mark : {std::string("\r"), std::string("\033[K")})
      for (std::size_t at = line.find(mark); at != std::string::npos; at = line.find(mark, at + 1))
        from = std::max(from, at + mark.size());
    lines.push_back(line.substr(std::min(from, line.size())));
  }
  return lines;
}

TEST(Progress, EveryLpcaPhaseEndsItsBarAndLogLinesStandAlone) {
  const auto dir = test::TempDir();
  const std::string in = (dir / "in.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0-8 --lights 0-8 --resolution 16 --samples 1 --quiet -o " + in), 0);
  const std::string command = test::Tool("btf-compress") + " " + in + " --method lpca -k 4 -c 2 -o " + (dir / "c.h5").string();
  std::string raw;
  ASSERT_EQ(test::RunCommand("script -qec '" + command + "' /dev/null", &raw), 0) << raw;
  bool info = false;
  for (const std::string stage : {"read", "k-means", "sample rounds", "lpca"}) {
    bool ended = false;
    for (const std::string& l : VisibleLines(raw)) ended |= l.rfind(stage, 0) == 0 && l.find("100%") != std::string::npos;
    EXPECT_TRUE(ended) << stage << " has no bar at 100 %:\n" << raw;
  }
  for (const std::string& l : VisibleLines(raw)) {
    if (l.find("btf-compress: ") == std::string::npos || l.find("info") == std::string::npos) continue;  // (colored)
    info = true;
    EXPECT_EQ(l.find("%"), std::string::npos) << "a log line shares its line with a bar: " << l;
  }
  EXPECT_TRUE(info) << raw;
  // Off a terminal: plain lines; --quiet: nothing on stderr.
  std::string plain;
  ASSERT_EQ(test::RunCommand(command + " 2>&1 >/dev/null", &plain), 0);
  EXPECT_NE(plain.find("] k-means"), std::string::npos) << plain;
  EXPECT_EQ(plain.find('\r'), std::string::npos);
  std::string quiet;
  ASSERT_EQ(test::RunCommand(command + " --quiet 2>&1 >/dev/null", &quiet), 0);
  EXPECT_EQ(quiet, "");
}

}  // namespace
}  // namespace btf
