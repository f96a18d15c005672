// Output on a full file system (issue #20's first case): the writing tools end with exit 4 and a
// message, keep the existing output and leave no temporary. Needs root to mount a 2 MiB tmpfs;
// skipped with a message where mounting is not allowed.
#include <gtest/gtest.h>
#include <sys/mount.h>

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
  // Runs `command` writing `output` inside the full file system over an existing file.
  void ExpectCleanFailure(const std::string& command, const fs::path& output) {
    std::ofstream(output) << "old output";
    std::string out;
    EXPECT_EQ(test::RunCommand(command + " 2>&1", &out), 4) << command << "\n" << out;
    EXPECT_NE(out.find("disk full"), std::string::npos) << out;
    std::ifstream in(output);
    std::string kept((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(kept, "old output") << "the old output was not kept";
    for (const auto& e : fs::directory_iterator(mnt_))
      EXPECT_EQ(e.path(), output) << "left behind: " << e.path();
    fs::remove(output);
  }
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

}  // namespace
}  // namespace btf
