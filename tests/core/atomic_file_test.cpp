#include "libbtf/core/atomic_file.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace btf
