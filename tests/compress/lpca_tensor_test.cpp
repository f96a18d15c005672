// Codec method lpca-tensor (libbtf/compress/lpca_tensor.h): error against its own rate-distortion
// settings, monotonicity in the byte budget, decoders, the codec file, thread independence,
// damaged files; --bytes for the other methods.
#include "libbtf/compress/lpca_tensor.h"

#include <gtest/gtest.h>
#include <hdf5.h>
#include <omp.h>

#include <cmath>
#include <functional>
#include <random>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/core/error.h"
#include "libbtf/io/hdf5.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

ExitCode ExitCodeOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.code();
  }
  return ExitCode::kOk;
}

// Two materials (texels of the left and right half), each a sum of 4 smooth separable
// view x light terms with per-texel amplitudes, plus 1 % noise: LPCA finds the two materials,
// their Eigen-ABRDFs are close to low rank over (views, lights x channels), the noise is not.
Dataset TwoMaterials(int views = 9, int lights = 10, int h = 12, int w = 12) {
  Dataset d = test::MakeTestDataset(views, lights, h, w, 3);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> noise(0, 0.01);
  std::vector<double> amp(std::size_t(h) * w * 4);
  for (auto& a : amp) a = 0.5 + u(rng);
  for (int v = 0; v < views; ++v)
    for (int l = 0; l < lights; ++l)
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          for (int c = 0; c < 3; ++c) {
            const std::size_t t = std::size_t(y) * w + x;
            const int mat = x < w / 2 ? 0 : 1;
            double val = 0.2;
            for (int m = 0; m < 4; ++m)
              val += amp[t * 4 + m] * (0.6 + 0.4 * std::cos(0.5 * (m + 1) * v + mat)) *
                     (0.5 + 0.3 * std::sin(0.4 * (m + 2) * l + 0.7 * c + 2 * mat));
            d.image(v, l).data()[t * 3 + c] = static_cast<float>(val + noise(rng));
          }
  return d;
}

CompressOptions Tensor(int k = 2, int c = 6) {
  CompressOptions o;
  o.method = CodecMethod::kLpcaTensor;
  o.clusters = k;
  o.components = c;
  return o;
}

double DecodedError(const Dataset& d, const Codec& c) {
  ErrorStats e;
  const Dataset back = c.DecodeAll();
  e.Add(d.data().data(), back.data().data(), d.size());
  return e.RelativeL2().value();
}

void Delete(const h5::File& f, const char* name) { ASSERT_GE(H5Ldelete(f.id(), name, H5P_DEFAULT), 0) << name; }

TEST(LpcaTensor, ErrorTargetIsMetWithFewerBytesThanTheLpcaItFactorises) {
  const Dataset d = TwoMaterials();
  CompressOptions lo = Tensor();
  lo.method = CodecMethod::kLpca;
  CompressSummary ls;
  test::CompressDataset(d, lo, &ls);
  for (int bits : {16, 8}) {
    for (double target : {0.05, 0.02}) {
      CompressOptions o = Tensor();
      o.tensor.quant_bits = bits;
      o.target_error = target;
      CompressSummary s;
      const Codec c = test::CompressDataset(d, o, &s);
      EXPECT_EQ(s.method, "lpca-tensor");
      ASSERT_LT(s.lpca_stage_error, target) << "the test needs a target above the LPCA stage's error";
      // The measured error is held to the target (the compressor re-factorises while it is above).
      EXPECT_LE(s.relative_error, target) << bits << " " << target;
      // The summary's error is the decoded codec's (both sums in double over the same floats).
      EXPECT_NEAR(s.relative_error, DecodedError(d, c), 1e-9);
      EXPECT_EQ(s.codec_bytes, c.StoredBytes());
      EXPECT_EQ(s.tensor_terms, int(c.lpca_tensor().terms()));
      EXPECT_GT(s.tensor_terms, 0);
      // Same clustering, factorised and quantised: smaller than the float LPCA.
      EXPECT_LT(s.codec_bytes, ls.codec_bytes) << bits << " " << target;
    }
  }
  // A looser target never needs more terms.
  CompressOptions a = Tensor(), b = Tensor();
  a.target_error = 0.05, b.target_error = 0.02;
  CompressSummary sa, sb;
  test::CompressDataset(d, a, &sa);
  test::CompressDataset(d, b, &sb);
  EXPECT_LE(sa.tensor_terms, sb.tensor_terms);
  EXPECT_LT(sa.tensor_terms, sb.tensor_terms);  // the data has error between the two to trade
}

