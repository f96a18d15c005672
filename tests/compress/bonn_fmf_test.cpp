// FMF and DFMF written by the streaming randomised SVD and read back by the Bonn readers.
#include "libbtf/compress/bonn_fmf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {


Dataset RandomDataset(int views, int lights, int h, int w, int channels) {
  Dataset d = test::MakeTestDataset(views, lights, h, w, channels);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  for (auto& x : d.data()) x = 0.2f + u(rng);
  return d;
}

TEST(BonnFmfWriter, AllComponentsRoundTrip) {
  const Dataset d = RandomDataset(3, 4, 5, 6, 3);  // FMF: 36 x 30, DFMF: 12 x 30 per channel
  const auto dir = test::TempDir();
  FmfWriteOptions o;
  o.components = 64;  // clamped to min(rows, texels): every component
  const ConvertSummary s = WriteFmf(o, *MemorySource(d), dir / "f.btf");
  EXPECT_EQ(s.output_format, "fmf");
  const auto fmf = OpenBonnSource(dir / "f.btf");
  EXPECT_EQ(fmf->kind(), "bonn-fmf");
  CheckCompatible(*MemorySource(d), *fmf);
  // float32 factors of a double SVD: a few float ulps of the largest value.
  EXPECT_LT(test::MaxRelativeError(*MemorySource(d), *fmf), 1e-5);
  o.decorrelate = true;
  WriteFmf(o, *MemorySource(d), dir / "d.btf");
  const BonnReader r(dir / "d.btf");
  EXPECT_EQ(r.header().color_model, 1);
  EXPECT_EQ(r.header().components, (std::vector<int>{12, 12, 12}));
  // The YUV inverse the reader applies has 5-6 significant digits (docs/format.md): its product
  // with the forward matrix differs from the identity by up to about 2e-5.
  EXPECT_LT(test::MaxRelativeError(*MemorySource(d), *OpenBonnSource(dir / "d.btf")), 1e-4);
}

TEST(BonnFmfWriter, FewerComponentsGiveLargerErrorsAndLowRankDataIsExact) {
  const Dataset d = RandomDataset(2, 5, 4, 4, 3);
  const auto dir = test::TempDir();
  double previous = 1e30;
  for (int k : {1, 3, 8}) {
    FmfWriteOptions o;
    o.components = k;
    WriteFmf(o, *MemorySource(d), dir / "f.btf");
    const double e = test::MaxRelativeError(*MemorySource(d), *OpenBonnSource(dir / "f.btf"));
    EXPECT_LT(e, previous) << k;
    previous = e;
  }
  // MakeTestDataset is v + 0.01 l + 1e-3 y + 1e-5 x + 0.3 c: rank 3 over texels (1, y, x).
  const Dataset low = test::MakeTestDataset(2, 5, 4, 4, 3);
  FmfWriteOptions o;
  o.components = 3;
  WriteFmf(o, *MemorySource(low), dir / "low.btf");
  EXPECT_LT(test::MaxRelativeError(*MemorySource(low), *OpenBonnSource(dir / "low.btf")), 1e-5);
}

// The load sequence of zeroeffects/btf's btf.hh (LoadBTF, as ../shared/reference section 4.8
// and docs/format.md describe it) walked over the bytes our writer made, independently of
// libbtf's reader: btf.hh returns no BTF unless each checked field holds. Beyond our reader it
// requires n_V = n_L (it expects n_L^2 U rows), one scalar size for all DFMF channels, equal FMF
// component counts (it strides by their minimum) and no byte after the last factor.
class BtfHhWalk {
 public:
  explicit BtfHhWalk(const std::filesystem::path& path) {
    std::ifstream f(path, std::ios::binary);
    bytes_.assign(std::istreambuf_iterator<char>(f), {});
  }
  template <typename T>
  T Get() {
    T v{};
    EXPECT_LE(pos_ + sizeof v, bytes_.size()) << "read past the end at byte " << pos_;
    if (pos_ + sizeof v <= bytes_.size()) std::memcpy(&v, bytes_.data() + pos_, sizeof v);
    pos_ += sizeof v;
    return v;
  }
  float F32At(std::size_t at) const {
    float v = 0;
    if (at + 4 <= bytes_.size()) std::memcpy(&v, bytes_.data() + at, 4);
    return v;
  }
  void Skip(std::size_t n) { pos_ += n; }
  std::size_t pos() const { return pos_; }
  std::size_t size() const { return bytes_.size(); }

  // Signature through rotations (btf.hh's read_common); returns n_L.
  std::uint32_t Common(const std::string& signature, std::uint32_t& width, std::uint32_t& height) {
    EXPECT_EQ(std::string(bytes_.data(), std::min(bytes_.size(), signature.size())), signature);
    pos_ = signature.size();
    const std::size_t start = pos_;
    const auto size = Get<std::uint32_t>(), version = Get<std::uint32_t>();
    Skip(3 * 80 + 4 + 12);  // setup, sensor, light source, ppmm, rgb scale
    if (version > 1) {
      EXPECT_EQ(Get<std::uint32_t>(), 0u) << "cosine flag (btf.hh: a stub that asserts)";
    }
    if (version > 2) Skip(Get<std::uint32_t>());
    if (version > 3) {
      const auto channels = Get<std::uint32_t>();
      EXPECT_LE(channels, 3u) << "btf.hh fetches at most 3 channels";
      for (std::uint32_t c = 0; c < channels; ++c) Skip(Get<std::uint32_t>());
    }
    EXPECT_EQ(pos_ - start, size) << "meta block size";
    const auto views = Get<std::uint32_t>();
    std::uint32_t lights = 0;
    for (std::uint32_t v = 0; v < views; ++v) {
      Skip(8);
      const auto n = Get<std::uint32_t>();
      if (v == 0) lights = n;
      EXPECT_EQ(n, lights) << "view " << v;
      Skip(8 * std::size_t(n));
    }
    EXPECT_EQ(views, lights) << "btf.hh expects n_L^2 U rows";
    width = Get<std::uint32_t>();
    height = Get<std::uint32_t>();
    EXPECT_EQ(Get<std::uint32_t>(), 0u) << "rotations";
    return lights;
  }

