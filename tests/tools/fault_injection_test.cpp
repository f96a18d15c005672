// Injected I/O faults (docs/errors.md, "Faults"): every tool that writes is run once per chosen
// fault position with tests/fault_inject.c preloaded, failing the N-th write (ENOSPC), read, fsync
// or rename (EIO) on the test's files. Each faulted run must end with exit 4 and a message that
// names a file, leave the previous output exactly as it was and no temporary behind; in the
// sanitizer build the same runs are also free of ASan/UBSan reports (those exit 1).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include "tests/fault_shim.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

// Every file under `dir` with its bytes: the state a faulted run must leave unchanged.
std::map<std::string, std::string> Snapshot(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    files[fs::relative(e.path(), dir).string()] = e.is_regular_file() ? test::Slurp(e.path()) : "<dir>";
  return files;
}

struct Counts {
  std::map<std::string, long> ops;
  bool injected = false;
};

Counts ReadCounts(const fs::path& p) {
  Counts c;
  std::istringstream in(test::Slurp(p));
  std::string op;
  long n;
  while (in >> op >> n) {
    if (op == "injected")
      c.injected = n != 0;
    else
      c.ops[op] = n;
  }
  return c;
}

// Positions to fail among n calls: the first, the middle and the last (the default run keeps
// to these; BTF_FAULT_POSITIONS=all sweeps every call, which takes minutes per tool).
std::vector<long> Positions(long n) {
  std::set<long> s;
  if (const char* all = std::getenv("BTF_FAULT_POSITIONS"); all && std::string(all) == "all") {
    for (long p = 1; p <= n; ++p) s.insert(p);
  } else {
    for (long p : {1L, (n + 1) / 2, n})
      if (p >= 1 && p <= n) s.insert(p);
  }
  return {s.begin(), s.end()};
}

struct ToolCase {
  std::string name;
  // Commands that make the inputs in IN (each run once, without faults). "{in}" and "{out}" are
  // replaced by the input and output folders.
  std::vector<std::string> setup;
  std::string command;  // writes only under {out}
};

std::string Expand(std::string s, const fs::path& in, const fs::path& out) {
  for (const auto& [k, v] : {std::pair<std::string, std::string>{"{in}", in.string()}, {"{out}", out.string()},
                             {"{src}", test::SourceDir()}})
    for (std::size_t p = s.find(k); p != std::string::npos; p = s.find(k, p + v.size())) s.replace(p, k.size(), v);
  return s;
}

void PrintTo(const ToolCase& c, std::ostream* os) { *os << c.name; }

class FaultInjection : public ::testing::TestWithParam<ToolCase> {};

TEST_P(FaultInjection, EveryFaultExitsFourAndKeepsTheOldOutput) {
  const ToolCase& tc = GetParam();
  const fs::path dir = test::TempDir(), in = dir / "in", out = dir / "out";
  fs::create_directories(in);
  fs::create_directories(out);
  for (const auto& s : tc.setup) ASSERT_EQ(test::RunCommand(Expand(s, in, out) + " >/dev/null 2>&1"), 0) << s;
  const std::string command = Expand(tc.command, in, out) + " --quiet";
  // A first run makes the output that every faulted run must keep; a second one, over it, counts
  // the calls (replacing an output can take other calls than creating one).
  ASSERT_EQ(test::RunCommand(command + " 2>&1"), 0) << command;
  const std::string env = fmt::format(
      "ASAN_OPTIONS=detect_leaks=1:verify_asan_link_order=0 LD_PRELOAD={} BTF_FAULT_DIR={} BTF_FAULT_COUNTS={} ",
      test::FaultShim(), dir.string(), (dir / "counts").string());
  std::string log;
  ASSERT_EQ(test::RunCommand(env + command + " 2>&1", &log), 0) << command << "\n" << log;
  const Counts total = ReadCounts(dir / "counts");
  ASSERT_GT(total.ops.at("write"), 0) << "the shim saw no writes: is it preloaded?";
  ASSERT_GT(total.ops.at("rename"), 0) << "no rename: the output is not written atomically";

  int runs = 0;
  for (const auto& [op, err] : std::vector<std::pair<std::string, std::string>>{
           {"write", "ENOSPC"}, {"read", "EIO"}, {"fsync", "EIO"}, {"rename", "EIO"}}) {
    for (long n : Positions(total.ops.at(op))) {
      const auto before = Snapshot(out);
      const std::string fault = fmt::format("BTF_FAULT={}:{}:{} ", op, n, err);
      const int rc = test::RunCommand(fault + env + command + " 2>&1", &log);
      const Counts c = ReadCounts(dir / "counts");
      const std::string what = fmt::format("{} with the {}th {} failing ({})\n{}", tc.name, n, op, err, log);
      ++runs;
      if (!c.injected) {  // the run took fewer calls of this kind (another code path): not a fault
        EXPECT_EQ(rc, 0) << what;
        continue;
      }
      EXPECT_EQ(rc, 4) << what;
      EXPECT_NE(log.find(dir.string()), std::string::npos) << "the message names no file: " << what;
      const auto after = Snapshot(out);
      EXPECT_EQ(after.size(), before.size()) << what;
      for (const auto& [name, bytes] : after) {
        ASSERT_TRUE(before.count(name)) << "left behind: " << name << "\n" << what;
        EXPECT_TRUE(before.at(name) == bytes) << name << " changed\n" << what;
      }
    }
  }
  RecordProperty("faulted_runs", runs);
}

