// Faults other than a failing system call (docs/errors.md, "Faults"): a read-only output folder,
// inputs that change while a tool reads them, two runs writing the same output at once, and
// SIGKILL at many points of a long write.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/io/dataset_io.h"
#include "tests/fault_shim.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

// Names of the temporaries AtomicOutput and AtomicDirectory leave in `dir` (none after a clean end).
std::vector<std::string> Temporaries(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) out.push_back(e.path().filename().string());
  return out;
}

// RMSE between two datasets or codecs (btf-eval compare); -1 when the comparison fails.
double Rmse(const fs::path& a, const fs::path& b) {
  std::string out;
  if (test::RunCommand(test::Tool("btf-eval") + " compare " + a.string() + " " + b.string() + " --json 2>/dev/null",
                       &out) != 0)
    return -1;
  return nlohmann::json::parse(out).at("rmse").get<double>();
}

// True when both files are readable datasets with the same values (in-process: fast).
bool SameData(const fs::path& a, const fs::path& b) {
  try {
    return ReadDataset(a).data() == ReadDataset(b).data();
  } catch (const std::exception&) {
    return false;
  }
}

const std::string kSynthBtf = test::Tool("btf-synth") + " btf --views 0-10 --lights 0-10 --resolution 16 --samples 1";

// A read-only file system (a tmpfs remounted read-only; root ignores folder permissions): every
// writing tool exits 4 naming the folder, and the file already there is untouched.
TEST(Faults, ReadOnlyOutputFolderExitsFourAndKeepsTheOldOutput) {
  const fs::path dir = test::TempDir(), mnt = dir / "ro";
  fs::create_directories(mnt);
  if (::mount("tmpfs", mnt.c_str(), "tmpfs", 0, "size=1m") != 0) GTEST_SKIP() << "cannot mount a tmpfs here";
  std::ofstream(mnt / "old.h5") << "old output";
  fs::create_directories(mnt / "photos");
  std::ofstream(mnt / "photos" / "manifest.json") << "old output";
  ASSERT_EQ(::mount(nullptr, mnt.c_str(), nullptr, MS_REMOUNT | MS_RDONLY, nullptr), 0);
  const std::string in = (dir / "in.h5").string(), codec = (dir / "codec.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1 --lights 0,1 --resolution 4 --samples 1 --quiet -o " + in), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + in + " --method pca-view --components 1 --quiet -o " + codec), 0);
  const std::string old = (mnt / "old.h5").string();
  for (const std::string& cmd :
       {test::Tool("btf-synth") + " btf --views 0,1 --lights 0,1 --resolution 4 --samples 1 -o " + old,
        test::Tool("btf-synth") + " photos --views 0 --lights 0 --width 160 --height 120 -o " + (mnt / "photos").string(),
        test::Tool("btf-compress") + " " + in + " --method pca-view --components 1 -o " + old,
        test::Tool("btf-compress") + " decode " + codec + " -o " + old,
        test::Tool("btf-compress") + " export " + codec + " -o " + (mnt / "export").string()}) {
    std::string out;
    const int rc = test::RunCommand(cmd + " --quiet 2>&1", &out);
    // export refuses a per-view PCA codec (usage, exit 2) before it writes: that is fine too.
    if (cmd.find(" export ") != std::string::npos && rc == 2) continue;
    EXPECT_EQ(rc, 4) << cmd << "\n" << out;
    EXPECT_NE(out.find(mnt.string()), std::string::npos) << "the message names no folder: " << out;
  }
  EXPECT_EQ(test::Slurp(mnt / "old.h5"), "old output");
  EXPECT_EQ(test::Slurp(mnt / "photos" / "manifest.json"), "old output");
  EXPECT_TRUE(Temporaries(mnt).empty());
  ::umount(mnt.c_str());
}