TEST(LpcaTensor, MoreBytesNeverGiveALargerError) {
  const Dataset d = TwoMaterials();
  CompressSummary base;
  CompressOptions probe = Tensor();
  probe.target_error = 0.5;  // a few terms, just to learn the fixed and per-term sizes
  const Codec p = test::CompressDataset(d, probe, &base);
  const std::uint64_t fixed = p.lpca_tensor().FixedBytes(std::size_t(d.height()) * d.width());
  const std::uint64_t term = p.lpca_tensor().TermBytes();
  double previous = 2;
  int previous_terms = -1;
  for (int n : {0, 1, 2, 4, 8, 16, 32, 64, 128}) {
    CompressOptions o = Tensor();
    o.max_bytes = fixed + n * term + term / 2;  // room for n terms, not n + 1
    CompressSummary s;
    test::CompressDataset(d, o, &s);
    EXPECT_LE(s.codec_bytes, o.max_bytes) << n;
    EXPECT_LE(s.tensor_terms, n);
    EXPECT_GE(s.tensor_terms, previous_terms);
    // Terms are added in order of predicted error reduction; each term's own 16-bit
    // quantisation error (~1e-5 of its size) is far below what it adds, so the measured
    // error falls too: no tolerance is needed.
    EXPECT_LE(s.relative_error, previous) << n;
    previous = s.relative_error;
    previous_terms = s.tensor_terms;
  }
  // The budget below the fixed part is refused, naming it.
  CompressOptions o = Tensor();
  o.max_bytes = fixed - 1;
  EXPECT_EQ(ExitCodeOf([&] { test::CompressDataset(d, o); }), ExitCode::kUsage);
}

TEST(LpcaTensor, DecodersAgreeWithTheViewSlot) {
  const Dataset d = TwoMaterials(5, 6, 6, 8);
  CompressOptions o = Tensor(2, 4);
  o.target_error = 0.03;
  const Codec c = test::CompressDataset(d, o);
  // The slot is summed in float (terms, then LPCA's weighted rows), the others in double: they
  // agree to float rounding of sums of values ~1 (a few ulps x terms).
  constexpr double kTol = 2e-5;
  test::ExpectDecodersAgreeWithViewSlot(c, kTol, kTol, {{0, 0}, {3, 0}, {7, 0}, {0, 5}, {3, 5}, {7, 5}});
}

TEST(LpcaTensor, CodecFileRoundTripsExactly) {
  const Dataset d = TwoMaterials();
  for (int bits : {8, 16}) {
    CompressOptions o = Tensor();
    o.tensor.quant_bits = bits;
    o.target_error = 0.03;
    const Codec c = test::CompressDataset(d, o);
    const auto path = test::TempDir() / "t.h5";
    WriteCodec(path, c);
    const Codec r = ReadCodec(path);
    EXPECT_EQ(r.method(), CodecMethod::kLpcaTensor);
    EXPECT_EQ(r.StoredBytes(), c.StoredBytes());
    EXPECT_EQ(c.DecodeAll().data(), r.DecodeAll().data());  // the same codes dequantise to the same floats
    const auto j = r.Describe();
    EXPECT_EQ(j["method"], "lpca-tensor");
    EXPECT_EQ(j["quant_bits"], bits);
    EXPECT_EQ(j["factor_terms"], c.lpca_tensor().terms());
    // Codes of 8 bits take one byte each in the file: the file is not far above StoredBytes.
    EXPECT_LT(std::filesystem::file_size(path), c.StoredBytes() + 64 * 1024) << bits;
  }
}