const std::string kSynth = test::Tool("btf-synth"), kCompress = test::Tool("btf-compress"),
                  kRegister = test::Tool("btf-register"), kEval = test::Tool("btf-eval"),
                  kConvert = test::Tool("btf-convert");
const std::string kSmallBtf = kSynth + " btf --views 0,1,7 --lights 0,3,9 --resolution 8 --samples 1";

INSTANTIATE_TEST_SUITE_P(
    Tools, FaultInjection,
    ::testing::Values(
        ToolCase{"synth_btf", {}, kSmallBtf + " -o {out}/a.h5"},
        ToolCase{"synth_brdf", {}, kSynth + " brdf --views 0-4 --lights 0-4 -o {out}/b.h5"},
        ToolCase{"synth_photos", {},
                 kSynth + " photos --views 0 --lights 0 --width 160 --height 120 --pixel-samples 1 -o {out}/photos"},
        ToolCase{"register_run",
                 {kSynth + " photos --views 0,7 --lights 0,3 --width 400 --height 300 --pixel-samples 1 -o {in}/photos"},
                 kRegister + " run {in}/photos/manifest.json --resolution 8 -o {out}/r.h5 --report {out}/r.json "
                             "--contact-sheet {out}/sheet.png"},
        ToolCase{"compress_pca_view", {kSmallBtf + " -o {in}/d.h5"},
                 kCompress + " {in}/d.h5 --method pca-view --components 2 -o {out}/c.h5"},
        ToolCase{"compress_lpca", {kSmallBtf + " -o {in}/d.h5"},
                 kCompress + " {in}/d.h5 --method lpca --clusters 2 --components 2 -o {out}/c.h5"},
        ToolCase{"decode",
                 {kSmallBtf + " -o {in}/d.h5", kCompress + " {in}/d.h5 --method lpca --clusters 2 --components 2 -o {in}/c.h5"},
                 kCompress + " decode {in}/c.h5 -o {out}/d.h5"},
        ToolCase{"export",
                 {kSmallBtf + " -o {in}/d.h5", kCompress + " {in}/d.h5 --method lpca --clusters 2 --components 2 -o {in}/c.h5"},
                 kCompress + " export {in}/c.h5 --format schneider --view-grid 4 --light-grid 4 -o {out}/export"},
        ToolCase{"convert_to_bdi", {kSmallBtf + " -o {in}/d.h5"}, kConvert + " {in}/d.h5 --to bdi -o {out}/x.btf"},
        ToolCase{"convert_to_dfmf", {kSmallBtf + " -o {in}/d.h5"},
                 kConvert + " {in}/d.h5 --to dfmf -c 2 -o {out}/x.btf"},
        ToolCase{"convert_to_pvf",
                 {kSmallBtf + " -o {in}/d.h5", kCompress + " {in}/d.h5 --method pca-view --components 2 -o {in}/c.h5"},
                 kConvert + " {in}/c.h5 --to pvf -o {out}/x.btf"},
        ToolCase{"convert_from_bdi", {kSmallBtf + " -o {in}/d.h5", kConvert + " {in}/d.h5 --to bdi -o {in}/x.btf"},
                 kConvert + " {in}/x.btf -o {out}/d.h5"},
        ToolCase{"sweep", {kSmallBtf + " -o {in}/d.h5"},
                 kEval + " sweep {in}/d.h5 --methods pca-view --components 1,2 --runs 1 --render-size 64 -o {out}/sweep"}),
    [](const auto& info) { return info.param.name; });

}  // namespace
}  // namespace btf
