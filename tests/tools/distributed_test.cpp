// Distributed runs over MPI (docs/scaling.md): results equal for 1-4 local ranks, ranks reported,
// a failing or killed rank ends the whole job cleanly, and commands that do not split their work
// refuse to run as N copies. Needs a build with MPI (BTF_HAVE_MPI) and mpirun; skipped otherwise
// (the sanitizer build has no MPI).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/io/dataset_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

#ifdef BTF_MPIEXEC
// Local ranks on this machine; one OpenMP thread each (the results do not depend on it).
std::string Mpirun(int ranks) {
  return fmt::format("{} --oversubscribe {} -x OMP_NUM_THREADS=1 -np {} ", BTF_MPIEXEC,
                     ::geteuid() == 0 ? "--allow-run-as-root" : "", ranks);
}
#define REQUIRE_MPI()
#else
std::string Mpirun(int) { return ""; }
#define REQUIRE_MPI() GTEST_SKIP() << "built without MPI"
#endif

nlohmann::json RunJson(const std::string& cmd, int* rc = nullptr) {
  std::string out;
  const int r = test::RunCommand(cmd + " --json --quiet", &out);
  if (rc) *rc = r;
  EXPECT_EQ(r, 0) << cmd;
  return r == 0 ? nlohmann::json::parse(out) : nlohmann::json();
}

const std::string kSynth = " btf --views 0-12 --lights 0-6 --resolution 8 --samples 2";

// btf-synth btf: ranks render disjoint view slots and rank 0 writes; 13 views over 1-4 ranks
// give uneven shares. The stored values must be bit-identical, since a slot does not depend on
// the rank that renders it; the JSON reports the ranks and each rank's time and memory.
TEST(Distributed, SynthBtfIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const fs::path serial = dir / "serial.h5";
  const auto j0 = RunJson(test::Tool("btf-synth") + kSynth + " -o " + serial.string());
  EXPECT_EQ(j0.value("ranks", 0), 1);
  EXPECT_EQ(j0.value("per_rank", nlohmann::json::array()).size(), 1u);
  const Dataset want = ReadDataset(serial);
  for (int ranks = 1; ranks <= 4; ++ranks) {
    const fs::path out = dir / fmt::format("ranks{}.h5", ranks);
    const auto j = RunJson(Mpirun(ranks) + test::Tool("btf-synth") + kSynth + " -o " + out.string());
    EXPECT_EQ(j.value("ranks", 0), ranks);
    ASSERT_EQ(j.value("per_rank", nlohmann::json::array()).size(), std::size_t(ranks));
    for (int r = 0; r < ranks; ++r) {
      EXPECT_EQ(j["per_rank"][r]["rank"], r);
      EXPECT_GT(j["per_rank"][r]["peak_rss_bytes"].get<double>(), 0);
    }
    EXPECT_TRUE(ReadDataset(out).data() == want.data()) << ranks << " ranks";
  }
}

// btf-eval compare: ranks measure disjoint view slots; every per-image sum is merged in the same
// order whatever the rank count, so every figure is bit-identical to the single-process run.
TEST(Distributed, CompareFiguresAreIdenticalForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string a = (dir / "a.h5").string(), b = (dir / "b.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + kSynth + " --seed 1 --quiet -o " + a), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + kSynth + " --seed 2 --quiet -o " + b), 0);
  const auto want = RunJson(test::Tool("btf-eval") + " compare " + a + " " + b);
  ASSERT_GT(want.value("rmse", 0.0), 0) << "two jitter seeds must differ, or the test compares nothing";
  for (int ranks = 1; ranks <= 4; ++ranks) {
    const auto got = RunJson(Mpirun(ranks) + test::Tool("btf-eval") + " compare " + a + " " + b);
    EXPECT_EQ(got.value("ranks", 0), ranks);
    for (const char* key : {"rmse", "rel_l2", "psnr_db", "max_abs", "max_abs_at", "mean_ssim", "peak", "view_rmse",
                            "light_rmse", "worst_images"})
      EXPECT_EQ(got[key], want[key]) << key << " with " << ranks << " ranks";
  }
}

// A rank that fails on its part (view slot 1 of the test file holds a NaN, which compare refuses
// as bad input) ends the job: exit 3, the message names rank 1 and the file.
TEST(Distributed, ARankThatCannotReadItsPartEndsTheJobNamingTheRank) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string a = (dir / "a.h5").string(), b = (dir / "b.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + kSynth + " --quiet -o " + a), 0);
  {
    Dataset d = ReadDataset(a);
    d.view_slot(1)[0] = std::numeric_limits<float>::quiet_NaN();  // owned by rank 1 of 2
    WriteDataset(b, d);
  }
  std::string out;
  const int rc = test::RunCommand(Mpirun(2) + test::Tool("btf-eval") + " compare " + a + " " + b + " --quiet 2>&1", &out);
  EXPECT_EQ(rc, 3) << out;
  EXPECT_NE(out.find("rank 1 of 2"), std::string::npos) << out;
  EXPECT_NE(out.find(b), std::string::npos) << out;
}

// SIGKILL of rank 1 while the job writes: mpirun ends the job with a non-zero exit, nothing
// appears under the final name, and rank 0 (ended by mpirun's SIGTERM) leaves no temporary.
TEST(Distributed, AKilledRankFailsTheJobWithoutPartialOutput) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir(), out = dir / "out.h5";
  const std::string cmd = Mpirun(3) + test::Tool("btf-synth") +
                          " btf --views 0-80 --lights 0-80 --resolution 24 --samples 2 --quiet -o " + out.string();
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    execl("/bin/sh", "sh", "-c", ("exec " + cmd + " >/dev/null 2>&1").c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // Rank 1 is the process whose environment says OMPI_COMM_WORLD_RANK=1; wait until it runs
  // and rank 0 has reserved its temporary.
  pid_t victim = -1;
  for (int i = 0; i < 600 && victim < 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    bool temp = false;
    for (const auto& e : fs::directory_iterator(dir)) temp |= e.path().filename().string().find(".tmp-") != std::string::npos;
    if (!temp) continue;
    for (const auto& p : fs::directory_iterator("/proc")) {
      const std::string env = test::Slurp(p.path() / "environ"), cmdline = test::Slurp(p.path() / "cmdline");
      if (cmdline.find("btf-synth") != std::string::npos && cmdline.find(out.string()) != std::string::npos &&
          env.find(std::string("OMPI_COMM_WORLD_RANK=1") + '\0') != std::string::npos)
        victim = std::stoi(p.path().filename().string());
    }
  }
  ASSERT_GT(victim, 0) << "rank 1 never started";
  ::kill(victim, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) != 0) << "status " << status;
  EXPECT_FALSE(fs::exists(out)) << "a partial output appeared under the final name";
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir)) left.push_back(e.path().filename().string());
  EXPECT_TRUE(left.empty()) << "left behind: " << left.front();
}

// A command that does not split its work refuses to run as N copies (exit 2, one message).
TEST(Distributed, SingleProcessCommandsRefuseSeveralRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  std::string out;
  const int rc = test::RunCommand(Mpirun(2) + test::Tool("btf-synth") + " brdf --views 0 --lights 0 -o " +
                                      (dir / "b.h5").string() + " 2>&1",
                                  &out);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("'btf-synth brdf' does not run distributed"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "b.h5"));
}

}  // namespace
}  // namespace btf
