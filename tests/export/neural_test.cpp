// Renderer export of the neural codec (libbtf/export/neural.h, layout neural-mlp): the reference
// decoder of the folder against the codec's own decoder, for both latent storages, with Fourier
// features and every activation; the files and manifest; a hand-built export decoded as
// docs/format.md says; refusals; the btf-compress export command.
#include "libbtf/export/neural.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "libbtf/compress/compress.h"
#include "libbtf/core/error.h"
#include "libbtf/export/neural_reference_decoder.h"
#include "libbtf/export/schneider.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"
#include "tests/test_util.h"

namespace btf {
namespace {

constexpr int kW = 6, kH = 5;

// 19 views x 19 lights of 6 x 5 texels, 3 channels: per texel an albedo and a glossy lobe around
// the mirror direction of wi, all values >= 0.03 (the codec's log domain).
const Dataset& Truth() {
  static const Dataset d = [] {
    Dataset ds(test::BonnSubset(19), test::BonnSubset(19, 4), kH, kW, 3);
    for (int v = 0; v < ds.num_views(); ++v)
      for (int l = 0; l < ds.num_lights(); ++l) {
        const Vec3 wi = ds.lights()[l].normalized(), wo = ds.views()[v].normalized();
        const Vec3 mirror(-wi.x(), -wi.y(), wi.z());
        float* img = ds.image(v, l).data();
        for (int t = 0; t < kW * kH; ++t) {
          const double gloss = std::pow(std::max(0.0, mirror.dot(wo)), 4 + 3 * (t % 4));
          for (int c = 0; c < 3; ++c)
            img[t * 3 + c] = float(0.03 + 0.1 * (1 + (t * 7 + c * 3) % 5) + (0.5 + 0.2 * c) * gloss * (t % 3));
        }
      }
    return ds;
  }();
  return d;
}

Codec NeuralCodec(const std::string& latent_storage, int fourier, int latent = 6) {
  CompressOptions o;
  o.method = CodecMethod::kNeural;
  o.seed = 3;
  o.neural.latent = latent;
  o.neural.hidden = {16, 16};
  o.neural.fourier = fourier;
  o.neural.latent_storage = latent_storage;
  o.neural.samples = 1 << 14;
  o.neural.batch = 512;
  o.neural.steps = 150;
  return test::CompressDataset(Truth(), o);
}

// The codec with its decoder's activation replaced (same parameters): every activation the file
// format allows goes through the export, though btf-compress trains SiLU only.
Codec WithActivation(Codec codec, Activation a) {
  NeuralCodecModel& m = CodecBuilder::neural(codec);
  NeuralNetShape shape = m.net.shape();
  shape.activation = a;
  NeuralNet net(shape, 0);
  net.parameters() = m.net.parameters();
  m.net = net;
  return codec;
}

// The codec's own decoder output y (log domain, float32) at texel t: NeuralCodecModel::Evaluate
// with the stored latent, as Codec::Value with nearest texel computes it before exp(y) - eps.
std::vector<float> CodecOutputs(const Codec& codec, std::size_t t, const Vec3& wi, const Vec3& wo) {
  const NeuralCodecModel& m = codec.neural();
  const Vec3 i = wi.normalized(), o = wo.normalized();
  const float i3[3] = {float(i.x()), float(i.y()), float(i.z())}, o3[3] = {float(o.x()), float(o.y()), float(o.z())};
  std::vector<float> y(std::size_t(codec.channels()));
  m.Evaluate(
      1, [&](Eigen::Index) { return m.latents.col(Eigen::Index(t)).data(); }, [&](Eigen::Index) { return i3; },
      [&](Eigen::Index) { return o3; }, y.data());
  return y;
}

// The reference decoder of the export against the codec at random (texel, wi, wo) over the whole
// hemispheres (the neural decoder is defined everywhere, not only at the sampled directions).
// The latents are the codec's own, bit for bit. The decoder outputs y differ by the codec's float32
// arithmetic only (the reference works in double): a dot product of n terms in float32 is off by
// at most about n 2^-24 sum |w_i a_i|, here n <= 17 terms per neuron and sum |w a| = O(1..10), so
// |dy| stays below 1e-5 (measured: about 1e-6); values exp(y) - eps then agree to the same
// relative size, |dv| <= 1e-5 (v + eps) + 1e-6 (float rounding of the values).
void ExpectReferenceMatchesCodec(const Codec& codec, const std::string& what) {
  const auto dir = test::TempDir() / "export";
  const NeuralExportSummary s = ExportNeural(codec, dir);
  const NeuralReferenceDecoder ref(dir);
  ASSERT_EQ(ref.latent(), codec.neural().latent) << what;
  EXPECT_EQ(s.latent_layers, (ref.latent() + 3) / 4);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      for (int j = 0; j < ref.latent(); ++j)
        ASSERT_EQ(ref.latents(x, y)[j], codec.neural().latents(j, Eigen::Index(y) * kW + x)) << what << " latent " << j;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u01(0, 1);
  double worst_y = 0, worst_v = 0;
  for (int i = 0; i < 2000; ++i) {
    const int x = int(u01(rng) * kW) % kW, y = int(u01(rng) * kH) % kH;
    const Vec3 wi = HemisphereFromSquare(Vec2(u01(rng), u01(rng))), wo = HemisphereFromSquare(Vec2(u01(rng), u01(rng)));
    const std::vector<double> yr = ref.Outputs(x, y, wi, wo);
    const std::vector<float> yc = CodecOutputs(codec, std::size_t(y) * kW + x, wi, wo);
    float a[3], b[3];
    ref.Value(x, y, wi, wo, a);
    codec.Value(Vec2((x + 0.5) / kW, 1 - (y + 0.5) / kH), wi, wo, b, UvFilter::kNearest);
    for (int c = 0; c < 3; ++c) {
      const double dy = std::abs(yr[std::size_t(c)] - yc[std::size_t(c)]);
      ASSERT_LE(dy, 1e-5) << what << " query " << i << " channel " << c;
      const double dv = std::abs(double(a[c]) - b[c]);
      ASSERT_LE(dv, 1e-5 * (std::abs(b[c]) + codec.log_epsilon()) + 1e-6) << what << " query " << i << " channel " << c;
      worst_y = std::max(worst_y, dy);
      worst_v = std::max(worst_v, dv / (std::abs(b[c]) + codec.log_epsilon()));
    }
  }
  std::cout << what << ": worst |dy| " << worst_y << ", worst |dv| / (v + eps) " << worst_v << "\n";
  // The comparison is not vacuous: float32 and double differ somewhere.
  EXPECT_GT(worst_y, 0) << what;
}

TEST(NeuralExport, ReferenceDecoderMatchesTheCodecWithUint8Latents) {
  ExpectReferenceMatchesCodec(NeuralCodec("uint8", 0), "uint8");
}
// Half latents, Fourier features (2 octaves), a latent count that fills its last texture layer
// partly (5 = 4 + 1).
TEST(NeuralExport, ReferenceDecoderMatchesTheCodecWithHalfLatentsAndFourierFeatures) {
  ExpectReferenceMatchesCodec(NeuralCodec("half", 2, 5), "half, fourier 2");
}
TEST(NeuralExport, ReferenceDecoderMatchesTheCodecForEveryActivation) {
  const Codec codec = NeuralCodec("uint8", 1);
  for (Activation a : {Activation::kRelu, Activation::kLeakyRelu, Activation::kSoftplus})
    ExpectReferenceMatchesCodec(WithActivation(codec, a), std::string(ActivationName(a)));
}

TEST(NeuralExport, ManifestAndFilesFollowTheLayout) {
  const auto dir = test::TempDir() / "export";
  const Codec codec = NeuralCodec("uint8", 0);
  const NeuralExportSummary s = ExportNeural(codec, dir);
  std::ifstream in(dir / "manifest.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["format"], "libbtf-schneider-export");
  EXPECT_EQ(j["format_version"], "2.2.0");
  EXPECT_EQ(j["layout"], "neural-mlp");
  EXPECT_EQ(j["latents"]["layers"], 2);
  EXPECT_EQ(j["latents"]["scale"].size(), 6u);
  EXPECT_EQ(j["encoding"]["width"], 6);  // wi.xy, wo.xy, half vector xy
  EXPECT_EQ(j["output"]["transform"], "log");
  EXPECT_EQ(j["output"]["epsilon"].get<double>(), codec.log_epsilon());
  // 6 latents in 2 RGBA layers of 6 x 5; decoder (12 -> 16 -> 16 -> 3) with a bias per neuron.
  EXPECT_EQ(std::filesystem::file_size(dir / "latents.u8"), 2u * kH * kW * 4);
  const std::uint64_t params = 16 * 13 + 16 * 17 + 3 * 17;
  EXPECT_EQ(s.parameters, std::int64_t(params));
  EXPECT_EQ(std::filesystem::file_size(dir / "decoder.f32"), params * 4);
  EXPECT_EQ(j["decoder"]["layers"][2]["offset"], 16 * 13 + 16 * 17);
  EXPECT_EQ(j["decoder"]["layers"][2]["first_row"], 32);
  EXPECT_EQ(j["decoder"]["layers"][2]["activation"], "linear");
  EXPECT_EQ(j["decoder"]["texture"]["width"], 5);  // ceil(17 / 4)
  EXPECT_EQ(j["decoder"]["texture"]["height"], 35);
  EXPECT_TRUE(std::filesystem::exists(dir / "btf_neural.glsl"));
  // The other layouts' decoders refuse it, naming the layout.
  try {
    SchneiderReferenceDecoder{dir};
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("neural-mlp"), std::string::npos);
  }
  std::filesystem::resize_file(dir / "decoder.f32", 8);
  EXPECT_THROW(NeuralReferenceDecoder{dir}, Error);
}

TEST(NeuralExport, RefusesOtherCodecsAndTheOtherExportsRefuseNeuralCodecs) {
  CompressOptions o;
  o.method = CodecMethod::kPcaView;
  o.components = 2;
  const Codec pca = test::CompressDataset(Truth(), o);
  try {
    ExportNeural(pca, test::TempDir() / "x");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
    EXPECT_NE(std::string(e.what()).find("--format sattler"), std::string::npos);
  }
  try {
    ExportSchneider({}, NeuralCodec("uint8", 0), test::TempDir() / "y");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
    EXPECT_NE(std::string(e.what()).find("--format neural"), std::string::npos);
  }
}

// A 1 x 1 texel, 1-channel export built byte by byte from docs/format.md (layout neural-mlp):
// one u8 latent (scale 0.5, bias -1, code 4: z = 1), no half vector, no Fourier features, a
// hidden ReLU layer of 2 and a linear output.
TEST(NeuralExport, HandBuiltExportDecodesAsDocumented) {
  const auto dir = test::TempDir() / "hand";
  std::filesystem::create_directories(dir);
  const nlohmann::json m = {
      {"format", "libbtf-schneider-export"}, {"format_version", "2.2.0"}, {"layout", "neural-mlp"},
      {"texture", {{"width", 1}, {"height", 1}, {"channels", 1}}},
      {"values", {{"units", "brdf_per_sr"}, {"cos_theta_i_included", false}}},
      {"latents", {{"file", "latents.u8"}, {"count", 1}, {"storage", "u8"}, {"layers", 1}, {"scale", {0.5}}, {"bias", {-1.0}}}},
      {"encoding", {{"half_vector", false}, {"fourier", 0}, {"width", 4}}},
      {"decoder",
       {{"file", "decoder.f32"},
        {"layers", {{{"inputs", 5}, {"outputs", 2}, {"offset", 0}, {"activation", "relu"}},
                    {{"inputs", 2}, {"outputs", 1}, {"offset", 12}, {"activation", "linear"}}}}}},
      {"output", {{"transform", "log"}, {"epsilon", 0.01}}}};
  std::ofstream(dir / "manifest.json") << m.dump();
  const unsigned char latents[4] = {4, 0, 0, 0};
  std::ofstream(dir / "latents.u8", std::ios::binary).write(reinterpret_cast<const char*>(latents), 4);
  // Layer 0 rows (w_z, w_wix, w_wiy, w_wox, w_woy, b): h0 = relu(z + 2 wi.x + 3 wo.y + 0.25),
  // h1 = relu(-z + wi.y - 1) (0 here); layer 1: y = 0.5 h0 - 4 h1 + 0.125.
  const float decoder[15] = {1, 2, 0, 0, 3, 0.25f, -1, 0, 1, 0, 0, -1, 0.5f, -4, 0.125f};
  std::ofstream(dir / "decoder.f32", std::ios::binary).write(reinterpret_cast<const char*>(decoder), sizeof(decoder));
  const NeuralReferenceDecoder ref(dir);
  float out = 0;
  // wi = (0.6, 0, 0.8), wo = (0, 0.6, 0.8): h0 = 1 + 1.2 + 1.8 + 0.25 = 4.25, y = 2.25.
  ref.Value(0, 0, Vec3(0.6, 0, 0.8), Vec3(0, 0.6, 0.8), &out);
  EXPECT_NEAR(out, std::exp(2.25) - 0.01, 1e-5);
  // Directions are normalised first: the same at twice the length.
  ref.Value(0, 0, Vec3(1.2, 0, 1.6), Vec3(0, 1.2, 1.6), &out);
  EXPECT_NEAR(out, std::exp(2.25) - 0.01, 1e-5);
}

TEST(NeuralExport, BtfCompressExportWritesTheNeuralLayoutByDefault) {
  const auto dir = test::TempDir();
  WriteCodec(dir / "n.h5", NeuralCodec("uint8", 0));
  const std::string exp = test::Tool("btf-compress") + " export " + (dir / "n.h5").string();
  std::string out;
  ASSERT_EQ(test::RunCommand(exp + " -o " + (dir / "e").string() + " --json --quiet", &out), 0) << out;
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["layout"], "neural-mlp");
  EXPECT_EQ(j["latent"], 6);
  EXPECT_TRUE(std::filesystem::exists(dir / "e" / "btf_neural.glsl"));
  EXPECT_NO_THROW(NeuralReferenceDecoder{dir / "e"});
  // The options of the other formats are refused (exit 2), and so is another format.
  EXPECT_EQ(test::RunCommand(exp + " --storage f16 -o " + (dir / "f").string() + " --quiet 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(exp + " --view-grid 8 -o " + (dir / "f").string() + " --quiet 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(exp + " --format sattler -o " + (dir / "f").string() + " --quiet 2>/dev/null"), 2);
  EXPECT_FALSE(std::filesystem::exists(dir / "f"));
}

}  // namespace
}  // namespace btf
