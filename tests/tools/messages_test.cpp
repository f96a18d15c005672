// What a mistyped command line gets (docs/errors.md): one "<tool>: error: ..." line in the style of
// the other errors, the nearest valid name, where to look; option checks say what the option must
// be in words, not as a C++ condition.
#include <gtest/gtest.h>

#include <string>

#include "tests/test_util.h"

namespace btf {
namespace {

std::string Output(const std::string& command, int expected_code) {
  std::string out;
  EXPECT_EQ(test::RunCommand(command + " 2>&1", &out), expected_code) << command << "\n" << out;
  return out;
}

TEST(Messages, MistypedOptionsAndCommandsGetTheNearestName) {
  const std::string metod = Output(test::Tool("btf-compress") + " in.h5 --metod lpca -o out.h5", 2);
  EXPECT_NE(metod.find("btf-compress: error: unknown option '--metod' (did you mean '--method'?)"), std::string::npos)
      << metod;
  EXPECT_EQ(metod.find("'lpca'"), std::string::npos) << "the unknown option's value is not a second error: " << metod;
  EXPECT_NE(metod.find("see btf-compress --help"), std::string::npos) << metod;
  const std::string comapre = Output(test::Tool("btf-eval") + " comapre a.h5 b.h5", 2);
  EXPECT_NE(comapre.find("did you mean 'compare'?"), std::string::npos) << comapre;
  const std::string foo = Output(test::Tool("btf-eval") + " foo", 2);
  EXPECT_NE(foo.find("compare"), std::string::npos) << foo;  // lists the commands
  const std::string none = Output(test::Tool("btf-eval"), 2);
  EXPECT_NE(none.find("a command is required: one of"), std::string::npos) << none;
  EXPECT_NE(none.find("sweep"), std::string::npos) << none;
}

TEST(Messages, AnOptionQuotedWithItsValueIsNamed) {
  // "--log-epsilon 1" as one argument (a script's quoted variable): not "unknown option
  // '--log-epsilon' (did you mean '--log-epsilon'?)".
  const std::string out = Output(test::Tool("btf-compress") + " in.h5 --method neural '--log-epsilon 1' -o out.h5", 2);
  EXPECT_NE(out.find("btf-compress: error: '--log-epsilon 1' is one argument: give the option and its value as two "
                     "(--log-epsilon 1) or as --log-epsilon=1"),
            std::string::npos)
      << out;
  EXPECT_EQ(out.find("did you mean"), std::string::npos) << out;
}

TEST(Messages, OptionChecksSayWhatTheOptionMustBeInWords) {
  const auto dir = test::TempDir();
  const std::string in = (dir / "in.h5").string();
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1 --lights 0,1 --resolution 4 --samples 1 --quiet -o " + in), 0);
  const std::string out = Output(test::Tool("btf-compress") + " " + in + " --method lpca --lpca-matrix double -o " +
                                  (dir / "c.h5").string(),
                              2);
  EXPECT_NE(out.find("invalid option 'lpca_matrix'"), std::string::npos) << out;
  EXPECT_EQ(out.find("required:"), std::string::npos) << out;
  EXPECT_EQ(out.find("=="), std::string::npos) << out;
}

}  // namespace
}  // namespace btf