// An input truncated, deleted or replaced by another file while btf-compress reads it (the
// change is made by tests/fault_inject.c at the N-th read of the input, for N over the whole
// run). Deleting or replacing the name does not change what the open file holds, so the run
// ends normally with the codec of the original (or of the replacement, or exit 4, when the name
// changed before the data file was opened); a truncated input ends with a clear error
// (exit 3: its chunks fail their checksums; or 4) and the old output untouched, or, when the
// truncation came after the last read, with the correct codec.
TEST(Faults, InputChangedWhileReadGivesTheOriginalResultOrAClearError) {
  const fs::path dir = test::TempDir(), in = dir / "in", out = dir / "out";
  fs::create_directories(in);
  fs::create_directories(out);
  const fs::path input = in / "d.h5", other = dir / "other.h5", ref = dir / "ref.h5", codec = out / "c.h5";
  ASSERT_EQ(test::RunCommand(kSynthBtf + " --quiet -o " + input.string()), 0);
  ASSERT_EQ(test::RunCommand(kSynthBtf + " --seed 9 --quiet -o " + other.string()), 0);
  // One thread: the codecs of two runs are then bit-identical (docs/architecture.md, "Threads").
  const std::string compress = "OMP_NUM_THREADS=1 " + test::Tool("btf-compress") + " " + input.string() +
                               " --method pca-view --components 2 --quiet -o ";
  ASSERT_EQ(test::RunCommand(compress + ref.string()), 0);
  const fs::path ref_other = dir / "ref_other.h5";  // the codec of the replacement
  ASSERT_EQ(test::RunCommand("OMP_NUM_THREADS=1 " + test::Tool("btf-compress") + " " + other.string() +
                             " --method pca-view --components 2 --quiet -o " + ref_other.string()),
            0);
  const std::string env = fmt::format("LD_PRELOAD={} ASAN_OPTIONS=detect_leaks=1:verify_asan_link_order=0 BTF_FAULT_DIR={} ",
                                      test::FaultShim(), in.string());
  ASSERT_EQ(test::RunCommand(env + "BTF_FAULT_COUNTS=" + (dir / "counts").string() + " " + compress + codec.string()), 0);
  std::ifstream counts(dir / "counts");
  std::string op;
  long reads = 0;
  counts >> op >> reads >> op >> reads;  // "write W\nread R..."
  ASSERT_GT(reads, 3);
  const std::string pristine = (dir / "pristine.h5").string();
  fs::copy_file(input, pristine);
  int errors = 0, completed = 0;
  for (const std::string action : {"truncate", "unlink", "replace"}) {
    for (long n : {1L, reads / 2, reads}) {
      fs::copy_file(pristine, input, fs::copy_options::overwrite_existing);
      fs::copy_file(other, dir / "replacement.h5", fs::copy_options::overwrite_existing);
      const std::string old = test::Slurp(codec);
      std::string log;
      const int rc = test::RunCommand(fmt::format("BTF_FAULT={}:{} BTF_FAULT_REPLACEMENT={} ", action, n,
                                                  (dir / "replacement.h5").string()) +
                                          env + compress + codec.string() + " 2>&1",
                                      &log);
      const std::string what = fmt::format("{} at read {} of {}: exit {}\n{}", action, n, reads, rc, log);
      if (rc == 0) {
        ++completed;
        // The original's codec; or, when the name was replaced at the first read (the format
        // sniffing, before the data file is opened), the replacement's: never a mix.
        const bool original = Rmse(ref, codec) == 0.0;
        EXPECT_TRUE(original || (action == "replace" && n == 1 && Rmse(ref_other, codec) == 0.0)) << what;
      } else {
        ++errors;
        // Deleted or replaced while it was being opened (the name is resolved by the format
        // sniffing, the header check and H5Fopen): "no such file" or "deleted or replaced", exit 4.
        EXPECT_TRUE(rc == 3 || rc == 4) << what;
        if (action != "truncate") {
          EXPECT_EQ(rc, 4) << what;
        }
        EXPECT_NE(log.find(input.string()), std::string::npos) << "the message names no file: " << what;
        EXPECT_EQ(test::Slurp(codec), old) << what;
      }
      EXPECT_TRUE(Temporaries(out).empty()) << what;
    }
  }
  EXPECT_GT(errors, 0) << "no change was noticed: are chunks checksummed?";
  EXPECT_GT(completed, 0);
}

