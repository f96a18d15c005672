#include "libbtf/io/image_io.h"

#include <sys/resource.h>

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <string>

#include "libbtf/core/error.h"
#include "libbtf/io/image_plugin.h"
#include "tests/test_util.h"

namespace btf {
namespace {

Image Ramp(int w, int h, int c) {
  Image img(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) img.at(x, y, k) = 0.9f * float(x + w * y) / float(w * h) + 0.01f * k;
  return img;
}

TEST(ImageIo, ExrFloatIsExactAndHalfIsClose) {
  const auto dir = test::TempDir();
  Image img = Ramp(17, 9, 3);
  img.at(3, 4, 1) = 1234.5f;  // HDR values survive EXR
  WriteImage(dir / "f.exr", img);
  const Image r = ReadImage(dir / "f.exr");
  ASSERT_EQ(r.width, 17);
  ASSERT_EQ(r.channels, 3);
  EXPECT_EQ(r.pixels, img.pixels);
  ImageWriteOptions half;
  half.has_format = true;
  half.format = PixelFormat::kHalf;
  WriteImage(dir / "h.exr", img, half);
  const Image rh = ReadImage(dir / "h.exr");
  for (std::size_t i = 0; i < img.pixels.size(); ++i)
    EXPECT_NEAR(rh.pixels[i], img.pixels[i], std::abs(img.pixels[i]) * 1e-3 + 1e-4);
}

TEST(ImageIo, Png16LinearRoundTripsToQuantization) {
  const auto dir = test::TempDir();
  const Image img = Ramp(20, 10, 4);
  WriteImage(dir / "a.png", img);  // default: 16-bit, linear values, tagged linear
  const Image r = ReadImage(dir / "a.png");
  ASSERT_EQ(r.channels, 4);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) EXPECT_NEAR(r.pixels[i], img.pixels[i], 0.5 / 65535 + 1e-7);
}

TEST(ImageIo, Srgb8BitIsDecodedToLinear) {
  const auto dir = test::TempDir();
  Image img(4, 1, 3);
  const float values[] = {0.0f, 0.05f, 0.2f, 0.9f};
  for (int x = 0; x < 4; ++x)
    for (int c = 0; c < 3; ++c) img.at(x, 0, c) = values[x];
  ImageWriteOptions opt;
  opt.has_format = true;
  opt.format = PixelFormat::kUint8;
  opt.srgb = true;
  WriteImage(dir / "s.png", img, opt);
  const Image r = ReadImage(dir / "s.png");
  // 8-bit sRGB steps are at most about 0.9 % of the linear value above 0.05 (plus tiny near 0).
  for (int x = 0; x < 4; ++x) EXPECT_NEAR(r.at(x, 0, 0), values[x], 0.01 * values[x] + 2e-4);
  EXPECT_NEAR(SrgbToLinear(LinearToSrgb(0.3f)), 0.3f, 1e-6);
}

TEST(ImageIo, ErrorsNameTheFile) {
  const auto dir = test::TempDir();
  try {
    ReadImage(dir / "nope.png");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kIo);
    EXPECT_NE(std::string(e.what()).find("nope.png"), std::string::npos);
  }
  EXPECT_THROW(WriteImage(dir / "x.unknownext", Ramp(2, 2, 1)), Error);
}

