// Output on a full file system (issue #20's first case): the writing tools end with exit 4 and a
// message, keep the existing output and leave no temporary. Needs root to mount a 2 MiB tmpfs;
// skipped with a message where mounting is not allowed.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/mount.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

class FullDisk : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::TempDir();
    mnt_ = dir_ / "full";
    fs::create_directories(mnt_);
    if (::mount("tmpfs", mnt_.c_str(), "tmpfs", 0, "size=2m") != 0) GTEST_SKIP() << "cannot mount a tmpfs here";
    mounted_ = true;
  }
  void TearDown() override {
    if (mounted_) ::umount(mnt_.c_str());
  }
  // Runs `command` writing `output` inside the full file system over an existing file, or, with
  // `marker`, over an existing output folder holding that file.
  void ExpectCleanFailure(const std::string& command, const fs::path& output, const std::string& marker = "") {
    const fs::path old = marker.empty() ? output : output / marker;
    if (!marker.empty()) fs::create_directories(output);
    std::ofstream(old) << "old output";
    std::string out;
    EXPECT_EQ(test::RunCommand(command + " 2>&1", &out), 4) << command << "\n" << out;
    EXPECT_NE(out.find("disk full"), std::string::npos) << out;
    std::ifstream in(old);
    std::string kept((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(kept, "old output") << "the old output was not kept: " << command;
    if (!marker.empty()) {
      EXPECT_EQ(std::distance(fs::directory_iterator(output), {}), 1) << "files added: " << command;
    }
    for (const auto& e : fs::directory_iterator(mnt_))
      EXPECT_TRUE(e.path() == output || e.path() == filler_) << "left behind: " << e.path();
    fs::remove_all(output);
  }
  // Leaves only `free_bytes` of the file system unused.
  void Fill(off_t free_bytes) {
    filler_ = mnt_ / "filler";
    const int fd = ::open(filler_.c_str(), O_WRONLY | O_CREAT, 0644);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::posix_fallocate(fd, 0, (2 << 20) - free_bytes), 0);
    ::close(fd);
  }
  fs::path filler_;
  fs::path dir_, mnt_;
  bool mounted_ = false;
};

TEST_F(FullDisk, WritingToolsExitFourAndKeepTheOldOutput) {
  const std::string big = (dir_ / "big.h5").string();
  // About 6 MB after deflate: three times the file system.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0-80 --lights 0-80 --resolution 32 --samples 1 "
                                                       "--quiet -o " + big),
            0);
  ExpectCleanFailure(test::Tool("btf-synth") + " btf --views 0-80 --lights 0-80 --resolution 32 --samples 1 --quiet -o " +
                         (mnt_ / "a.h5").string(),
                     mnt_ / "a.h5");
  const std::string codec = (dir_ / "codec.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + big + " --method lpca --clusters 2 --components 2 " +
                             "--max-iterations 1 --quiet -o " + codec),
            0);
  ExpectCleanFailure(test::Tool("btf-compress") + " decode " + codec + " -o " + (mnt_ / "d.h5").string(), mnt_ / "d.h5");
  ExpectCleanFailure(test::Tool("btf-compress") + " " + big + " --method pca-view --components 40 --quiet -o " +
                         (mnt_ / "c.h5").string(),
                     mnt_ / "c.h5");
}

// The other writing tools, with their inputs outside and 16 KiB left on the output's file system.
TEST_F(FullDisk, EveryOtherWritingToolExitsFourAndKeepsTheOldOutput) {
  const std::string synth = test::Tool("btf-synth"), comp = test::Tool("btf-compress");
  const std::string data = (dir_ / "d.h5").string(), codec = (dir_ / "c.h5").string();
  ASSERT_EQ(test::RunCommand(synth + " btf --views 0-8 --lights 0-8 --resolution 16 --samples 1 --quiet -o " + data), 0);
  ASSERT_EQ(test::RunCommand(comp + " " + data + " --method lpca --clusters 2 --components 2 --quiet -o " + codec), 0);
  Fill(16 << 10);
  ExpectCleanFailure(synth + " brdf --views 0-80 --lights 0-80 -o " + (mnt_ / "b.h5").string(), mnt_ / "b.h5");
  ExpectCleanFailure(synth + " photos --views 0 --lights 0 --width 320 --height 240 -o " + (mnt_ / "photos").string(),
                     mnt_ / "photos", "manifest.json");
  ExpectCleanFailure(test::Tool("btf-register") + " run " + test::SourceDir() + "/sample_data/photos/manifest.json " +
                         "--resolution 32 -o " + (mnt_ / "r.h5").string(),
                     mnt_ / "r.h5");
  ExpectCleanFailure(comp + " export " + codec + " -o " + (mnt_ / "export").string(), mnt_ / "export", "manifest.json");
  ExpectCleanFailure(test::Tool("btf-convert") + " " + data + " --to bdi -o " + (mnt_ / "x.btf").string(), mnt_ / "x.btf");
  ExpectCleanFailure(test::Tool("btf-convert") + " " + data + " --to dfmf -c 8 -o " + (mnt_ / "y.btf").string(),
                     mnt_ / "y.btf");
  ExpectCleanFailure(test::Tool("btf-eval") + " sweep " + data + " --methods pca-view --components 1,2 --runs 1 -o " +
                         (mnt_ / "sweep").string(),
                     mnt_ / "sweep", "results.json");
}

}  // namespace
}  // namespace btf
