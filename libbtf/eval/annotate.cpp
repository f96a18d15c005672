#include "libbtf/eval/annotate.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <vector>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include "libbtf/core/error.h"

namespace btf {

namespace {

namespace oiio = OIIO;

[[noreturn]] void ThrowOiio(const char* what, const std::string& message) {
  throw Error(ExitCode::kInternal, fmt::format("OpenImageIO {}: {}", what, message));
}

oiio::ImageSpec SpecOf(const Image& image) {
  return oiio::ImageSpec(image.width, image.height, image.channels, oiio::TypeDesc::FLOAT);
}

// An ImageBuf over the image's own pixels (no copy): ImageBufAlgo writes straight into them.
oiio::ImageBuf Wrap(Image& image) { return oiio::ImageBuf(SpecOf(image), image.pixels.data()); }

Image FromBuf(const oiio::ImageBuf& buf) {
  const oiio::ImageSpec& spec = buf.spec();
  Image out(spec.width, spec.height, spec.nchannels);
  if (!buf.get_pixels(buf.roi(), oiio::TypeDesc::FLOAT, out.pixels.data()))
    ThrowOiio("get_pixels", buf.geterror());
  return out;
}

}  // namespace

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
  oiio::ImageBuf buf = Wrap(image);
  const bool ok = oiio::ImageBufAlgo::render_text(buf, x, y, text, size, font, color, oiio::ImageBufAlgo::TextAlignX::Left,
                                                  oiio::ImageBufAlgo::TextAlignY::Top);
  if (!ok) (void)buf.geterror();  // clear it: the caller reports the missing text
  return ok;
}

int TextWidth(const std::string& text, int size) {
  const std::string font = LabelFont();
  if (font.empty() || text.empty()) return 0;
  const oiio::ROI r = oiio::ImageBufAlgo::text_size(text, size, font);
  if (!r.defined()) {
    (void)oiio::geterror();
    return 0;
  }
  return r.width();
}

Image FalseColorImage(const float* values, int width, int height, double full_scale) {
  std::vector<float> t(std::size_t(width) * height);
  for (std::size_t i = 0; i < t.size(); ++i) {
    const double v = full_scale > 0 ? values[i] / full_scale : 0.0;
    t[i] = std::isnan(v) ? 1.0f : float(std::clamp(v, 0.0, 1.0));
  }
  const oiio::ImageBuf src(oiio::ImageSpec(width, height, 1, oiio::TypeDesc::FLOAT), t.data());
  const oiio::ImageBuf mapped = oiio::ImageBufAlgo::color_map(src, 0, "viridis");
  if (mapped.has_error()) ThrowOiio("color_map", mapped.geterror());
  return FromBuf(mapped);  // OpenImageIO's maps are tabulated as linear values
}

void FalseColor(double t, float* rgb) {
  const float v = float(t);
  const Image px = FalseColorImage(&v, 1, 1, 1.0);
  std::copy_n(px.pixels.begin(), 3, rgb);
}

void Paste(Image& dst, const Image& src, int x, int y, int zoom) {
  if (src.channels != dst.channels) ThrowUsage("paste: channel counts differ ({} and {})", src.channels, dst.channels);
  if (zoom < 1) ThrowUsage("paste: zoom must be >= 1");
  Image copy = src;
  oiio::ImageBuf from = Wrap(copy);
  if (zoom > 1) {
    oiio::ROI roi(0, src.width * zoom, 0, src.height * zoom, 0, 1, 0, src.channels);
    from = oiio::ImageBufAlgo::resample(from, /*interpolate=*/false, roi);
    if (from.has_error()) ThrowOiio("resample", from.geterror());
  }
  oiio::ImageBuf to = Wrap(dst);
  if (!oiio::ImageBufAlgo::paste(to, x, y, 0, 0, from)) ThrowOiio("paste", to.geterror());
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
