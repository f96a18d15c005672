// Bonn .btf readers and the BDI writer, on files written byte by byte from the documented layout
// (tests/io/bonn_test.h), so a reader bug cannot be hidden by a matching writer bug.
#include "libbtf/io/bonn.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/file_kind.h"
#include "libbtf/io/half.h"
#include "tests/io/bonn_test.h"
#include "tests/test_util.h"

namespace btf {
namespace {

using test::Bytes;
using test::Layout;

// Every view slot of a source as one Dataset.
Dataset ReadAll(const SlotSource& s) {
  Dataset d(s.views(), s.lights(), s.height(), s.width(), s.channels(), s.info());
  for (int v = 0; v < d.num_views(); ++v) s.ReadViewSlot(v, d.view_slot(v).data());
  return d;
}

Dataset ReadBonn(const std::filesystem::path& p) { return ReadAll(*OpenBonnSource(p)); }

// Expects btf::Error (bad input) whose message contains every fragment.
template <typename F>
void ExpectBadInput(F f, const std::vector<std::string>& fragments) {
  try {
    f();
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput) << e.what();
    for (const auto& s : fragments) EXPECT_NE(std::string(e.what()).find(s), std::string::npos) << e.what() << " / " << s;
  }
}

// ---- float16 storage (the conversions themselves: tests/io/half_test.cpp) ----

TEST(Half, Float16StorageRoundsAsFloatToHalf) {
  // float16 datasets are converted by libbtf (io/half.h), not by HDF5, whose 1.10.8 conversion
  // truncates half subnormals and drops the carry into the exponent (3.99956 -> 2). Values are
  // drawn over the whole half range, subnormals included, and 3.99956 explicitly: every value
  // read back must equal FloatToHalf's.
  Dataset d(Sampling::Bonn81().Subset({0}), Sampling::Bonn81().Subset({0}), 100, 100, 1);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> e(-26, 16), m(-1, 1);
  for (auto& x : d.data()) x = m(rng) * std::exp2(e(rng));
  d.data()[0] = 3.99956f;
  d.data()[1] = 1.63f * std::ldexp(1.0f, -24);
  const auto path = test::TempDir() / "f16.h5";
  DatasetWriteOptions o;
  o.storage = h5::Storage::kFloat16;
  WriteDataset(path, d, o);
  const Dataset r = ReadDataset(path);
  int subnormal = 0;
  for (std::size_t i = 0; i < d.size(); ++i) {
    ASSERT_EQ(HalfToFloat(FloatToHalf(d.data()[i])), r.data()[i]) << i << ": " << d.data()[i];
    if (d.data()[i] != 0 && std::abs(d.data()[i]) < std::ldexp(1.0f, -14)) ++subnormal;
  }
  EXPECT_EQ(r.data()[0], 4.0f);
  EXPECT_EQ(r.data()[1], std::ldexp(2.0f, -24));
  EXPECT_GT(subnormal, 500);
}

// ---- colour models ----

// The forward definitions of docs/format.md, section "Colour models", evaluated here in double.
std::array<double, 3> Undo(int model, std::array<double, 3> v, const std::array<float, 9>& M,
                           const std::array<float, 3>& mean) {
  const double eps = 1e-5;
  auto yuv = [](double y, double u, double w) {
    return std::array<double, 3>{y + 1.13983 * w, y - 0.39465 * u - 0.5806 * w, y + 2.03211 * u};
  };
  auto sgn = [](double x) { return double((x > 0) - (x < 0)); };
  switch (model) {
    case 0: return v;
    case 1: return yuv(v[0], v[1], v[2]);
    case 3:
      return {v[0] * M[0] + v[1] * M[3] + v[2] * M[6] + mean[0], v[0] * M[1] + v[1] * M[4] + v[2] * M[7] + mean[1],
              v[0] * M[2] + v[1] * M[5] + v[2] * M[8] + mean[2]};
    case 4: return {v[0] + v[1] - v[2], v[0] + v[2], v[0] - v[1] - v[2]};
    case 9: return yuv(std::exp(v[0]) - eps, v[1], v[2]);
    case 10:
      return yuv(std::exp(v[0]) - eps, sgn(v[1]) * eps * std::exp(std::abs(v[1])),
                 sgn(v[2]) * eps * std::exp(std::abs(v[2])));
    case 11: {
      const double y = std::exp(v[0]) - eps;
      return yuv(y, v[1] * (y + eps), v[2] * (y + eps));
    }
    case 12: return {std::exp(v[0]) - eps, std::exp(v[1]) - eps, std::exp(v[2]) - eps};
  }
  return v;
}

constexpr std::array<float, 9> kTransform{0.6f, 0.5f, 0.4f, 0.3f, -0.2f, 0.1f, 0.05f, 0.1f, -0.3f};
constexpr std::array<float, 3> kMean{0.25f, 0.5f, 0.125f};

// A DFMF file: 2 components per channel (channel 2 has 1), float32 factors.
Bytes Dfmf(const Layout& L, int model, bool transposed = false) {
  Bytes f;
  f.Text("!DFMF08FCR").Append(test::CommonHeader(L, true));
  f.U32(2).I32(model);
  for (float m : kMean) f.F32(m);
  for (float t : kTransform) f.F32(t);
  const int dirs = L.views * L.lights, texels = L.texels();
  for (int c = 0; c < L.nc(); ++c) {
    const int k = c == 2 ? 1 : 2;
    f.U8(4).U32(std::uint32_t(k));
    if (!transposed) f.U32(std::uint32_t(dirs)).U32(std::uint32_t(texels));
    else f.U32(std::uint32_t(texels)).U32(std::uint32_t(dirs));
    for (int i = 0; i < k; ++i) f.F32(9.0f);  // singular values: informational only
    auto put_u = [&] { for (int r = 0; r < dirs; ++r) for (int i = 0; i < k; ++i) f.F32(float(test::FactorU(c, r, i))); };
    auto put_v = [&] { for (int t = 0; t < texels; ++t) for (int i = 0; i < k; ++i) f.F32(float(test::FactorV(c, t, i))); };
    if (!transposed) put_u(), put_v();
    else put_v(), put_u();
  }
  return f;
}

// The decorrelated value of channel c at (view, light, texel) of Dfmf().
double DfmfChannel(int c, int v, int l, int t, const Layout& L) {
  const int k = c == 2 ? 1 : 2;
  double s = 0;
  for (int i = 0; i < k; ++i) s += float(test::FactorU(c, l + L.lights * v, i)) * double(float(test::FactorV(c, t, i)));
  return s;
}

class DfmfColorModel : public ::testing::TestWithParam<int> {};

TEST_P(DfmfColorModel, DecodesToTheDocumentedValues) {
  const int model = GetParam();
  const Layout L;
  const auto path = test::TempDir() / "m.btf";
  Dfmf(L, model).Save(path);
  EXPECT_EQ(FileFormatOf(path), "bonn-dfmf");
  const Dataset d = ReadBonn(path);
  ASSERT_EQ(d.num_views(), 2);
  ASSERT_EQ(d.num_lights(), 3);
  ASSERT_EQ(d.width(), 3);
  ASSERT_EQ(d.height(), 2);
  for (int v = 0; v < L.views; ++v)
    for (int l = 0; l < L.lights; ++l)
      for (int y = 0; y < L.height; ++y)
        for (int x = 0; x < L.width; ++x) {
          const int t = x + L.width * y;  // texel index of the file: x fastest, row y = dataset row y
          const auto want = Undo(model, {DfmfChannel(0, v, l, t, L), DfmfChannel(1, v, l, t, L), DfmfChannel(2, v, l, t, L)},
                                 kTransform, kMean);
          for (int c = 0; c < 3; ++c)
            // float32 products and sums of values < 2: a few float ulps; the logarithmic models
            // scale that by exp() of at most e^1.5.
            EXPECT_NEAR(d.at(v, l, y, x, c), want[std::size_t(c)], 2e-6 * (1 + std::abs(want[std::size_t(c)])))
                << "model " << model << " v" << v << " l" << l << " y" << y << " x" << x << " c" << c;
        }
}

INSTANTIATE_TEST_SUITE_P(Models, DfmfColorModel, ::testing::Values(0, 1, 3, 4, 9, 10, 11, 12));

TEST(BonnDfmf, Model11KnownValue) {
  // One texel, one direction, one component: Y' = ln(0.5 + eps), U' = 0.2, V' = -0.1.
  Layout L;
  L.views = L.lights = L.width = L.height = 1;
  Bytes f;
  f.Text("!DFMF08FCR").Append(test::CommonHeader(L, true)).U32(1).I32(11);
  for (int i = 0; i < 12; ++i) f.F32(0);
  const float stored[3] = {float(std::log(0.5 + 1e-5)), 0.2f, -0.1f};
  for (int c = 0; c < 3; ++c) f.U8(4).U32(1).U32(1).U32(1).F32(1).F32(1).F32(stored[c]);
  const auto path = test::TempDir() / "m11.btf";
  f.Save(path);
  const Dataset d = ReadBonn(path);
  // Y = 0.5, U = 0.2 * 0.50001, V = -0.1 * 0.50001; RGB from the BT.601 analog inverse.
  const double y = 0.5, u = 0.2 * 0.50001, v = -0.1 * 0.50001;
  EXPECT_NEAR(d.at(0, 0, 0, 0, 0), y + 1.13983 * v, 1e-6);
  EXPECT_NEAR(d.at(0, 0, 0, 0, 1), y - 0.39465 * u - 0.5806 * v, 1e-6);
  EXPECT_NEAR(d.at(0, 0, 0, 0, 2), y + 2.03211 * u, 1e-6);
}

TEST(BonnDfmf, TransposedLayoutDecodesTheSame) {
  Layout L;
  L.width = 4;  // 8 texels, 6 directions: the layouts are told apart by their sizes
  const auto dir = test::TempDir();
  Dfmf(L, 1).Save(dir / "a.btf");
  Dfmf(L, 1, true).Save(dir / "b.btf");
  EXPECT_EQ(ReadBonn(dir / "a.btf").data(), ReadBonn(dir / "b.btf").data());
}

TEST(BonnDfmf, HeaderSamplingRotationsAndMeta) {
  Layout L;
  L.rotations = 2;
  L.cosine = true;
  L.ppmm = 4;
  const auto path = test::TempDir() / "r.btf";
  Dfmf(L, 0).Save(path);
  const BonnReader r(path);
  const BonnHeader& h = r.header();
  EXPECT_EQ(h.signature, "!DFMF08FCR");
  ASSERT_EQ(h.rotations.size(), 2u);
  EXPECT_EQ(h.rotations[1][8], 18.0f);
  EXPECT_TRUE(h.cosine_flag);
  EXPECT_EQ(h.xml, "<x/>");
  EXPECT_EQ(h.measurement_setup, "hand-built setup");
  EXPECT_EQ(h.components, (std::vector<int>{2, 2, 1}));
  for (int v = 0; v < L.views; ++v)
    EXPECT_LT((h.views[v] - DirectionFromAngles(Layout::ViewTheta(v), Layout::ViewPhi(v))).norm(), 1e-7);
  for (int l = 0; l < L.lights; ++l)
    EXPECT_LT((h.lights[l] - DirectionFromAngles(Layout::LightTheta(l), Layout::LightPhi(l))).norm(), 1e-7);
  const DatasetInfo info = h.Info();
  EXPECT_TRUE(info.cos_theta_i_included);  // values are kept as stored; the flag says what they are
  EXPECT_EQ(info.units, "relative");
  EXPECT_DOUBLE_EQ(info.texel_size_mm, 0.25);
  const auto j = DescribeBonnFile(path, true);
  EXPECT_EQ(j["format"], "bonn-dfmf");
  EXPECT_EQ(j["color_model"]["name"], "rgb");
  EXPECT_EQ(j["rotations"], 2);
  EXPECT_EQ(j["values"]["count"], 2 * 3 * 3 * 2 * 3);
}

// ---- FMF ----

// FMF with n_C = channels, k_file components of which `stride` are stored per row.
Bytes Fmf(const Layout& L, const std::string& sig, int header_version, std::uint32_t drr, int k_file, int stride,
          int scalar_size = 4) {
  Bytes f;
  f.Text(sig).Append(test::CommonHeader(L, sig.back() == 'R'));
  if (sig == "!FMF12FCER") {
    f.U8(std::uint8_t(header_version));
    if (header_version >= 1) f.U32(drr);
    if (header_version >= 2) {
      f.U32(3).U32(2);  // height map 3 wide, 2 high
      for (int i = 0; i < 6; ++i) f.U16(0x3c00);
    }
  }
  const int rows = L.nc() * L.lights * L.views, cols = L.texels();
  f.U32(std::uint32_t(k_file)).U8(std::uint8_t(scalar_size)).U32(std::uint32_t(stride)).U32(std::uint32_t(rows)).U32(std::uint32_t(cols));
  auto put = [&](double x) {
    if (scalar_size == 4) f.F32(float(x));
    else f.F64(x);
  };
  for (int i = 0; i < stride; ++i) put(1.0);
  for (int r = 0; r < rows; ++r)
    for (int i = 0; i < stride; ++i) put(test::FactorU(0, r, i));
  for (int t = 0; t < cols; ++t)
    for (int i = 0; i < stride; ++i) put(test::FactorV(0, t, i));
  return f;
}

double FmfValue(int c, int v, int l, int t, int k, const Layout& L, bool drr) {
  double s = 0;
  for (int i = 0; i < k; ++i) s += test::FactorU(0, c + L.nc() * (l + L.lights * v), i) * test::FactorV(0, t, i);
  return drr ? std::exp(s) - 1e-5 : s;
}

void ExpectFmf(const Dataset& d, const Layout& L, int k, bool drr) {
  for (int v = 0; v < L.views; ++v)
    for (int l = 0; l < L.lights; ++l)
      for (int y = 0; y < L.height; ++y)
        for (int x = 0; x < L.width; ++x)
          for (int c = 0; c < L.nc(); ++c) {
            const double want = FmfValue(c, v, l, x + L.width * y, k, L, drr);
            // float32 factors (rounded from double): relative 1e-6.
            ASSERT_NEAR(d.at(v, l, y, x, c), want, 1e-6 * (1 + std::abs(want)));
          }
}

TEST(BonnFmf, BothHeaderVersionsDynamicRangeAndHeightMap) {
  const Layout L;
  const auto dir = test::TempDir();
  Fmf(L, "!FMF06FC", 0, 0, 2, 2).Save(dir / "old.btf");
  ExpectFmf(ReadBonn(dir / "old.btf"), L, 2, false);
  Fmf(L, "!FMF06FCR", 0, 0, 2, 2, 8).Save(dir / "old_r.btf");
  ExpectFmf(ReadBonn(dir / "old_r.btf"), L, 2, false);
  Fmf(L, "!FMF12FCER", 1, 0, 2, 2).Save(dir / "v1.btf");
  ExpectFmf(ReadBonn(dir / "v1.btf"), L, 2, false);
  Fmf(L, "!FMF12FCER", 2, 1, 2, 2).Save(dir / "v2.btf");
  ExpectFmf(ReadBonn(dir / "v2.btf"), L, 2, true);
  const BonnReader r(dir / "v2.btf");
  EXPECT_EQ(r.header().height_map_width, 3);
  EXPECT_EQ(r.header().height_map_height, 2);
  EXPECT_EQ(r.header().dynamic_range_reduction, 1u);
  ExpectBadInput([&] { Fmf(L, "!FMF12FCER", 3, 0, 2, 2).Save(dir / "v3.btf"), (void)BonnReader(dir / "v3.btf"); },
                 {"v3.btf", "header_version", "byte"});
}

TEST(BonnFmf, ComponentCountsThatDifferUseTheMinimumAndTheStoredStride) {
  const Layout L;
  const auto dir = test::TempDir();
  // The file claims 1 component but stores 3 per row: decode 1, step rows by 3.
  Fmf(L, "!FMF06FC", 0, 0, 1, 3).Save(dir / "a.btf");
  ExpectFmf(ReadBonn(dir / "a.btf"), L, 1, false);
  Fmf(L, "!FMF06FC", 0, 0, 5, 2).Save(dir / "b.btf");
  ExpectFmf(ReadBonn(dir / "b.btf"), L, 2, false);
}

TEST(BonnFmf, MultispectralChannelNames) {
  Layout L;
  L.channels = {"450", "550", "650", "750"};
  const auto path = test::TempDir() / "ms.btf";
  Fmf(L, "!FMF06FCR", 0, 0, 2, 2).Save(path);
  const auto src = OpenBonnSource(path);
  EXPECT_EQ(src->channels(), 4);
  EXPECT_EQ(src->info().channel_names, L.channels);
  EXPECT_EQ(src->info().color_space, "multispectral");
  ExpectFmf(ReadAll(*src), L, 2, false);
}

TEST(BonnMeta, OlderMetaVersionsDefaultToRgbWithoutCosine) {
  for (int version : {1, 2, 3}) {
    Layout L;
    L.meta_version = version;
    L.cosine = true;  // written only from version 2 on
    const auto path = test::TempDir() / "v.btf";
    Fmf(L, "!FMF06FC", 0, 0, 2, 2).Save(path);
    const BonnReader r(path);
    EXPECT_EQ(r.header().channel_names, (std::vector<std::string>{"R", "G", "B"}));
    EXPECT_EQ(r.header().cosine_flag, version >= 2);
  }
}

// ---- PVF ----

double PvfC(int v, int d, int k) { return 0.1 * (d + 1) - 0.05 * k + 0.2 * v; }
double PvfW(int v, int r, int k) { return 0.5 - 0.03 * r + 0.1 * k - 0.1 * v; }
double PvfM(int v, int d) { return 0.01 * d + v; }

Bytes PvfViews(const Layout& L, bool images) {
  Bytes f;
  const int k = 2;
  const int weights = images ? L.lights : L.texels();
  const int dim = images ? L.nc() * L.texels() : L.nc() * L.lights;
  for (int v = 0; v < L.views; ++v) {
    f.U8(4).U32(k).U32(std::uint32_t(weights)).U32(std::uint32_t(dim));
    for (int i = 0; i < k; ++i) f.F32(3.0f);
    for (int d = 0; d < dim; ++d) f.F32(float(PvfM(v, d)));
    for (int d = 0; d < dim; ++d)
      for (int i = 0; i < k; ++i) f.F32(float(PvfC(v, d, i)));
    for (int r = 0; r < weights; ++r)
      for (int i = 0; i < k; ++i) f.F32(float(PvfW(v, r, i)));
  }
  return f;
}

void ExpectPvf(const Dataset& d, const Layout& L, bool images) {
  for (int v = 0; v < L.views; ++v)
    for (int l = 0; l < L.lights; ++l)
      for (int t = 0; t < L.texels(); ++t)
        for (int c = 0; c < L.nc(); ++c) {
          const int dim = images ? c + L.nc() * t : c + L.nc() * l, row = images ? l : t;
          double want = PvfM(v, dim);
          for (int i = 0; i < 2; ++i) want += PvfW(v, row, i) * PvfC(v, dim, i);
          ASSERT_NEAR(d.at(v, l, t / L.width, t % L.width, c), want, 1e-6 * (1 + std::abs(want)));
        }
}

TEST(BonnPvf, CurrentHeaderLightFields) {
  const Layout L;
  Bytes f;
  f.Text("!PVF06FCR").Append(test::CommonHeader(L, true)).U32(2).U32(std::uint32_t(L.views)).Append(PvfViews(L, false));
  const auto path = test::TempDir() / "p.btf";
  f.Save(path);
  EXPECT_EQ(FileFormatOf(path), "bonn-pvf");
  ExpectPvf(ReadBonn(path), L, false);
}

TEST(BonnPvf, LegacyHeaderStackedImages) {
  const Layout L;
  Bytes f;
  f.Text("!PVF06FC").I32(301074).U32(2).U32(std::uint32_t(L.width)).U32(std::uint32_t(L.height)).U32(std::uint32_t(L.views));
  f.Append(test::SamplingBlock(L)).Append(PvfViews(L, true));
  const auto path = test::TempDir() / "legacy.btf";
  f.Save(path);
  const BonnReader r(path);
  EXPECT_TRUE(r.header().pvf_legacy);
  EXPECT_TRUE(r.header().pvf_images);
  ExpectPvf(ReadBonn(path), L, true);
}

// ---- BDI ----

// Half patterns k/8 for k = -64..63 are exact; value index i maps to one of them.
std::uint16_t BdiHalf(std::size_t i) { return FloatToHalf(float(int(i % 127) - 63) / 8.0f); }

Bytes Bdi(const Layout& L, std::uint8_t compression, const std::vector<std::uint8_t>& mask, int scan_lines) {
  Bytes f;
  f.Text("!BDIF06R2!").Append(test::Meta(L)).Append(test::SamplingBlock(L));
  f.U32(std::uint32_t(L.width)).U32(std::uint32_t(L.height)).U32(std::uint32_t(scan_lines)).U8(compression);
  for (auto m : mask) f.U8(m);
  f.U32(std::uint32_t(L.rotations));
  for (int i = 0; i < 9 * L.rotations; ++i) f.F32(float(i));
  std::size_t stored = 0;
  for (auto m : mask) stored += compression == 0 || m;
  const std::size_t abrdf = std::size_t(L.views) * L.lights * L.nc(), per_chunk = std::size_t(L.width) * scan_lines;
  std::size_t value = 0;
  for (std::size_t s0 = 0; s0 < stored; s0 += per_chunk) {
    const std::size_t n = std::min(per_chunk, stored - s0);
    f.U32(std::uint32_t(n * abrdf * 2));
    for (std::size_t i = 0; i < n * abrdf; ++i) f.U16(BdiHalf(value++));
  }
  return f;
}

void ExpectBdi(const Dataset& d, const Layout& L, std::uint8_t compression, const std::vector<std::uint8_t>& mask) {
  std::size_t s = 0;
  const std::size_t abrdf = std::size_t(L.views) * L.lights * L.nc();
  for (int t = 0; t < L.texels(); ++t) {
    const bool stored = compression == 0 || mask[std::size_t(t)];
    for (int v = 0; v < L.views; ++v)
      for (int l = 0; l < L.lights; ++l)
        for (int c = 0; c < L.nc(); ++c) {
          // ABRDF element order: channel fastest, then light, then view.
          const float want = stored ? HalfToFloat(BdiHalf(s * abrdf + std::size_t(c + L.nc() * (l + L.lights * v)))) : 0.0f;
          ASSERT_EQ(d.at(v, l, t / L.width, t % L.width, c), want) << t;
        }
    s += stored;
  }
}

TEST(BonnBdi, FullAndSparseMaskWithShortLastChunk) {
  Layout L;
  L.width = 3;
  L.height = 5;
  L.rotations = 1;
  const auto dir = test::TempDir();
  std::vector<std::uint8_t> mask(15, 1);
  for (int i : {1, 7, 8, 14}) mask[std::size_t(i)] = 0;
  for (std::uint8_t compression : {std::uint8_t(0), std::uint8_t(2)}) {
    for (int scan_lines : {1, 2, 4}) {
      const auto path = dir / fmt::format("b{}{}.btf", compression, scan_lines);
      Bdi(L, compression, mask, scan_lines).Save(path);
      EXPECT_EQ(FileFormatOf(path), "bonn-bdi");
      ExpectBdi(ReadBonn(path), L, compression, mask);
      EXPECT_EQ(BonnReader(path).header().stored_texels, compression == 0 ? 15u : 11u);
    }
  }
  ExpectBadInput([&] { Bdi(L, 1, mask, 2).Save(dir / "bz.btf"), (void)BonnReader(dir / "bz.btf"); },
                 {"bz.btf", "compression", "bzip2"});
}

// ---- BDI writer and round trips ----

TEST(BonnBdi, DatasetToBdiToDatasetEqualsTheHalfRoundedInput) {
  Dataset d = test::MakeTestDataset(3, 4, 5, 6);
  d.info().cos_theta_i_included = true;
  d.data()[5] = -3.0e-6f;  // a half subnormal
  const auto dir = test::TempDir();
  WriteBdi(dir / "d.btf", *MemorySource(d));
  const auto src = OpenBonnSource(dir / "d.btf");
  CheckCompatible(*MemorySource(d), *src);  // directions through float32 angles: within 1e-6
  const Dataset r = ReadAll(*src);
  for (std::size_t i = 0; i < d.size(); ++i) ASSERT_EQ(r.data()[i], HalfToFloat(FloatToHalf(d.data()[i]))) << i;
  EXPECT_TRUE(r.info().cos_theta_i_included);
  // Through btf-convert's library call to a dataset file: the same values.
  Convert(ConvertOptions(), *src, dir / "back.h5");
  EXPECT_EQ(ReadDataset(dir / "back.h5").data(), r.data());
  // And through HDF5's own half storage: the same rounding in the normal half range.
  DatasetWriteOptions o;
  o.storage = h5::Storage::kFloat16;
  WriteDataset(dir / "f16.h5", d, o);
  const Dataset f16 = ReadDataset(dir / "f16.h5");
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (std::abs(d.data()[i]) < std::ldexp(1.0f, -14)) continue;
    ASSERT_EQ(f16.data()[i], r.data()[i]) << i;
  }
}

