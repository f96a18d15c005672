// A codec decoded at another BTF's directions (libbtf/eval/codec_at_directions.h) and btf-eval
// compare's use of it: the neural codec measured against btf-synth's ground truth at directions it
// was never trained on; a linear codec at its own directions gives the plain figures.
#include "libbtf/eval/codec_at_directions.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/compress/codec_source.h"
#include "libbtf/eval/metrics.h"
#include "libbtf/io/dataset_io.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

std::string Q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

// Smooth, positive values on bonn81 subsets (the log transform of the neural codec needs > -eps).
Dataset SmoothDataset(const Sampling& views, const Sampling& lights, int n) {
  Dataset d(views, lights, n, n, 3);
  for (int v = 0; v < views.size(); ++v)
    for (int l = 0; l < lights.size(); ++l)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x)
          for (int c = 0; c < 3; ++c)
            d.at(v, l, y, x, c) = float(0.2 + 0.5 * std::max(0.0, lights[l].z()) * (1 + 0.3 * views[v].z()) +
                                        0.05 * std::sin(0.7 * x + 1.3 * y + c));
  return d;
}

Sampling Indices(const Sampling& s, int first, int step) {
  std::vector<int> i;
  for (int k = first; k < s.size(); k += step) i.push_back(k);
  return s.Subset(i);
}

// Every value of the source equals Codec::Value at the texel's centre (nearest uv filter) at the
// source's directions, to float rounding.
void ExpectCodecValues(const Codec& codec, const CodecAtDirections& src) {
  std::vector<float> slot(src.slot_size());
  const int H = src.height(), W = src.width(), C = src.channels();
  double worst = 0;
  for (int v = 0; v < src.views().size(); ++v) {
    src.ReadViewSlot(v, slot.data());
    for (int l = 0; l < src.lights().size(); ++l)
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          float want[3];
          codec.Value(Vec2((x + 0.5) / W, 1 - (y + 0.5) / H), src.lights()[l], src.views()[v], want, UvFilter::kNearest);
          for (int c = 0; c < C; ++c) {
            const float got = slot[((std::size_t(l) * H + y) * W + x) * C + c];
            worst = std::max(worst, std::abs(double(got) - want[c]) / (1 + std::abs(double(want[c]))));
          }
        }
  }
  EXPECT_LT(worst, 1e-5) << MethodName(codec.method());
}

TEST(CodecAtDirections, LinearCodecAtItsOwnDirectionsGivesThePlainFigures) {
  const Dataset ref = test::MakeTestDataset(5, 6, 6, 7);
  for (const CodecMethod m : {CodecMethod::kPcaView, CodecMethod::kLpca}) {
    CompressOptions co;
    co.method = m;
    co.components = 2;
    co.clusters = 3;
    const Codec codec = test::CompressDataset(ref, co);
    const CompareSummary plain = Compare({}, *MemorySource(ref), CodecSource(codec, "codec"));
    const CompareSummary at =
        Compare({}, *MemorySource(ref), CodecAtDirections(codec, codec.views(), codec.lights(), "codec"));
    EXPECT_FALSE(plain.test_at_reference_directions);
    ASSERT_GT(plain.rmse, 0) << MethodName(m);
    EXPECT_NEAR(at.rmse, plain.rmse, 1e-6 * plain.rmse) << MethodName(m);
    EXPECT_NEAR(at.max_abs, plain.max_abs, 1e-5 * plain.max_abs) << MethodName(m);
    EXPECT_NEAR(*at.mean_ssim, *plain.mean_ssim, 1e-9) << MethodName(m);
  }
}

TEST(CodecAtDirections, EqualsCodecValueAtTexelCentres) {
  const Sampling bonn = Sampling::Bonn81();
  const Dataset train = SmoothDataset(Indices(bonn, 0, 3), Indices(bonn, 0, 3), 5);
  const Sampling views = Indices(bonn, 1, 9), lights = Indices(bonn, 2, 7);  // none of the trained ones
  for (const CodecMethod m : {CodecMethod::kPcaView, CodecMethod::kLpcaTensor, CodecMethod::kNeural}) {
    CompressOptions co;
    co.method = m;
    co.components = 3;
    co.clusters = 2;
    co.neural.samples = 4096;
    co.neural.steps = 20;
    co.neural.batch = 512;
    const Codec codec = test::CompressDataset(train, co);
    ExpectCodecValues(codec, CodecAtDirections(codec, views, lights, "codec"));
  }
}

