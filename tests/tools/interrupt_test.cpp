// Interrupted runs leave no half-written output and lose nothing (docs/errors.md): a tool killed
// with SIGTERM/SIGINT while working removes its temporary file and leaves an existing output of
// the same name untouched.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "libbtf/io/dataset_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

bool HasTemporary(const fs::path& dir) {
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) return true;
  return false;
}

// Starts `argv` with stdout/stderr discarded; returns its pid.
pid_t Spawn(const std::vector<std::string>& args) {
  const pid_t pid = fork();
  if (pid == 0) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    freopen("/dev/null", "w", stdout);
    freopen("/dev/null", "w", stderr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}

// Waits until `ready()` or the child exits (then fails the test); returns true if ready.
template <typename Ready>
bool WaitUntil(pid_t pid, Ready ready, double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (ready()) return true;
    int status;
    if (waitpid(pid, &status, WNOHANG) == pid) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

int KillAndWait(pid_t pid, int sig) {
  kill(pid, sig);
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFSIGNALED(status) ? WTERMSIG(status) : -1;
}

TEST(Interrupt, KilledSynthesisRemovesItsTemporaryAndKeepsTheOldOutput) {
  // btf-synth streams view slots into the temporary file while it generates, so the temporary
  // exists for most of the run: kill it then.
  const fs::path dir = test::TempDir();
  const fs::path out = dir / "gt.h5";
  WriteDataset(out, test::MakeTestDataset(1, 1, 2, 2));
  const std::string before = test::Slurp(out);
  for (int sig : {SIGTERM, SIGINT}) {
    const pid_t pid = Spawn({test::Tool("btf-synth"), "btf", "--model", "irawan2006", "--preset", "twill",
                             "--directions", "bonn81", "--resolution", "96", "--quiet", "-o", out.string()});
    ASSERT_TRUE(WaitUntil(pid, [&] { return HasTemporary(dir); }, 60)) << "no temporary appeared";
    EXPECT_EQ(KillAndWait(pid, sig), sig);
    EXPECT_FALSE(HasTemporary(dir)) << "signal " << sig;
    EXPECT_EQ(test::Slurp(out), before) << "signal " << sig;
  }
}

TEST(Interrupt, KilledCompressionLeavesTheExistingCodecUntouched) {
  const fs::path dir = test::TempDir();
  const fs::path data = dir / "data.h5", out = dir / "codec.h5";
  WriteDataset(data, test::MakeTestDataset(81, 81, 24, 24));
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + data.string() +
                             " --method pca-view --components 2 --quiet -o " + out.string()),
            0);
  const std::string before = test::Slurp(out);
  const pid_t pid = Spawn({test::Tool("btf-compress"), data.string(), "--method", "lpca", "--clusters", "16",
                           "--components", "8", "--quiet", "-o", out.string()});
  // btf-compress reserves its temporary before the work; once it is there, let the run get into
  // the work (reading and clustering), then interrupt it.
  ASSERT_TRUE(WaitUntil(pid, [&] { return HasTemporary(dir); }, 60)) << "no temporary appeared";
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, WNOHANG), 0) << "compression finished before it could be interrupted";
  ASSERT_TRUE(HasTemporary(dir));
  EXPECT_EQ(KillAndWait(pid, SIGTERM), SIGTERM);
  EXPECT_FALSE(HasTemporary(dir));
  EXPECT_EQ(test::Slurp(out), before);
}

}  // namespace
}  // namespace btf
