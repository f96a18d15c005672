// Outputs never destroy inputs (docs/errors.md): every tool refuses, with exit 2 and before any
// work, an output that is one of its inputs by any name, and an output path that holds something
// other than a regular file; the input is left byte for byte as it was.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

struct Refusal {
  std::string command;  // without the output
  fs::path output;      // an input, by some name
  fs::path input;       // the file that must survive
};

// Runs each command onto its input: exit 2, a message naming the output, the input unchanged.
void ExpectRefused(const std::vector<Refusal>& cases) {
  for (const Refusal& r : cases) {
    const std::string before = test::Slurp(r.input);
    std::string out;
    EXPECT_EQ(test::RunCommand(r.command + " " + r.output.string() + " --quiet 2>&1", &out), 2) << r.command << "\n" << out;
    EXPECT_NE(out.find("destroy the input"), std::string::npos) << r.command << "\n" << out;
    EXPECT_NE(out.find(r.output.string()), std::string::npos) << out;
    EXPECT_EQ(test::Slurp(r.input), before) << r.command;
  }
}

TEST(Outputs, AnOutputOverAnInputIsRefusedByEveryTool) {
  const fs::path dir = test::TempDir();
  const std::string data = (dir / "a.h5").string(), codec = (dir / "c.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1 --lights 0,1 --resolution 4 --samples 1 --quiet -o " + data), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + data + " --method pca-view -c 1 --quiet -o " + codec), 0);
  fs::create_hard_link(data, dir / "hard.h5");
  fs::create_symlink(data, dir / "soft.h5");
  std::ofstream(dir / "dirs.txt") << "0 0\n30 90\n";
  const std::string compress = test::Tool("btf-compress") + " " + data + " --method pca-view -c 1 -o";
  ExpectRefused({
      {compress, data, data},
      {compress, dir / "." / "a.h5", data},
      {compress, dir / "hard.h5", data},
      {compress, dir / "soft.h5", data},
      {test::Tool("btf-compress") + " decode " + codec + " -o", codec, codec},
      {test::Tool("btf-convert") + " " + data + " -o", data, data},
      {test::Tool("btf-synth") + " btf --directions " + (dir / "dirs.txt").string() + " --resolution 2 --samples 1 -o",
       dir / "dirs.txt", dir / "dirs.txt"},
  });
}

TEST(Outputs, RegistrationOutputsOverItsPhotosManifestOrBoardAreRefused) {
  const fs::path dir = test::TempDir() / "photos";
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " photos --views 0 --lights 0 --width 160 --height 120 --quiet -o " +
                             dir.string()),
            0);
  const auto manifest = nlohmann::json::parse(test::Slurp(dir / "manifest.json"));
  const fs::path photo = dir / manifest.at("photos").at(0).at("file").get<std::string>();
  const fs::path board = dir / manifest.at("board").get<std::string>();
  const std::string run = test::Tool("btf-register") + " run " + (dir / "manifest.json").string() + " --resolution 8";
  ExpectRefused({
      {run + " -o", photo, photo},
      {run + " -o", dir / "manifest.json", dir / "manifest.json"},
      {run + " -o " + (dir.parent_path() / "d.h5").string() + " --report", photo, photo},
      {run + " -o " + (dir.parent_path() / "d.h5").string() + " --contact-sheet", board, board},
      {test::Tool("btf-register") + " calibrate " + photo.string() + " --board " + board.string() + " -o", board, board},
  });
  EXPECT_FALSE(fs::exists(dir.parent_path() / "d.h5"));
}

// Output paths holding a folder, a named pipe or (as root) a device are refused before the work
// and left as they were.
TEST(Outputs, OnlyARegularFileIsReplaced) {
  const fs::path dir = test::TempDir();
  const std::string data = (dir / "a.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1 --lights 0,1 --resolution 4 --samples 1 --quiet -o " + data), 0);
  ASSERT_EQ(::mkfifo((dir / "pipe").c_str(), 0600), 0);
  fs::create_directories(dir / "folder");
  for (const std::string name : {"pipe", "folder"}) {
    std::string out;
    EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + data + " --method pca-view -c 1 --quiet -o " +
                                   (dir / name).string() + " 2>&1",
                               &out),
              2)
        << out;
    EXPECT_NE(out.find("only a regular file is replaced"), std::string::npos) << out;
  }
  EXPECT_TRUE(fs::is_fifo(dir / "pipe"));
  EXPECT_TRUE(fs::is_empty(dir / "folder"));
}

// Outputs are checked before the work, by one rule for every tool: a file output onto a folder is
// refused (exit 2), an output in a folder that does not exist too (exit 4: create it first), for
// file and folder outputs alike; nothing is created.
TEST(Outputs, AreCheckedBeforeTheWorkByOneRule) {
  const fs::path dir = test::TempDir();
  const std::string data = (dir / "a.h5").string(), codec = (dir / "c.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1 --lights 0,1 --resolution 4 --samples 1 --quiet -o " + data), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + data + " --method lpca -k 2 -c 1 --quiet -o " + codec), 0);
  fs::create_directories(dir / "folder");
  const std::string missing = (dir / "missing" / "x").string();
  struct Case {
    std::string command;
    int code;
  };
  for (const Case& c : std::vector<Case>{
           {test::Tool("btf-compress") + " decode " + codec + " -o " + (dir / "folder").string(), 2},
           {test::Tool("btf-compress") + " decode " + codec + " -o " + missing, 4},
           {test::Tool("btf-compress") + " export " + codec + " -o " + missing, 4},
           {test::Tool("btf-convert") + " " + data + " -o " + (dir / "folder").string(), 2},
           {test::Tool("btf-synth") + " photos --views 0 --lights 0 -o " + missing, 4},
           {test::Tool("btf-eval") + " render " + codec + " -o " + (dir / "folder").string(), 2},
       }) {
    std::string out;
    EXPECT_EQ(test::RunCommand(c.command + " --quiet 2>&1", &out), c.code) << c.command << "\n" << out;
  }
  EXPECT_FALSE(fs::exists(dir / "missing"));
  EXPECT_TRUE(fs::is_empty(dir / "folder"));
}

}  // namespace
}  // namespace btf
