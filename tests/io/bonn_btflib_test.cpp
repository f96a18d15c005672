// BDI files laid out the way btflib (the Bonn group's MATLAB library) writes them, and Bonn files
// whose header claims more than the file holds. Files are built byte by byte (tests/io/bonn_test.h)
// from btflib's writer as read in its source (write_bdi_header.m, write_bdi_chunks.m): meta block
// version 4, the sampling, W, H, scan_lines_per_chunk, the compression byte, the mask (x fastest),
// n_rot = 0, then chunks of W x scan_lines_per_chunk ABRDFs each: the last one too, its texels
// past the stored ones padded (btflib's chunk buffer is a full column per chunk).
#include <sys/resource.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/half.h"
#include "tests/io/bonn_test.h"
#include "tests/test_util.h"

namespace btf {
namespace {

using test::Bytes;
using test::Layout;

// The distinct value of stored ABRDF element i (exact in half: k/8 for k = -64..63).
std::uint16_t StoredHalf(std::size_t i) { return FloatToHalf(float(int(i % 127) - 63) / 8.0f); }

struct BtflibBdi {
  Layout L;
  std::uint8_t compression = 2;
  int scan_lines = 4;  // btflib's default
  std::vector<std::uint8_t> mask;  // x fastest; empty = all stored
  std::uint16_t padding = 0;       // the half written into the padding (btflib: 0)
  bool pad = true;                 // false: the last chunk short (what libbtf's writer does)

  std::size_t abrdf() const { return std::size_t(L.views) * L.lights * L.nc(); }
  std::size_t per_chunk() const { return std::size_t(L.width) * scan_lines; }
  bool stored(int t) const { return compression == 0 || mask.empty() || mask[std::size_t(t)] != 0; }
  std::size_t stored_count() const {
    std::size_t n = 0;
    for (int t = 0; t < L.texels(); ++t) n += stored(t);
    return n;
  }
  std::size_t padding_abrdfs() const {
    const std::size_t rest = stored_count() % per_chunk();
    return pad && rest ? per_chunk() - rest : 0;
  }
  Bytes Build() const {
    Bytes f;
    f.Text("!BDIF06R2!").Append(test::Meta(L)).Append(test::SamplingBlock(L));
    f.U32(std::uint32_t(L.width)).U32(std::uint32_t(L.height)).U32(std::uint32_t(scan_lines)).U8(compression);
    for (int t = 0; t < L.texels(); ++t) f.U8(mask.empty() ? 1 : mask[std::size_t(t)]);
    f.U32(0);  // n_rot
    const std::size_t n = stored_count();
    std::size_t value = 0;
    for (std::size_t s0 = 0; s0 < n; s0 += per_chunk()) {
      const std::size_t real = std::min(per_chunk(), n - s0), written = pad ? per_chunk() : real;
      f.U32(std::uint32_t(written * abrdf() * 2));
      for (std::size_t i = 0; i < written * abrdf(); ++i) f.U16(i < real * abrdf() ? StoredHalf(value++) : padding);
    }
    return f;
  }
  // Every decoded value is the stored one (element c + nC (l + nL v) of stored ABRDF s), or 0.
  void Expect(const SlotSource& src) const {
    std::vector<float> slot(src.slot_size());
    for (int v = 0; v < L.views; ++v) {
      src.ReadViewSlot(v, slot.data());
      std::size_t s = 0;
      for (int t = 0; t < L.texels(); ++t) {
        for (int l = 0; l < L.lights; ++l)
          for (int c = 0; c < L.nc(); ++c) {
            const float want =
                stored(t) ? HalfToFloat(StoredHalf(s * abrdf() + std::size_t(c + L.nc() * (l + L.lights * v)))) : 0.0f;
            ASSERT_EQ(slot[(std::size_t(l) * L.texels() + std::size_t(t)) * L.nc() + c], want) << v << " " << t;
          }
        s += stored(t);
      }
    }
  }
};

// The file: 8 x 6 texels, 4 scan lines a chunk: chunk 1 holds 16 ABRDFs padded to 32.
TEST(BonnBtflib, PaddedLastChunkIsReadForFullAndSparseMasks) {
  const auto dir = test::TempDir();
  BtflibBdi b;
  b.L.width = 8;
  b.L.height = 6;
  b.padding = 0x7e00;  // NaN: the padding's values are never read
  std::vector<std::uint8_t> sparse(48, 1);
  for (int t : {0, 9, 17, 40, 47}) sparse[std::size_t(t)] = 0;
  for (std::uint8_t compression : {std::uint8_t(0), std::uint8_t(2)})
    for (int scan_lines : {4, 5, 1})
      for (const auto& mask : {std::vector<std::uint8_t>(), sparse}) {
        b.compression = compression, b.scan_lines = scan_lines, b.mask = mask;
        const auto path = dir / "btflib.btf";
        b.Build().Save(path);
        SCOPED_TRACE(testing::Message() << "compression " << int(compression) << ", scan lines " << scan_lines
                                        << ", stored " << b.stored_count());
        const BonnReader r(path);
        EXPECT_EQ(r.header().stored_texels, b.stored_count());
        EXPECT_EQ(r.header().padding_abrdfs, b.padding_abrdfs());
        b.Expect(*OpenBonnSource(path));
        // btf-info: the padding is reported, and the statistics never see its NaNs.
        const auto j = DescribeBonnFile(path, /*with_stats=*/true);
        EXPECT_EQ(j.value("last_chunk_padding_abrdfs", std::uint64_t(0)), b.padding_abrdfs());
        EXPECT_EQ(j["values"]["nan_count"], 0) << j["values"].dump();
        EXPECT_EQ(j["values"]["count"], std::uint64_t(b.L.views) * b.L.lights * b.L.texels() * b.L.nc());
      }
  // The case did pad: 48 stored texels, 32 a chunk.
  b.compression = 2, b.scan_lines = 4, b.mask.clear();
  EXPECT_EQ(b.padding_abrdfs(), 16u);
  // btf-convert's library call reads it like the same file written with a short last chunk.
  b.Build().Save(dir / "padded.btf");
  b.pad = false;
  b.Build().Save(dir / "short.btf");
  ConvertOptions o;
  Convert(o, *OpenBonnSource(dir / "padded.btf"), dir / "padded.h5");
  Convert(o, *OpenBonnSource(dir / "short.btf"), dir / "short.h5");
  EXPECT_EQ(ReadDataset(dir / "padded.h5").data(), ReadDataset(dir / "short.h5").data());
}

TEST(BonnBtflib, ALastChunkOfAnyOtherSizeIsRefusedNamingBothForms) {
  const auto dir = test::TempDir();
  BtflibBdi b;
  b.L.width = 8;
  b.L.height = 6;
  Bytes f = b.Build();
  // Chunk 1's byte_size: after chunk 0 (4 + 32 ABRDFs).
  const std::size_t chunk1_at = f.size() - (4 + 32 * b.abrdf() * 2);
  for (std::size_t abrdfs : {std::size_t(17), std::size_t(31), std::size_t(33), std::size_t(40)}) {
    Bytes g = f;
    const auto bytes = std::uint32_t(abrdfs * b.abrdf() * 2);
    std::memcpy(g.b.data() + chunk1_at, &bytes, 4);
    g.b.resize(chunk1_at + 4 + bytes);  // the data fits the claim: only the size is wrong
    g.Save(dir / "bad.btf");
    const std::string what = test::BadInputOf([&] { (void)BonnReader(dir / "bad.btf"); });
    EXPECT_NE(what.find("bad.btf"), std::string::npos) << what;
    EXPECT_NE(what.find(fmt::format("chunk 1 byte_size at byte {}", chunk1_at)), std::string::npos) << what;
    EXPECT_NE(what.find(fmt::format("expected 16 ABRDFs x {} bytes", b.abrdf() * 2)), std::string::npos) << what;
    EXPECT_NE(what.find("padded to full scan lines"), std::string::npos) << what;
  }
  // A chunk before the last cannot be padded: it is full already, and a wrong size is refused
  // with the one form.
  Bytes g = f;
  const std::size_t chunk0_at = chunk1_at - (4 + 32 * b.abrdf() * 2);
  const auto bytes = std::uint32_t(16 * b.abrdf() * 2);
  std::memcpy(g.b.data() + chunk0_at, &bytes, 4);
  g.Save(dir / "bad.btf");
  const std::string what = test::BadInputOf([&] { (void)BonnReader(dir / "bad.btf"); });
  EXPECT_NE(what.find("chunk 0 byte_size"), std::string::npos) << what;
  EXPECT_EQ(what.find("padded"), std::string::npos) << what;
  // A padded file cut anywhere is refused.
  for (std::size_t n = f.size() - 40; n < f.size(); n += 7) {
    Bytes cut;
    cut.b.assign(f.b.begin(), f.b.begin() + std::ptrdiff_t(n));
    cut.Save(dir / "cut.btf");
    EXPECT_NE(test::BadInputOf([&] { (void)BonnReader(dir / "cut.btf"); }).find("cut.btf"), std::string::npos);
  }
}

// Peak resident memory of this process, bytes (each test runs in its own process under ctest).
double PeakRssBytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) * 1024;
}

