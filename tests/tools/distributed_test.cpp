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

#include "libbtf/compress/codec.h"
#include "libbtf/io/dataset_io.h"
#include "tests/codec_util.h"
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

// Renders `btf-synth` with these flags into dir/in.h5 and returns its path.
std::string SynthInput(const fs::path& dir, const std::string& flags) {
  const std::string in = (dir / "in.h5").string();
  EXPECT_EQ(test::RunCommand(test::Tool("btf-synth") + flags + " --quiet -o " + in), 0) << flags;
  return in;
}

// The rank that owns view slot `view` (rank 1 of 2) finds an Inf in it: the job ends with exit 3
// naming that rank and the file, and no codec appears.
void ExpectDamagedSlotEndsTheJob(const std::string& method, int view) {
  const fs::path dir = test::TempDir();
  const std::string a = (dir / "a.h5").string(), b = (dir / "b.h5").string(), codec = (dir / "c.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + kSynth + " --quiet -o " + a), 0);
  {
    Dataset d = ReadDataset(a);
    d.view_slot(view)[5] = std::numeric_limits<float>::infinity();
    WriteDataset(b, d);
  }
  std::string out;
  const int rc = test::RunCommand(
      Mpirun(2) + test::Tool("btf-compress") + " " + b + " --method " + method + " --quiet -o " + codec + " 2>&1", &out);
  EXPECT_EQ(rc, 3) << method << ": " << out;
  EXPECT_NE(out.find("rank 1 of 2"), std::string::npos) << out;
  EXPECT_NE(out.find(b), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(codec)) << method;
}

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

// Compresses `input` with `flags` in one process and with 1-4 ranks: every codec array and
// every error figure of the summary are bit-identical; the JSON names the ranks.
void ExpectCompressionIndependentOfRanks(const std::string& input, const std::string& flags, const fs::path& dir) {
  const fs::path serial = dir / "serial.h5";
  const auto want = RunJson(test::Tool("btf-compress") + " " + input + flags + " -o " + serial.string());
  ASSERT_GT(want.value("rmse", 0.0), 0) << "a lossless codec would compare nothing";
  const Codec ref = ReadCodec(serial);
  for (int ranks = 1; ranks <= 4; ++ranks) {
    const fs::path out = dir / fmt::format("ranks{}.h5", ranks);
    const auto got = RunJson(Mpirun(ranks) + test::Tool("btf-compress") + " " + input + flags + " -o " + out.string());
    EXPECT_EQ(got.value("ranks", 0), ranks);
    EXPECT_EQ(got.value("per_rank", nlohmann::json::array()).size(), std::size_t(ranks));
    for (const char* key : {"rmse", "relative_error", "max_abs_error", "psnr_db", "codec_bytes", "components",
                            "slot_components", "cluster_components", "iteration_relative_errors",
                            "iteration_reassigned_texels", "warnings", "latent_components", "neural"})
      if (want.contains(key)) {  // compared as text: doubles printed with every digit
        EXPECT_EQ(got.value(key, nlohmann::json()).dump(), want[key].dump()) << key << " with " << ranks << " ranks";
      }
    test::ExpectSameCodec(ref, ReadCodec(out), fmt::format("{} ranks", ranks));
    std::vector<std::string> left;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().filename().string().find(".tmp-") != std::string::npos) left.push_back(e.path().string());
    EXPECT_TRUE(left.empty()) << "temporary left behind: " << left.front();
  }
}

// btf-compress --method pca-view: ranks decompose disjoint view slots (13 over 1-4 ranks:
// uneven shares), rank 0 gathers them and writes.
TEST(Distributed, PcaViewCodecIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, kSynth);
  ExpectCompressionIndependentOfRanks(in, " --method pca-view --components 3", dir);
}

// btf-compress --method lpca: ranks own disjoint texel blocks. 48 x 48 texels are 9 blocks of
// 256 texels (the last one shorter), split unevenly over 2-4 ranks; the k-means sample is every
// texel (fewer than 8192), its rounds in the full dimension (108 values: below 2 x the default
// subspace) and in a subspace of 16.
TEST(Distributed, LpcaCodecIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, " btf --views 0-5 --lights 0-5 --resolution 48 --samples 1");
  for (const std::string subspace : {"", " --lpca-subspace 16"}) {
    SCOPED_TRACE(subspace);
    ExpectCompressionIndependentOfRanks(in, " --method lpca --clusters 6 --components 3 --seed 3" + subspace, dir);
  }
}

