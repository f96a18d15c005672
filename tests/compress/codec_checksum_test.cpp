// Codec files refuse damage instead of decoding to other values (docs/format.md, "Checksums"):
// every array and string a libbtf writer stores is checksummed (compact datasets inside HDF5
// 1.10's checksummed object headers, larger ones in Fletcher-32 chunks), and so is the metadata.
// A flipped bit anywhere in a small codec file is refused (btf::Error) or leaves every decoded
// value as it was (a bit HDF5 does not use).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "libbtf/compress/codec.h"
#include "libbtf/core/error.h"
#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"
#include "tests/test_util.h"

namespace btf {
namespace {

namespace fs = std::filesystem;

std::string Bytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), {}};
}

struct FlipCounts {
  int refused = 0, unchanged = 0, changed = 0;
};

// Flips one bit of every `stride`-th byte of the codec file at `path` in turn (bit i % 8 of byte
// i) and decodes what reads.
FlipCounts FlipEveryByte(const fs::path& path, std::size_t stride) {
  const std::string original = Bytes(path);
  const Dataset reference = ReadCodec(path).DecodeAll();
  const fs::path damaged = path.parent_path() / "damaged.h5";
  FlipCounts n;
  for (std::size_t i = 0; i < original.size(); i += stride) {
    std::string bytes = original;
    bytes[i] = char(bytes[i] ^ (1 << (i % 8)));
    std::ofstream(damaged, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
    try {
      const Dataset d = ReadCodec(damaged).DecodeAll();
      if (d.data() == reference.data()) ++n.unchanged;
      else {
        ++n.changed;
        ADD_FAILURE() << path.filename() << ": the flip at byte " << i << " of " << original.size()
                      << " was accepted and changed decoded values";
      }
    } catch (const Error&) {
      ++n.refused;
    }
  }
  return n;
}

// A pca-view codec flipped at every byte; the other methods at every 7th (their arrays sit in the
// same two kinds of storage). The sanitizer build takes every 5th / 31st byte: the same storage
// kinds at a fifth of the time.
TEST(CodecChecksums, AFlippedBitIsRefusedOrChangesNothing) {
#ifdef BTF_SANITIZER_BUILD
  const std::size_t first = 5, others = 31;
#else
  const std::size_t first = 1, others = 7;
#endif
  const Dataset d = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(4), 6, 6, 2, 0.05);
  const fs::path dir = test::TempDir();
  struct Case {
    const char* name;
    CodecMethod method;
  };
  bool pca_view = true;
  for (const Case& c : {Case{"pca-view", CodecMethod::kPcaView}, Case{"lpca", CodecMethod::kLpca},
                        Case{"lpca-tensor", CodecMethod::kLpcaTensor}, Case{"fmf", CodecMethod::kFmf},
                        Case{"neural", CodecMethod::kNeural}}) {
    SCOPED_TRACE(c.name);
    CompressOptions o;
    o.method = c.method;
    o.components = 2;
    o.clusters = 2;
    o.neural.steps = 5;
    o.neural.samples = 512;
    o.neural.batch = 256;
    const fs::path path = dir / (std::string(c.name) + ".h5");
    WriteCodec(path, test::CompressDataset(d, o));
    const FlipCounts n = FlipEveryByte(path, pca_view ? first : others);
    pca_view = false;
    EXPECT_EQ(n.changed, 0);
    EXPECT_GT(n.refused, 0);
    RecordProperty(std::string(c.name) + "_refused", n.refused);
    RecordProperty(std::string(c.name) + "_unchanged", n.unchanged);
  }
}

}  // namespace
}  // namespace btf