// Two runs writing the same output at once (different seeds): both end cleanly, and the output is
// one of the two complete results, never a mix; the same for a folder output.
TEST(Faults, ConcurrentRunsOnOneOutputLeaveOneCompleteResult) {
  const fs::path dir = test::TempDir();
  const fs::path a = dir / "a.h5", b = dir / "b.h5", both = dir / "both.h5";
  ASSERT_EQ(test::RunCommand(kSynthBtf + " --seed 1 --quiet -o " + a.string()), 0);
  ASSERT_EQ(test::RunCommand(kSynthBtf + " --seed 2 --quiet -o " + b.string()), 0);
  const std::string photos = test::Tool("btf-synth") + " photos --views 0,7 --lights 0 --width 240 --height 180 --quiet";
  for (int round = 0; round < 2; ++round) {
    const std::string cmd = fmt::format("({0} --seed 1 -o {1} & p1=$!; {0} --seed 2 -o {1} & p2=$!; {2} --seed 1 -o {3} & "
                                        "p3=$!; {2} --seed 2 -o {3} & p4=$!; wait $p1 && wait $p2 && wait $p3 && wait $p4)",
                                        kSynthBtf + " --quiet", both.string(), photos, (dir / "photos").string());
    std::string log;
    ASSERT_EQ(test::RunCommand(cmd + " 2>&1", &log), 0) << log;
    const bool is_a = SameData(a, both), is_b = SameData(b, both);
    EXPECT_TRUE(is_a || is_b) << "round " << round << ": the output is neither complete result";
    EXPECT_TRUE(fs::exists(dir / "photos" / "manifest.json"));
    EXPECT_TRUE(fs::exists(dir / "photos" / "v000_l000.png") && fs::exists(dir / "photos" / "v007_l000.png"));
    EXPECT_TRUE(Temporaries(dir).empty()) << Temporaries(dir).front();
  }
}

// SIGKILL at many points of a long write: the final name holds the old file or the complete new
// one (compared by value with a reference run), never a partial file. A killed process cannot
// remove its temporary; the next run of any tool does not trip over it (docs/errors.md).
TEST(Faults, SigkillAtAnyPointLeavesTheOldOrTheCompleteNewFile) {
  const fs::path dir = test::TempDir(), old_ref = dir / "old.h5", new_ref = dir / "new.h5", target = dir / "out.h5";
  const std::string synth = test::Tool("btf-synth") + " btf --views 0-30 --lights 0-80 --resolution 16 --samples 1 --quiet";
  ASSERT_EQ(test::RunCommand(synth + " --seed 1 -o " + old_ref.string()), 0);
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(test::RunCommand(synth + " --seed 2 -o " + new_ref.string()), 0);
  const double run_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  int old_kept = 0, new_complete = 0;
  constexpr int kKills = 8;
  for (int k = 0; k < kKills; ++k) {
    fs::copy_file(old_ref, target, fs::copy_options::overwrite_existing);
    // Kill times spread from the start to past the end of a normal run.
    const double at = run_s * 1.2 * (k + 0.5) / kKills;
    const pid_t pid = fork();
    if (pid == 0) {
      execl("/bin/sh", "sh", "-c", ("exec " + synth + " --seed 2 -o " + target.string() + " 2>/dev/null").c_str(),
            static_cast<char*>(nullptr));
      _exit(127);
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(at));
    ::kill(pid, SIGKILL);
    int status = 0;
    ::waitpid(pid, &status, 0);
    const bool is_old = SameData(old_ref, target), is_new = SameData(new_ref, target);
    EXPECT_TRUE(is_old || is_new) << "killed after " << at << " s: the final name holds neither the old nor the complete new file";
    old_kept += is_old;
    new_complete += is_new;
    for (const auto& t : Temporaries(dir)) fs::remove(dir / t);
  }
  RecordProperty("old_kept", old_kept);
  RecordProperty("new_complete", new_complete);
  EXPECT_GT(old_kept, 0) << "no kill landed inside the write: the test says nothing";
}

}  // namespace
}  // namespace btf