// btf-compress --method fmf: the randomised SVD's passes are split over view slots (13 over 1-4
// ranks: uneven shares); rank 0 adds the per-view X^T Q terms in view order, so the factors and
// every error figure are bit-identical. 24 x 24 texels and 13 x 7 x 3 rows: a full-rank block
// on every rank, and the --log transform applied by the rank that reads the slot.
TEST(Distributed, FmfCodecIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, " btf --views 0-12 --lights 0-6 --resolution 24 --samples 1");
  ExpectCompressionIndependentOfRanks(in, " --method fmf --components 6 --seed 5", dir);
  const fs::path log_dir = dir / "log";
  fs::create_directories(log_dir);
  ExpectCompressionIndependentOfRanks(in, " --method fmf --components 4 --log --error 0.05", log_dir);
}

// btf-compress --method dfmf: the three YUV matrices, each factorised as fmf's one.
TEST(Distributed, DfmfCodecIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, " btf --views 0-12 --lights 0-6 --resolution 24 --samples 1");
  ExpectCompressionIndependentOfRanks(in, " --method dfmf --components 5 --seed 2", dir);
}

// btf-compress --method neural: each rank draws the samples of the view slots it owns (13 over
// 1-4 ranks: uneven shares) and all gather the set; training is data-parallel over the 6 blocks
// of 256 samples of each step (split 6, 3+3, 2+2+2, 1+2+1+2 over the ranks), the gradients
// gathered and summed in block order. The decoder, the latents (as trained and as stored) and every
// figure of the summary, the losses included, are bit-identical to the one process's (which runs
// with the default OpenMP threads, the ranks with one each).
TEST(Distributed, NeuralCodecIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, " btf --views 0-12 --lights 0-6 --resolution 16 --samples 1");
  ExpectCompressionIndependentOfRanks(in,
                                      " --method neural --neural-latent 4 --neural-hidden 16,16 --neural-samples 6000 "
                                      "--neural-batch 1536 --neural-steps 40 --seed 7",
                                      dir);
  const Codec ref = ReadCodec(dir / "serial.h5");
  ASSERT_EQ(ref.method(), CodecMethod::kNeural);
  for (int ranks = 1; ranks <= 4; ++ranks) {
    const Codec got = ReadCodec(dir / fmt::format("ranks{}.h5", ranks));
    const NeuralCodecModel &x = ref.neural(), &y = got.neural();
    EXPECT_EQ(y.latent, 4);
    EXPECT_TRUE(x.codes == y.codes && x.scale == y.scale && x.bias == y.bias) << ranks << " ranks";
    EXPECT_TRUE(x.latents == y.latents) << ranks << " ranks";
    EXPECT_TRUE(x.net.parameters() == y.net.parameters()) << ranks << " ranks";
  }
}

// neural: the rank that draws the samples of the damaged view slot reports it (exit 3, its rank
// and the file named) while rank 0 waits in the gather; no codec appears.
TEST(Distributed, NeuralRankThatReadsADamagedSlotEndsTheJob) {
  REQUIRE_MPI();
  ExpectDamagedSlotEndsTheJob("neural", 5);
}

// btf-convert --to fmf | dfmf factorises with the same distributed SVD; rank 0 writes the Bonn
// file, whose bytes (no time stamps) are the same for 1-4 ranks as for one process.
TEST(Distributed, ConvertToFmfAndDfmfWritesTheSameFileForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, kSynth);
  for (const std::string to : {"fmf", "dfmf"}) {
    const fs::path serial = dir / (to + "-serial.btf");
    const std::string flags = " --to " + to + " --components 4 --quiet -o ";
    ASSERT_EQ(test::RunCommand(test::Tool("btf-convert") + " " + in + flags + serial.string()), 0);
    const std::string want = test::Slurp(serial);
    ASSERT_GT(want.size(), 100u);
    for (int ranks = 1; ranks <= 4; ++ranks) {
      const fs::path out = dir / fmt::format("{}-ranks{}.btf", to, ranks);
      ASSERT_EQ(test::RunCommand(Mpirun(ranks) + test::Tool("btf-convert") + " " + in + flags + out.string()), 0)
          << to << " with " << ranks << " ranks";
      EXPECT_TRUE(test::Slurp(out) == want) << to << " with " << ranks << " ranks";
    }
  }
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) left.push_back(e.path().string());
  EXPECT_TRUE(left.empty()) << "temporary left behind: " << left.front();
}