// A file of a few hundred bytes claiming 32768 x 32768 texels: refused from the file size before
// the 1 GiB mask (or anything else that size) is allocated.
TEST(BonnBtflib, ClaimedSizesAreCheckedAgainstTheFileBeforeAllocating) {
  const auto dir = test::TempDir();
  Layout L;
  L.views = L.lights = 1;
  for (std::uint8_t compression : {std::uint8_t(0), std::uint8_t(2)}) {
    Bytes f;
    f.Text("!BDIF06R2!").Append(test::Meta(L)).Append(test::SamplingBlock(L));
    f.U32(32768).U32(32768).U32(4).U8(compression);
    for (int i = 0; i < 16; ++i) f.U8(1);
    f.Save(dir / "claims.btf");
    const double before = PeakRssBytes();
    const std::string what = test::BadInputOf([&] { (void)DescribeBonnFile(dir / "claims.btf", false); });
    EXPECT_LT(PeakRssBytes() - before, 64.0 * (1 << 20));
    EXPECT_NE(what.find("claims.btf"), std::string::npos) << what;
    EXPECT_NE(what.find("mask of 32768 x 32768 texels"), std::string::npos) << what;
    EXPECT_NE(what.find("needs 1073741824 bytes but the file ends at byte"), std::string::npos) << what;
  }
  // A mask that is all there but no chunks after it: refused before the per-texel table.
  Bytes f;
  f.Text("!BDIF06R2!").Append(test::Meta(L)).Append(test::SamplingBlock(L));
  f.U32(2048).U32(2048).U32(4).U8(2);
  for (int i = 0; i < 2048 * 2048; ++i) f.U8(i % 2);
  f.U32(0);
  f.Save(dir / "nochunks.btf");
  const std::string what = test::BadInputOf([&] { (void)BonnReader(dir / "nochunks.btf"); });
  EXPECT_NE(what.find("256 chunks of 2097152 stored ABRDFs x 6 bytes"), std::string::npos) << what;
}

}  // namespace
}  // namespace btf