TEST(BonnBdi, WriterRefusesValuesBeyondHalfAndWritesNothing) {
  Dataset d = test::MakeTestDataset(1, 2, 2, 2);
  d.at(0, 1, 1, 0, 2) = 7e4f;
  const auto dir = test::TempDir();
  ExpectBadInput([&] { WriteBdi(dir / "x.btf", *MemorySource(d)); }, {"view 0, light 1", "(y 1, x 0)", "channel 2"});
  d.at(0, 1, 1, 0, 2) = std::numeric_limits<float>::quiet_NaN();
  ExpectBadInput([&] { WriteBdi(dir / "x.btf", *MemorySource(d)); }, {"NaN"});
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

TEST(BonnConvert, OptionsAndTargets) {
  ConvertOptions o;
  EXPECT_EQ(ConvertTarget(o, "x.h5"), "dataset");
  EXPECT_EQ(ConvertTarget(o, "x.btf"), "bdi");
  o.to = "dataset";
  EXPECT_EQ(ConvertTarget(o, "x.btf"), "dataset");
  const auto usage = [](const ConvertOptions& opt, const char* out) {
    try {
      ConvertTarget(opt, out);
      ADD_FAILURE() << out;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kUsage) << e.what();
    }
  };
  usage(ConvertOptions(), "x.txt");
  o.to = "svd";
  usage(o, "x.btf");
  for (const char* to : {"fmf", "dfmf", "pvf"}) {  // valid targets, written by libbtf/compress
    o.to = to;
    EXPECT_EQ(ConvertTarget(o, "x.btf"), to);
  }
  o = ConvertOptions();
  o.storage = "float8";
  usage(o, "x.h5");
  o = ConvertOptions();
  o.deflate_level = 10;
  usage(o, "x.h5");
  o = ConvertOptions();
  o.scan_lines_per_chunk = 0;
  usage(o, "x.btf");
}