 private:
  std::vector<char> bytes_;
  std::size_t pos_ = 0;
};

TEST(BonnFmfWriter, FilesFollowTheLoadRulesOfBtfHh) {
  // Rank 3 over texels (MakeTestDataset), so 3 components reproduce it to float rounding.
  const Dataset d = test::MakeTestDataset(3, 3, 5, 6, 3);
  const auto dir = test::TempDir();
  FmfWriteOptions o;
  o.components = 3;
  WriteFmf(o, *MemorySource(d), dir / "f.btf");
  BtfHhWalk f(dir / "f.btf");
  std::uint32_t W = 0, H = 0;
  const std::uint32_t nl = f.Common("!FMF12FCER", W, H);
  EXPECT_EQ(f.Get<std::uint8_t>(), 1);    // header version 1: the dynamic-range flag follows
  EXPECT_EQ(f.Get<std::uint32_t>(), 0u);  // no dynamic-range reduction
  const auto k0 = f.Get<std::uint32_t>();
  EXPECT_EQ(f.Get<std::uint8_t>(), 4);  // float32
  const auto k = f.Get<std::uint32_t>();
  EXPECT_EQ(k0, k);
  const auto rows = f.Get<std::uint32_t>(), cols = f.Get<std::uint32_t>();
  ASSERT_EQ(rows, nl * nl * 3);
  ASSERT_EQ(cols, W * H);
  f.Skip(4 * std::size_t(k));  // singular values
  const std::size_t u_at = f.pos(), sxv_at = u_at + 4 * std::size_t(rows) * k;
  f.Skip(4 * (std::size_t(rows) + cols) * k);
  EXPECT_EQ(f.pos(), f.size()) << "btf.hh rejects trailing bytes";
  // btf.hh's fetch of channel c, view v, light l at its texel (x, y): sum_j U[c + 3 (l + nl v)][j]
  // SxV[x + W (H - 1 - y)][j], since it flips rows on loading (libbtf, like btflib, does not):
  // btf.hh shows our texel (x, H - 1 - y) at (x, y).
  double worst = 0;
  for (int v = 0; v < 3; ++v)
    for (int l = 0; l < 3; ++l)
      for (int y = 0; y < int(H); ++y)
        for (int x = 0; x < int(W); ++x)
          for (int c = 0; c < 3; ++c) {
            const std::size_t row = std::size_t(c) + 3 * (std::size_t(l) + nl * std::size_t(v));
            const std::size_t texel = std::size_t(x) + W * (H - 1 - std::size_t(y));
            double value = 0;
            for (std::uint32_t j = 0; j < k; ++j)
              value += double(f.F32At(u_at + 4 * (row * k + j))) * f.F32At(sxv_at + 4 * (texel * k + j));
            worst = std::max(worst, std::abs(value - d.at(v, l, int(H) - 1 - y, x, c)));
          }
  EXPECT_LT(worst, 1e-5);  // float32 factors of values below 3: a few float ulps

  o.decorrelate = true;
  WriteFmf(o, *MemorySource(d), dir / "d.btf");
  BtfHhWalk g(dir / "d.btf");
  g.Common("!DFMF08FCR", W, H);
  g.Get<std::uint32_t>();                // num_components (not used for reading)
  EXPECT_EQ(g.Get<std::uint32_t>(), 1u);  // colour model 1 (YUV): btf.hh loads it, its fetch decodes only 0 and 11
  g.Skip(12 * 4);                        // colour mean, transform
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(g.Get<std::uint8_t>(), 4) << "channel " << c << ": btf.hh needs one scalar size";
    const auto kc = g.Get<std::uint32_t>();
    EXPECT_EQ(g.Get<std::uint32_t>(), nl * nl);
    EXPECT_EQ(g.Get<std::uint32_t>(), W * H);
    g.Skip(4 * std::size_t(kc) * (1 + nl * nl + W * H));
  }
  EXPECT_EQ(g.pos(), g.size()) << "btf.hh rejects trailing bytes";
}

TEST(BonnFmfWriter, DfmfNeedsThreeChannelsAndNothingIsWritten) {
  const Dataset d = RandomDataset(1, 2, 2, 2, 4);
  FmfWriteOptions o;
  o.decorrelate = true;
  const auto dir = test::TempDir();
  try {
    WriteFmf(o, *MemorySource(d), dir / "d.btf");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
  }
  Dataset bad = RandomDataset(1, 2, 2, 2, 3);
  bad.data()[3] = std::numeric_limits<float>::infinity();
  o.decorrelate = false;
  try {
    WriteFmf(o, *MemorySource(bad), dir / "f.btf");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir));
}

}  // namespace
}  // namespace btf