TEST(LpcaTensor, ResultsDoNotDependOnTheThreadCount) {
  const Dataset d = TwoMaterials();
  CompressOptions o = Tensor();
  o.target_error = 0.03;
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const Codec one = test::CompressDataset(d, o);
  const Dataset a = one.DecodeAll();
  omp_set_num_threads(2);
  const Codec two = test::CompressDataset(d, o);
  const Dataset b = two.DecodeAll();
  omp_set_num_threads(saved);
  EXPECT_EQ(one.lpca_tensor().ranks, two.lpca_tensor().ranks);
  EXPECT_EQ(one.lpca_tensor().u_codes, two.lpca_tensor().u_codes);
  EXPECT_EQ(one.lpca_tensor().w_codes, two.lpca_tensor().w_codes);
  EXPECT_EQ(one.lpca_tensor().weight_codes, two.lpca_tensor().weight_codes);
  EXPECT_EQ(a.data(), b.data());
  // The same file bytes apart from the creation time: compare the decoded files' content instead.
  const auto dir = test::TempDir();
  WriteCodec(dir / "1.h5", one);
  WriteCodec(dir / "2.h5", two);
  EXPECT_EQ(ReadCodec(dir / "1.h5").DecodeAll().data(), ReadCodec(dir / "2.h5").DecodeAll().data());
}

TEST(LpcaTensor, DamagedCodecFilesAreRefusedNamingFileAndItem) {
  const Dataset d = TwoMaterials(4, 5, 6, 6);
  CompressOptions o = Tensor(2, 3);
  o.tensor.quant_bits = 8;
  o.target_error = 0.05;
  const Codec c = test::CompressDataset(d, o);
  const auto dir = test::TempDir();
  WriteCodec(dir / "c.h5", c);
  const std::size_t R = c.lpca_tensor().terms();
  ASSERT_GT(R, 2u);
  auto expect_refused = [&](const std::function<void(const h5::File&)>& damage, const std::string& words) {
    std::filesystem::copy_file(dir / "c.h5", dir / "bad.h5", std::filesystem::copy_options::overwrite_existing);
    {
      const h5::File f = h5::File::OpenForUpdate(dir / "bad.h5");
      damage(f);
    }
    try {
      ReadCodec(dir / "bad.h5");
      ADD_FAILURE() << "accepted: " << words;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput);
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.h5"), std::string::npos) << e.what();
    }
  };
  expect_refused(
      [&](const h5::File& f) {
        std::vector<std::int32_t> r = f.ReadInts("/codec/lpca_tensor/ranks");
        std::size_t i = 0;
        while (r[i] >= 4) ++i;  // a function below the largest rank (min(views, lights x channels) = 4)
        r[i] += 1;              // one term more than the factor arrays hold
        Delete(f, "/codec/lpca_tensor/ranks");
        f.WriteInts("/codec/lpca_tensor/ranks", {2, 4}, r.data());
      },
      "'/codec/lpca_tensor/view_factors' has shape");
  expect_refused(
      [&](const h5::File& f) {
        std::vector<std::int32_t> q = f.ReadInts("/codec/lpca_tensor/light_factors");
        q[5] = 300;  // above 2^8 - 1
        Delete(f, "/codec/lpca_tensor/light_factors");
        f.WriteInts("/codec/lpca_tensor/light_factors", {R, 5, 3}, q.data());
      },
      "'/codec/lpca_tensor/light_factors' element 5 is 300, outside [0, 255]");
  expect_refused(
      [&](const h5::File& f) {
        std::vector<float> s = f.ReadFloats("/codec/lpca_tensor/view_scale");
        s[1] = NAN;
        Delete(f, "/codec/lpca_tensor/view_scale");
        f.WriteFloats("/codec/lpca_tensor/view_scale", {R}, s.data());
      },
      "'/codec/lpca_tensor/view_scale' holds a non-finite value at element 1");
  expect_refused(
      [&](const h5::File& f) {
        std::vector<float> s = f.ReadFloats("/codec/lpca_tensor/weight_scale");
        s[0] = 3e38f;  // finite, but codes up to 255 overflow float
        Delete(f, "/codec/lpca_tensor/weight_scale");
        f.WriteFloats("/codec/lpca_tensor/weight_scale", {2, 3}, s.data());
      },
      "dequantises to a non-finite value");
  expect_refused(
      [](const h5::File& f) {
        Delete(f, "/codec/lpca_tensor/cluster_index");
        std::vector<std::int32_t> idx(36, 0);
        idx[7] = 2;
        f.WriteInts("/codec/lpca_tensor/cluster_index", {6, 6}, idx.data());
      },
      "'/codec/lpca_tensor/cluster_index' element 7 is 2, outside [0, 1]");
  expect_refused([](const h5::File& f) { Delete(f, "/codec/lpca_tensor/weights"); },
                 "'/codec/lpca_tensor/weights' is missing");
  expect_refused([](const h5::File& f) { f.SetAttr("/codec/lpca_tensor", "bits", std::int64_t(12)); }, "@bits' = 12");
}