// ---- bad input ----

TEST(BonnBadInput, EveryTruncationIsRefusedNamingTheFile) {
  const Layout L;
  const auto dir = test::TempDir();
  std::vector<std::uint8_t> mask(std::size_t(L.texels()), 1);
  const std::vector<Bytes> files = {Dfmf(L, 11), Fmf(L, "!FMF12FCER", 2, 1, 2, 2), Bdi(L, 2, mask, 1)};
  for (std::size_t i = 0; i < files.size(); ++i)
    for (std::size_t n = 1; n < files[i].size(); n += 3) {
      Bytes cut;
      cut.b.assign(files[i].b.begin(), files[i].b.begin() + std::ptrdiff_t(n));
      const auto path = dir / "cut.btf";
      cut.Save(path);
      try {
        const auto src = OpenBonnSource(path);
        ADD_FAILURE() << "file " << i << " cut at " << n << " accepted";
      } catch (const Error& e) {
        ASSERT_EQ(e.code(), ExitCode::kBadInput) << e.what();
        ASSERT_NE(std::string(e.what()).find("cut.btf"), std::string::npos) << e.what();
      }
    }
}

TEST(BonnBadInput, SignaturesSizesAndValues) {
  const Layout L;
  const auto dir = test::TempDir();
  const auto save = [&](const Bytes& b) {
    b.Save(dir / "bad.btf");
    return dir / "bad.btf";
  };
  // Unknown signature.
  ExpectBadInput([&] { FileFormatOf(save(Bytes().Text("!XYZ01ABC!").U32(0))); }, {"bad.btf", "signature", "byte 0"});
  // Trailing bytes: sizes disagree with the file length.
  ExpectBadInput([&] { (void)BonnReader(save(Bytes().Append(Dfmf(L, 0)).U32(7))); }, {"4 trailing bytes"});
  // Matrix sizes that fit neither layout.
  {
    Bytes f = Dfmf(L, 0);
    const std::size_t rows_at = 10 + test::CommonHeader(L, true).size() + 4 + 4 + 12 + 36 + 1 + 4;
    const std::uint32_t bad = 5;
    std::memcpy(f.b.data() + rows_at, &bad, 4);
    ExpectBadInput([&] { (void)BonnReader(save(f)); }, {"channel 0 rows x cols", fmt::format("byte {}", rows_at), "5 x 6"});
  }
  // Absurd size: a view count no file could hold, refused before allocating.
  {
    Bytes f;
    f.Text("!DFMF08FCR").Append(test::Meta(L)).U32(0x7fffffff);
    ExpectBadInput([&] { (void)BonnReader(save(f)); }, {"sampling of 2147483647 views", "n_views at byte"});
  }
  // NaN in a factor: the element's byte offset.
  {
    Bytes f = Dfmf(L, 0);
    const std::size_t u_at = 10 + test::CommonHeader(L, true).size() + 4 + 4 + 12 + 36 + 1 + 12 + 8;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(f.b.data() + u_at + 4, &nan, 4);
    ExpectBadInput([&] { (void)BonnReader(save(f)); }, {"channel 0 U", fmt::format("byte {}", u_at + 4), "row 0, component 1"});
  }
  // Unsupported colour model (Lab).
  ExpectBadInput([&] { (void)BonnReader(save(Dfmf(L, 2))); }, {"color_model", "2 (lab)"});
  // A sampling whose light list differs per view.
  {
    Bytes f;
    f.Text("!FMF06FC").Append(test::Meta(L));
    Bytes s = test::SamplingBlock(L);
    const std::size_t second_view_light0_phi = 4 + (12 + 8 * 3) + 12 + 4;
    const float phi = 0.5f;
    std::memcpy(s.b.data() + second_view_light0_phi, &phi, 4);
    f.Append(s);
    ExpectBadInput([&] { (void)BonnReader(save(f)); }, {"view 1 light 0 phi", "tensor-product"});
  }
  // Meta block whose struct_size disagrees with its content.
  {
    Bytes m = test::Meta(L);
    const std::uint32_t wrong = 300;
    std::memcpy(m.b.data(), &wrong, 4);
    ExpectBadInput([&] { (void)BonnReader(save(Bytes().Text("!FMF06FC").Append(m))); }, {"struct_size at byte 8", "is 300"});
  }
}