// fmf: the rank that owns a view slot holding Inf reports it (exit 3, its rank and the file
// named) and no codec appears.
TEST(Distributed, FmfRankThatReadsADamagedSlotEndsTheJob) {
  REQUIRE_MPI();
  ExpectDamagedSlotEndsTheJob("fmf", 5);
}

// The same with a random k-means sample (8192 of 96 x 96 texels, gathered on rank 0) and the
// log transform.
TEST(Distributed, LpcaWithASampledSeedingIsTheSameForOneToFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, " btf --views 0-3 --lights 0-3 --resolution 96 --samples 1");
  ExpectCompressionIndependentOfRanks(in, " --method lpca --clusters 5 --components 2 --log --max-iterations 4", dir);
}

// BTF_MAX_BYTES applies per rank: an LPCA whose texel-major matrix is over the limit is refused
// by one process (exit 3, naming the limit) and succeeds with 4 ranks, each holding a quarter
// of the texels (and rank 0 the 8192-texel sample, half of them). The float matrix: the default
// half one (2 bytes a value) would fit one process.
TEST(Distributed, LpcaOverOneRanksMemoryLimitSucceedsWithFourRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = SynthInput(dir, " btf --views 0-2 --lights 0-2 --resolution 128 --samples 1");
  const double matrix = 4.0 * 128 * 128 * 3 * 3 * 3;  // texels x (views x lights x channels) floats
  const std::string limit = fmt::format("BTF_MAX_BYTES={} ", std::uint64_t(0.6 * matrix));
  const std::string flags = " --method lpca --lpca-matrix float --clusters 4 --components 2 --max-iterations 3 --quiet";
  std::string out;
  const fs::path one = dir / "one.h5", four = dir / "four.h5";
  const int rc1 = test::RunCommand(limit + test::Tool("btf-compress") + " " + in + flags + " -o " + one.string() + " 2>&1", &out);
  EXPECT_EQ(rc1, 3) << out;
  EXPECT_NE(out.find("BTF_MAX_BYTES"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(one));
  const std::string mpirun = Mpirun(4) + "-x " + limit.substr(0, limit.size() - 1) + " ";
  const int rc4 = test::RunCommand(limit + mpirun + test::Tool("btf-compress") + " " + in + flags + " -o " + four.string() + " 2>&1", &out);
  EXPECT_EQ(rc4, 0) << out;
  ASSERT_TRUE(fs::exists(four));
  // The same codec as one process with enough memory.
  const fs::path free = dir / "free.h5";
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + in + flags + " -o " + free.string()), 0);
  test::ExpectSameCodec(ReadCodec(free), ReadCodec(four), "4 ranks under the limit");
}

// pca-view: the rank that owns the damaged view slot reports it (exit 3, its rank and the
// file named) and no codec appears.
TEST(Distributed, PcaViewRankThatReadsADamagedSlotEndsTheJob) {
  REQUIRE_MPI();
  ExpectDamagedSlotEndsTheJob("pca-view", 3);
}

// lpca-tensor (its factorisation runs on one process), decode, and btf-convert's conversions
// other than the factorisation to fmf / dfmf do not split their work: refused on 2 ranks.
TEST(Distributed, CompressCommandsThatDoNotSplitRefuseSeveralRanks) {
  REQUIRE_MPI();
  const fs::path dir = test::TempDir();
  const std::string in = (dir / "in.h5").string(), codec = (dir / "c.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + kSynth + " --quiet -o " + in), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + in + " --method pca-view --quiet -o " + codec), 0);
  struct Refused {
    std::string tool, args, name;
  };
  for (const Refused& c : std::vector<Refused>{
           {"btf-compress", in + " --method lpca-tensor -o " + (dir / "f.h5").string(), "btf-compress --method lpca-tensor"},
           {"btf-compress", "decode " + codec + " -o " + (dir / "d.h5").string(), "btf-compress decode"},
           {"btf-convert", in + " --to bdi -o " + (dir / "b.btf").string(), "btf-convert --to bdi"}}) {
    std::string out;
    const int rc = test::RunCommand(Mpirun(2) + test::Tool(c.tool) + " " + c.args + " 2>&1", &out);
    EXPECT_EQ(rc, 2) << out;
    EXPECT_NE(out.find("'" + c.name + "' does not run distributed"), std::string::npos) << out;
  }
  EXPECT_FALSE(fs::exists(dir / "f.h5"));
  EXPECT_FALSE(fs::exists(dir / "d.h5"));
  EXPECT_FALSE(fs::exists(dir / "b.btf"));
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