// Regression (fuzz_image): OpenEXR allocates what a header attribute claims before reading it, so
// a damaged size field cost gigabytes; ReadImage refuses it from the header walk, naming the item.
TEST(ImageIo, ExrAttributeClaimingMoreThanTheFileIsRefused) {
  const auto dir = test::TempDir();
  WriteImage(dir / "ok.exr", Ramp(5, 4, 3));
  std::ifstream in(dir / "ok.exr", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string key("channels\0chlist\0", 16);
  const auto at = bytes.find(key);
  ASSERT_NE(at, std::string::npos);
  for (int i = 0; i < 4; ++i) bytes[at + key.size() + i] = i == 3 ? '\x7f' : '\xff';  // size 2^31 - 1
  std::ofstream(dir / "bad.exr", std::ios::binary) << bytes;
  try {
    ReadImage(dir / "bad.exr");
    FAIL() << "damaged EXR header accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    const std::string what = e.what();
    EXPECT_NE(what.find("bad.exr"), std::string::npos) << what;
    EXPECT_NE(what.find("'channels'"), std::string::npos) << what;
  }
  EXPECT_EQ(ReadImage(dir / "ok.exr").width, 5);  // the walk accepts what we write
}

// ---- claimed sizes (ImageReadOptions::max_pixels) ----

std::uint32_t Crc32(const std::string& bytes) {  // PNG's CRC (ISO 3309), bit by bit
  std::uint32_t c = 0xffffffffu;
  for (unsigned char b : bytes) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}

std::string Be32(std::uint32_t v) {
  return {char(v >> 24), char(v >> 16), char(v >> 8), char(v)};
}

std::string PngChunk(const std::string& type, const std::string& data) {
  return Be32(std::uint32_t(data.size())) + type + data + Be32(Crc32(type + data));
}

// A 69-byte PNG whose header claims width x height 8-bit RGB pixels; its one IDAT holds a
// 12-byte zlib stream (a valid header and deflate block, far too short for the image).
std::string ClaimingPng(std::uint32_t width, std::uint32_t height) {
  const std::string ihdr = Be32(width) + Be32(height) + std::string("\x08\x02\x00\x00\x00", 5);
  const std::string idat("\x78\x9c\x63\x60\x00\x00\x00\x02\x00\x01\x00\x00", 12);
  return std::string("\x89PNG\r\n\x1a\n", 8) + PngChunk("IHDR", ihdr) + PngChunk("IDAT", idat) + PngChunk("IEND", "");
}

double PeakRssBytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) * 1024;
}

// A few bytes can claim gigapixels (a 30000 x 30000 RGB image as float: 10 GB): the header's size
// is checked against max_pixels before any pixel is allocated or read, and the message says what
// to pass.
TEST(ImageIo, HeaderClaimingMorePixelsThanTheLimitIsRefusedBeforeReading) {
  const auto dir = test::TempDir();
  const std::string png = ClaimingPng(30000, 30000);
  ASSERT_EQ(png.size(), 69u);
  std::ofstream(dir / "huge.png", std::ios::binary) << png;
  (void)LoadImagePlugin();  // OpenImageIO's own libraries (~110 MB) load on first use: not counted
  const double before = PeakRssBytes();
  std::string what = test::BadInputOf([&] { ReadImage(dir / "huge.png"); });
  EXPECT_LT(PeakRssBytes() - before, 64.0 * (1 << 20));
  for (const char* part : {"huge.png", "30000 x 30000 = 900000000 pixels", "over the limit of 134217728",
                           "pass --max-pixels 900000000"})
    EXPECT_NE(what.find(part), std::string::npos) << what << " / " << part;
  // From memory (an entry of a zip archive) the same.
  what = test::BadInputOf([&] { DecodeImage("set.zip:huge.png", png); });
  EXPECT_NE(what.find("set.zip:huge.png"), std::string::npos) << what;
  // Raised above the claim, the file is read, and found to be short: still bad input, no crash.
  ImageReadOptions small;
  small.max_pixels = 1000;
  std::ofstream(dir / "short.png", std::ios::binary) << ClaimingPng(30, 30);
  what = test::BadInputOf([&] { ReadImage(dir / "short.png", small); });
  EXPECT_EQ(what.find("--max-pixels"), std::string::npos) << what;
}

TEST(ImageIo, MaxPixelsIsInclusiveAndZeroMeansNoLimit) {
  const auto dir = test::TempDir();
  WriteImage(dir / "r.png", Ramp(64, 48, 3));
  ImageReadOptions o;
  o.max_pixels = 64 * 48;
  EXPECT_EQ(ReadImage(dir / "r.png", o).width, 64);
  o.max_pixels = 64 * 48 - 1;
  EXPECT_NE(test::BadInputOf([&] { ReadImage(dir / "r.png", o); }).find("pass --max-pixels 3072"), std::string::npos);
  o.max_pixels = 0;
  EXPECT_EQ(ReadImage(dir / "r.png", o).height, 48);
  EXPECT_EQ(ImageReadOptions().max_pixels, std::uint64_t(1) << 27);
}

}  // namespace
}  // namespace btf