TEST(CodecAtDirections, CompareUsesItForCodecsOnly) {
  const Sampling bonn = Sampling::Bonn81();
  const Dataset train = SmoothDataset(Indices(bonn, 0, 2), Indices(bonn, 0, 2), 4);
  const Dataset held = SmoothDataset(Indices(bonn, 1, 2), Indices(bonn, 1, 2), 4);
  CompressOptions co;
  co.method = CodecMethod::kPcaView;
  co.components = 2;
  const Codec codec = test::CompressDataset(train, co);
  const CompareSummary s = Compare({}, *MemorySource(held, "truth"), CodecSource(codec, "codec"));
  EXPECT_TRUE(s.test_at_reference_directions);
  EXPECT_EQ(s.views, held.num_views());
  EXPECT_TRUE(s.ToJson()["test_decoded_at_reference_directions"].get<bool>());
  EXPECT_NE(s.Report().find("test decoded at the reference's directions"), std::string::npos);
  // The same figure as comparing with the adapter itself.
  const CompareSummary direct =
      Compare({}, *MemorySource(held, "truth"), CodecAtDirections(codec, held.views(), held.lights(), "codec"));
  EXPECT_EQ(s.rmse, direct.rmse);
  // Datasets sampled on other directions are refused (bad input), as before.
  EXPECT_THROW(Compare({}, *MemorySource(held), *MemorySource(train)), Error);
  // Other texel counts are refused for codecs too.
  const Dataset small = SmoothDataset(Indices(bonn, 1, 2), Indices(bonn, 1, 2), 3);
  EXPECT_THROW(Compare({}, *MemorySource(small), CodecSource(codec, "codec")), Error);
}

// btf-synth twill at 16 x 16 texels: the neural codec trained on every other bonn81 view and light
// (41 x 41, a short training: 512 steps), then measured against btf-synth's truth at the other
// 40 x 40 (never trained on). Bound: the held-out relative L2 error at most 1.5 times the error at
// the trained directions (measured 0.863 against 0.861: the twill's highlights dominate the linear
// error of so short a training) and below 1 (better than decoding zeros).
TEST(BtfEvalCli, NeuralCodecAtHeldOutDirectionsAgainstTruth) {
  const auto dir = test::TempDir();
  std::string even, odd;
  for (int i = 0; i < 81; ++i) {
    std::string& s = i % 2 ? odd : even;
    s += (s.empty() ? "" : ",") + std::to_string(i);
  }
  const std::string synth = test::Tool("btf-synth") + " btf --model irawan2006 --preset twill --directions bonn81 "
                                                      "--resolution 16 --quiet";
  ASSERT_EQ(test::RunCommand(synth + " --views " + even + " --lights " + even + " -o " + Q(dir / "train.h5")), 0);
  ASSERT_EQ(test::RunCommand(synth + " --views " + odd + " --lights " + odd + " -o " + Q(dir / "held.h5")), 0);
  ASSERT_EQ(test::RunCommand(test::Tool("btf-compress") + " " + Q(dir / "train.h5") +
                             " --method neural --neural-samples 262144 --neural-epochs 8 -o " + Q(dir / "n.h5") + " -q"),
            0);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + Q(dir / "train.h5") + " " + Q(dir / "n.h5") +
                                 " --json --no-ssim -q",
                             &out),
            0);
  const auto trained = nlohmann::json::parse(out);
  EXPECT_FALSE(trained["test_decoded_at_reference_directions"].get<bool>());
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + Q(dir / "held.h5") + " " + Q(dir / "n.h5") +
                                 " --json --no-ssim -q",
                             &out),
            0);
  const auto held = nlohmann::json::parse(out);
  EXPECT_TRUE(held["test_decoded_at_reference_directions"].get<bool>());
  EXPECT_EQ(held["shape"]["views"], 40);
  const double rel_trained = trained["rel_l2"].get<double>(), rel_held = held["rel_l2"].get<double>();
  RecordProperty("rel_l2_trained", fmt::format("{:.4f}", rel_trained));
  RecordProperty("rel_l2_held_out", fmt::format("{:.4f}", rel_held));
  EXPECT_LT(rel_held, 1.5 * rel_trained) << "trained " << rel_trained << " held out " << rel_held;
  EXPECT_LT(rel_held, 1.0) << "trained " << rel_trained << " held out " << rel_held;
  // The text report says how the test was decoded; two datasets on other directions are refused.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + Q(dir / "held.h5") + " " + Q(dir / "n.h5") +
                                 " --no-ssim -q",
                             &out),
            0);
  EXPECT_NE(out.find("test decoded at the reference's directions"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + Q(dir / "held.h5") + " " + Q(dir / "train.h5") +
                             " 2>&1",
                             &out),
            3);
  EXPECT_NE(out.find("compare BTFs sampled on the same directions"), std::string::npos) << out;
}

}  // namespace
}  // namespace btf