TEST(LpcaTensor, OptionsAreChecked) {
  CompressOptions o = Tensor();
  o.tensor.quant_bits = 12;
  EXPECT_EQ(ExitCodeOf([&] { o.Check(); }), ExitCode::kUsage);
  o = Tensor();
  o.max_bytes = 1000, o.target_error = 0.1;
  EXPECT_EQ(ExitCodeOf([&] { o.Check(); }), ExitCode::kUsage);
  o = Tensor();
  o.storage = CodecStorage::kHalf;
  EXPECT_EQ(ExitCodeOf([&] { o.Check(); }), ExitCode::kUsage);
  o = Tensor();
  o.retained_energy = 0.9;
  EXPECT_EQ(ExitCodeOf([&] { o.Check(); }), ExitCode::kUsage);
  EXPECT_EQ(ParseMethod("lpca-tensor"), CodecMethod::kLpcaTensor);
  EXPECT_EQ(MethodName(CodecMethod::kLpcaTensor), "lpca-tensor");
}

TEST(LpcaTensor, QuantisedVectorsRoundTripWithinHalfAStep) {
  std::vector<float> x{-1.5f, 0.25f, 3.0f, 2.0f, -0.125f}, y(5);
  for (int bits : {8, 16}) {
    float scale = 0, bias = 0;
    const auto q = QuantiseVector(x.data(), x.size(), bits, &scale, &bias, y.data());
    EXPECT_EQ(bias, -1.5f);
    EXPECT_EQ(q[0], 0);
    EXPECT_EQ(q[2], (1 << bits) - 1);
    for (std::size_t i = 0; i < x.size(); ++i) {
      EXPECT_EQ(y[i], Dequantise(scale, bias, q[i]));
      EXPECT_LE(std::abs(y[i] - x[i]), 0.5 * scale * (1 + 1e-6)) << bits << " " << i;
    }
  }
  const std::vector<float> c(4, 0.75f);
  float scale = 1, bias = 0;
  const auto q = QuantiseVector(c.data(), c.size(), 8, &scale, &bias, y.data());
  EXPECT_EQ(scale, 0.0f);
  EXPECT_EQ(y[3], 0.75f);
}

// --bytes for the other methods: the largest c that fits, and c + 1 would not.
TEST(CodecBytes, EveryMethodStaysWithinTheBudget) {
  const Dataset d = TwoMaterials(4, 6, 8, 8);
  for (CodecMethod m : {CodecMethod::kPcaView, CodecMethod::kLpca, CodecMethod::kFmf, CodecMethod::kDfmf}) {
    CompressOptions o;
    o.method = m;
    o.clusters = 2;
    o.components = 64;
    CompressSummary one, s;
    o.components = 1;
    test::CompressDataset(d, o, &one);
    o.components = 64;
    o.max_bytes = one.codec_bytes * 3;
    test::CompressDataset(d, o, &s);
    EXPECT_LE(s.codec_bytes, o.max_bytes) << MethodName(m);
    EXPECT_GT(s.components, 1) << MethodName(m);
    EXPECT_LT(s.relative_error, one.relative_error) << MethodName(m);
    o.components = s.components + 1;
    o.max_bytes = 0;
    CompressSummary more;
    test::CompressDataset(d, o, &more);
    if (more.components > s.components) {
      EXPECT_GT(more.codec_bytes, one.codec_bytes * 3) << MethodName(m);
    }
    o.max_bytes = one.codec_bytes - 1;
    o.components = 64;
    EXPECT_EQ(ExitCodeOf([&] { test::CompressDataset(d, o); }), ExitCode::kUsage) << MethodName(m);
  }
}

}  // namespace
}  // namespace btf
