#include "libbtf/io/image_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <string>

#include "libbtf/core/error.h"
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

}  // namespace
}  // namespace btf
