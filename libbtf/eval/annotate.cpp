#include "libbtf/eval/annotate.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/io/image_plugin.h"

namespace btf {

std::string LabelFont() {
  if (const char* env = std::getenv("BTF_FONT")) {
    std::error_code ec;
    return std::filesystem::is_regular_file(env, ec) ? std::string(env) : std::string();
  }
  for (const char* path : {"/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", "/usr/share/fonts/TTF/DejaVuSans.ttf"}) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(path, ec)) return path;
  }
  return {};
}

bool DrawText(Image& image, int x, int y, const std::string& text, int size, const std::array<float, 3>& rgb) {
  if (text.empty()) return true;
  const std::string font = LabelFont();
  if (font.empty() || image.channels < 3) return false;
  std::vector<float> color(std::size_t(image.channels), 1.0f);
  std::copy(rgb.begin(), rgb.end(), color.begin());
  return LoadImagePlugin().RenderText(image, x, y, text, size, font, color);
}

int TextWidth(const std::string& text, int size) {
  const std::string font = LabelFont();
  if (font.empty() || text.empty()) return 0;
  int width = 0;
  return LoadImagePlugin().TextWidth(text, size, font, &width) ? width : 0;
}

Image FalseColorImage(const float* values, int width, int height, double full_scale) {
  std::vector<float> t(std::size_t(width) * height);
  for (std::size_t i = 0; i < t.size(); ++i) {
    const double v = full_scale > 0 ? values[i] / full_scale : 0.0;
    t[i] = std::isnan(v) ? 1.0f : float(std::clamp(v, 0.0, 1.0));
  }
  Image mapped;
  std::string error;
  if (!LoadImagePlugin().ColorMap(t.data(), width, height, "viridis", &mapped, &error))
    throw Error(ExitCode::kInternal, "OpenImageIO " + error);
  return mapped;  // OpenImageIO's maps are tabulated as linear values
}

void FalseColor(double t, float* rgb) {
  const float v = float(t);
  const Image px = FalseColorImage(&v, 1, 1, 1.0);
  std::copy_n(px.pixels.begin(), 3, rgb);
}

void Paste(Image& dst, const Image& src, int x, int y, int zoom) {
  if (src.channels != dst.channels) ThrowUsage("paste: channel counts differ ({} and {})", src.channels, dst.channels);
  if (zoom < 1) ThrowUsage("paste: zoom must be >= 1");
  std::string error;
  if (!LoadImagePlugin().Paste(dst, src, x, y, zoom, &error)) throw Error(ExitCode::kInternal, "OpenImageIO " + error);
}

Image Filled(int width, int height, const std::array<float, 3>& rgb, int channels) {
  Image im(width, height, channels);
  for (std::size_t i = 0; i < im.pixels.size(); ++i) {
    const int k = int(i % std::size_t(channels));
    im.pixels[i] = k < 3 ? rgb[k] : 0.0f;
  }
  return im;
}

Image ToDisplay(const Image& linear) {
  Image out = linear;
  for (float& v : out.pixels) v = LinearToSrgb(v);
  return out;
}

Image ToLinear(const Image& display) {
  Image out = display;
  for (float& v : out.pixels) v = SrgbToLinear(v);
  return out;
}

}  // namespace btf
