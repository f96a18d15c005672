#include "libbtf/eval/annotate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <optional>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

namespace btf {
namespace {

// Sets BTF_FONT for the lifetime of the object, restoring the previous value afterwards.
class ScopedFont {
 public:
  explicit ScopedFont(const char* value) {
    if (const char* old = std::getenv("BTF_FONT")) old_ = old;
    setenv("BTF_FONT", value, 1);
  }
  ~ScopedFont() {
    if (old_)
      setenv("BTF_FONT", old_->c_str(), 1);
    else
      unsetenv("BTF_FONT");
  }

 private:
  std::optional<std::string> old_;
};

// OpenImageIO's own "viridis" at t (linear values).
std::array<float, 3> OiioViridis(float t) {
  const OIIO::ImageBuf src(OIIO::ImageSpec(1, 1, 1, OIIO::TypeDesc::FLOAT), &t);
  const OIIO::ImageBuf m = OIIO::ImageBufAlgo::color_map(src, 0, "viridis");
  std::array<float, 3> rgb{};
  m.get_pixels(m.roi(), OIIO::TypeDesc::FLOAT, rgb.data());
  return rgb;
}

TEST(EvalAnnotate, FalseColorIsOpenImageIosViridis) {
  for (float t : {0.0f, 0.25f, 0.5f, 1.0f}) {
    float rgb[3];
    FalseColor(t, rgb);
    const auto want = OiioViridis(t);
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(rgb[k], want[k]) << t << " " << k;
  }
  // The ends are viridis' published ends, #440154 (dark blue) and #fde725 (yellow), to 1/255.
  float lo[3], hi[3];
  FalseColor(0, lo);
  FalseColor(1, hi);
  const float want_lo[3] = {0x44, 0x01, 0x54}, want_hi[3] = {0xfd, 0xe7, 0x25};
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(LinearToSrgb(lo[k]) * 255, want_lo[k], 1.0) << k;
    EXPECT_NEAR(LinearToSrgb(hi[k]) * 255, want_hi[k], 1.0) << k;
  }
}

TEST(EvalAnnotate, FalseColorImageScalesAndClamps) {
  const float values[6] = {0.0f, 2.0f, 4.0f, -1.0f, 9.0f, std::numeric_limits<float>::quiet_NaN()};
  const Image im = FalseColorImage(values, 3, 2, 4.0);  // full scale 4
  ASSERT_EQ(im.width, 3);
  ASSERT_EQ(im.height, 2);
  ASSERT_EQ(im.channels, 3);
  float lo[3], mid[3], hi[3];
  FalseColor(0, lo), FalseColor(0.5, mid), FalseColor(1, hi);
  for (int k = 0; k < 3; ++k) {
    EXPECT_FLOAT_EQ(im.at(0, 0, k), lo[k]);
    EXPECT_FLOAT_EQ(im.at(1, 0, k), mid[k]);
    EXPECT_FLOAT_EQ(im.at(2, 0, k), hi[k]);
    EXPECT_FLOAT_EQ(im.at(0, 1, k), lo[k]);  // below 0: clamped
    EXPECT_FLOAT_EQ(im.at(1, 1, k), hi[k]);  // above full scale: clamped
    EXPECT_FLOAT_EQ(im.at(2, 1, k), hi[k]);  // NaN shows as full scale
  }
}

TEST(EvalAnnotate, DrawTextMarksPixelsWhenTheFontExists) {
  if (LabelFont().empty()) GTEST_SKIP() << "no DejaVu Sans (fonts-dejavu-core) on this machine";
  Image im = Filled(120, 30, {1, 1, 1});
  ASSERT_TRUE(DrawText(im, 4, 4, "Hg 0.5%", 16, {0, 0, 0}));
  int dark = 0, outside = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      if (im.at(x, y, 0) < 0.5f) (x >= 4 && y >= 4 ? dark : outside)++;
  EXPECT_GT(dark, 40);  // strokes of six glyphs
  EXPECT_EQ(outside, 0);  // nothing above or left of the top-left corner
  const int w = TextWidth("Hg 0.5%", 16);
  EXPECT_GT(w, 30);
  EXPECT_LT(w, 110);
}

TEST(EvalAnnotate, MissingFontDrawsNothingAndSaysSo) {
  const ScopedFont none("/nonexistent/font.ttf");
  EXPECT_EQ(LabelFont(), "");
  Image im = Filled(60, 20, {1, 1, 1});
  EXPECT_FALSE(DrawText(im, 2, 2, "label", 14, {0, 0, 0}));
  for (float v : im.pixels) ASSERT_EQ(v, 1.0f);
  EXPECT_EQ(TextWidth("label", 14), 0);
}

TEST(EvalAnnotate, PasteWithZoomRepeatsPixels) {
  Image src(2, 1, 3);
  src.at(0, 0, 0) = 0.25f, src.at(1, 0, 1) = 0.75f;
  Image dst = Filled(8, 5, {1, 1, 1});
  Paste(dst, src, 1, 2, 3);
  for (int y = 0; y < dst.height; ++y)
    for (int x = 0; x < dst.width; ++x) {
      const bool inside = x >= 1 && x < 7 && y >= 2 && y < 5;
      const int sx = (x - 1) / 3;
      for (int k = 0; k < 3; ++k)
        EXPECT_EQ(dst.at(x, y, k), inside ? src.at(sx, 0, k) : 1.0f) << x << "," << y << " " << k;
    }
  // Parts outside the destination are cut off.
  Paste(dst, src, 7, 4, 3);
  EXPECT_EQ(dst.at(7, 4, 0), 0.25f);
}

}  // namespace
}  // namespace btf
