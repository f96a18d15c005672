#include "libbtf/core/atomic_file.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/sysmacros.h>

#include <fstream>

#include "libbtf/core/error.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(AtomicOutput, CommitReplacesAndAbandonKeepsTheOldFile) {
  const auto dir = test::TempDir();
  const auto path = dir / "out.json";
  WriteTextFileAtomic(path, "first");
  EXPECT_EQ(test::Slurp(path), "first");
  {
    AtomicOutput out(path);
    std::ofstream(out.temp_path()) << "half-writ";
    EXPECT_TRUE(std::filesystem::exists(out.temp_path()));
    EXPECT_EQ(out.temp_path().extension(), ".json");  // writers that pick a type by extension work
  }  // abandoned
  EXPECT_EQ(test::Slurp(path), "first");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);
  WriteTextFileAtomic(path, "second");
  EXPECT_EQ(test::Slurp(path), "second");
}

TEST(AtomicOutput, ReserveCreatesTheTemporaryUntilCommitOrAbandon) {
  const auto dir = test::TempDir();
  {
    AtomicOutput out(dir / "c.h5");
    out.Reserve();
    EXPECT_TRUE(std::filesystem::exists(out.temp_path()));
    EXPECT_FALSE(std::filesystem::exists(out.final_path()));
  }  // abandoned: the reserved temporary goes too
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 0);
  AtomicOutput out(dir / "c.h5");
  out.Reserve();
  std::ofstream(out.temp_path()) << "codec";
  out.Commit();
  EXPECT_EQ(test::Slurp(dir / "c.h5"), "codec");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);
}

TEST(AtomicOutput, ReserveNowClaimsTheOutputAtConstruction) {
  const auto dir = test::TempDir();
  {
    AtomicOutput out(dir / "c.h5", AtomicOutput::kReserve);
    EXPECT_TRUE(std::filesystem::exists(out.temp_path()));
  }
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 0);
  // A folder that exists but takes no new file (even for root): the claim fails at once, as I/O.
  try {
    AtomicOutput out("/proc/libbtf-claim.h5", AtomicOutput::kReserve);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kIo);
    EXPECT_NE(std::string(e.what()).find("cannot create"), std::string::npos) << e.what();
  }
}

TEST(AtomicOutput, MissingFolderIsAnIoError) {
  try {
    AtomicOutput out(test::TempDir() / "no" / "such" / "f.h5");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kIo);
  }
}

// An output that is an input, by any name, is refused before anything is written; outputs and
// inputs that do not exist are fine.
TEST(CheckOutput, SameFileByAnyNameAndFoldersHoldingAnInput) {
  namespace fs = std::filesystem;
  const auto dir = test::TempDir();
  std::ofstream(dir / "a.h5") << "input";
  fs::create_directories(dir / "sub");
  fs::create_hard_link(dir / "a.h5", dir / "hard.h5");
  fs::create_symlink(dir / "a.h5", dir / "soft.h5");
  for (const fs::path& out : {dir / "a.h5", dir / "sub" / ".." / "a.h5", dir / "hard.h5", dir / "soft.h5"}) {
    ExitCode code{};
    const std::string msg = test::ErrorOf([&] { CheckOutput(out, {dir / "b.h5", dir / "a.h5"}); }, &code);
    EXPECT_EQ(code, ExitCode::kUsage) << out;
    EXPECT_NE(msg.find("destroy the input"), std::string::npos) << msg;
    EXPECT_NE(msg.find(out.string()), std::string::npos) << msg;
  }
  EXPECT_NO_THROW(CheckOutput(dir / "new.h5", {dir / "a.h5"}));
  EXPECT_NO_THROW(CheckOutput(dir / "a.h5", {dir / "missing.h5", ""}));
  EXPECT_NO_THROW(CheckOutput(dir / "sub", {dir / "a.h5"}, OutputKind::kFolder));  // a folder beside the input
  std::ofstream(dir / "sub" / "c.h5") << "input";
  ExitCode code{};
  const std::string msg = test::ErrorOf([&] { CheckOutput(dir / "sub", {dir / "sub" / "c.h5"}, OutputKind::kFolder); }, &code);
  EXPECT_EQ(code, ExitCode::kUsage);
  EXPECT_NE(msg.find("holds the input"), std::string::npos) << msg;
  EXPECT_NO_THROW(CheckOutput(dir / "su", {dir / "sub" / "c.h5"}, OutputKind::kFolder));  // a name prefix is no folder
}

// Only a regular file, a symbolic link or nothing may be replaced: a named pipe, a device or a
// folder at the output path is refused when the output is claimed, before any work, and left as
// it was.
TEST(AtomicOutput, RefusesToReplaceAnythingButARegularFile) {
  namespace fs = std::filesystem;
  const auto dir = test::TempDir();
  ASSERT_EQ(::mkfifo((dir / "pipe").c_str(), 0600), 0);
  fs::create_directories(dir / "folder");
  const bool device = ::mknod((dir / "null").c_str(), S_IFCHR | 0666, ::makedev(1, 3)) == 0;  // as root only
  std::vector<std::pair<fs::path, std::string>> cases = {{dir / "pipe", "a named pipe"}, {dir / "folder", "a folder"}};
  if (device) cases.emplace_back(dir / "null", "a device");
  for (const auto& [path, kind] : cases) {
    ExitCode code{};
    const std::string msg = test::ErrorOf([&] { AtomicOutput out(path, AtomicOutput::kReserve); }, &code);
    EXPECT_EQ(code, ExitCode::kUsage) << path;
    EXPECT_NE(msg.find(kind), std::string::npos) << msg;
  }
  EXPECT_TRUE(fs::is_fifo(dir / "pipe"));
  EXPECT_TRUE(fs::is_directory(dir / "folder"));
  if (device) EXPECT_TRUE(fs::is_character_file(dir / "null"));
  // A symbolic link is replaced by the output; its target is untouched.
  std::ofstream(dir / "target") << "kept";
  fs::create_symlink(dir / "target", dir / "link");
  WriteTextFileAtomic(dir / "link", "new");
  EXPECT_FALSE(fs::is_symlink(dir / "link"));
  EXPECT_EQ(test::Slurp(dir / "link"), "new");
  EXPECT_EQ(test::Slurp(dir / "target"), "kept");
}

}  // namespace
}  // namespace btf