TEST(BonnBadInput, LightListsDifferingOnlyInTheSignOfZeroAreEqual) {
  // Found by fuzz_bonn_pvf: 0 and -0 differ bitwise but are the same direction.
  Layout L;
  L.views = 2;
  L.lights = 1;
  L.width = L.height = 1;
  Bytes s = test::SamplingBlock(L);
  const float zero = 0.0f, minus_zero = -0.0f;
  std::memcpy(s.b.data() + 4 + 8 + 4, &zero, 4);            // view 0, light 0 theta
  std::memcpy(s.b.data() + 4 + 20 + 8 + 4, &minus_zero, 4);  // view 1, light 0 theta
  Bytes f;
  f.Text("!FMF06FC").Append(test::Meta(L)).Append(s).U32(1).U32(1);
  f.U32(1).U8(4).U32(1).U32(3 * 2).U32(1).F32(1);
  for (int i = 0; i < 6 + 1; ++i) f.F32(0.5f);
  const auto path = test::TempDir() / "z.btf";
  f.Save(path);
  const Dataset d = ReadBonn(path);
  EXPECT_EQ(d.at(1, 0, 0, 0, 2), 0.25f);
  // A real difference is still refused, naming the entry.
  const float other = 0.5f;
  std::memcpy(f.b.data() + 8 + test::Meta(L).size() + 4 + 20 + 8 + 4, &other, 4);
  f.Save(path);
  ExpectBadInput([&] { (void)BonnReader(path); }, {"view 1 light 0 theta", "is 0.5 but view 0 has 0"});
}

}  // namespace
}  // namespace btf
