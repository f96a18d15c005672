// The neural codec through the tools: btf-synth's ground truth, btf-compress --method neural,
// btf-info on the codec, btf-eval compare of the codec against the truth, btf-compress decode.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace btf {
namespace {

TEST(NeuralTools, CompressInfoCompareAndDecode) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/";
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1,7,20 --lights 0,3,9,20,40 --resolution 8 "
                             "--samples 1 --quiet -o " + d + "gt.h5"),
            0);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "gt.h5 --method neural --neural-latent 4 "
                                 "--neural-hidden 16,16 --neural-samples 4096 --neural-steps 200 --neural-batch 256 "
                                 "-o " + d + "n.h5 --json --quiet",
                             &out),
            0)
      << out;
  const auto s = nlohmann::json::parse(out);
  EXPECT_EQ(s["method"], "neural");
  EXPECT_EQ(s["options"]["neural_hidden"], nlohmann::json::array({16, 16}));
  EXPECT_EQ(s["neural"]["steps"], 200);
  EXPECT_LT(s["neural"]["last_loss"].get<double>(), s["neural"]["first_loss"].get<double>());
  const double rel = s["relative_error"].get<double>();
  EXPECT_GT(rel, 0);
  EXPECT_LT(rel, 1);

  ASSERT_EQ(test::RunCommand(test::Tool("btf-info") + " " + d + "n.h5 --json", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  EXPECT_EQ(info["method"], "neural");
  EXPECT_EQ(info["latent"], 4);
  EXPECT_EQ(info["hidden"], nlohmann::json::array({16, 16}));
  EXPECT_EQ(info["stored_bytes"], s["codec_bytes"]);

  // btf-eval decodes the codec itself: the same error as the compressor measured.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + d + "gt.h5 " + d + "n.h5 --json --quiet", &out), 0)
      << out;
  EXPECT_NEAR(nlohmann::json::parse(out)["rel_l2"].get<double>(), rel, 1e-6 * rel);

  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " decode " + d + "n.h5 -o " + d + "dec.h5 --quiet"), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + d + "gt.h5 " + d + "dec.h5 --json --quiet", &out), 0);
  EXPECT_NEAR(nlohmann::json::parse(out)["rel_l2"].get<double>(), rel, 1e-6 * rel);

  // Refused with a usage error: an error target, a zero hidden width.
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "gt.h5 --method neural --error 0.1 -o " + d +
                             "x.h5 --quiet 2>/dev/null"),
            2);
  EXPECT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + d + "gt.h5 --method neural --neural-hidden 8,0 -o " + d +
                             "x.h5 --quiet 2>/dev/null"),
            2);
}

}  // namespace
}  // namespace btf
