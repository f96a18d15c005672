// libbtf_oiio.so: every call libbtf makes to OpenImageIO (libbtf/io/image_plugin.h). A shared
// module loaded with dlopen() on first use, so that programs which read or write no image never
// load OpenImageIO. It links OpenImageIO only (libbtf's types here are header-only) and reports
// failures as return values: exceptions stay on libbtf's side.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <memory>
#include <string>
#include <vector>

#include "libbtf/io/image_plugin.h"

namespace btf {
namespace {

// Measurement data: a 4th channel is data, never premultiplied alpha to be (un)associated.
OIIO::ImageSpec ReadConfig() {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  return config;
}

class OiioReader final : public ImageReader {
 public:
  // `proxy` (may be null) is what `in` reads from; kept alive as long as the reader.
  OiioReader(std::unique_ptr<OIIO::Filesystem::IOMemReader> proxy, std::unique_ptr<OIIO::ImageInput> in)
      : proxy_(std::move(proxy)), in_(std::move(in)) {
    const OIIO::ImageSpec& spec = in_->spec();
    header_.width = spec.width;
    header_.height = spec.height;
    header_.channels = spec.nchannels;
    header_.depth = spec.depth;
    header_.integer = spec.format.basetype != OIIO::TypeDesc::FLOAT && spec.format.basetype != OIIO::TypeDesc::HALF &&
                      spec.format.basetype != OIIO::TypeDesc::DOUBLE;
    header_.colorspace = spec.get_string_attribute("oiio:ColorSpace");
    header_.alpha_channel = spec.alpha_channel;
  }
  const ImageHeader& header() const override { return header_; }
  bool Read(float* pixels, std::string* error) override {
    if (in_->read_image(0, 0, 0, header_.channels, OIIO::TypeDesc::FLOAT, pixels)) return true;
    *error = in_->geterror();
    return false;
  }

 private:
  std::unique_ptr<OIIO::Filesystem::IOMemReader> proxy_;
  std::unique_ptr<OIIO::ImageInput> in_;
  ImageHeader header_;
};

OIIO::ImageSpec WriteSpec(int width, int height, int channels, const ImageEncoding& encoding, const std::string& path) {
  const PixelFormat fmt = encoding.format;
  const OIIO::TypeDesc type = fmt == PixelFormat::kUint8    ? OIIO::TypeDesc::UINT8
                              : fmt == PixelFormat::kUint16 ? OIIO::TypeDesc::UINT16
                              : fmt == PixelFormat::kHalf   ? OIIO::TypeDesc::HALF
                                                            : OIIO::TypeDesc::FLOAT;
  OIIO::ImageSpec spec(width, height, channels, type);
  spec.attribute("oiio:ColorSpace", encoding.srgb ? "sRGB" : "linear");
  spec.alpha_channel = -1;
  spec.attribute("oiio:UnassociatedAlpha", 1);
  if (encoding.exr_zip) spec.attribute("compression", "zip");
  if (encoding.jpeg_quality > 0) spec.attribute("Compression", "jpeg:" + std::to_string(encoding.jpeg_quality));
  return spec;
}

OIIO::ImageSpec SpecOf(const Image& image) {
  return OIIO::ImageSpec(image.width, image.height, image.channels, OIIO::TypeDesc::FLOAT);
}

class OiioPlugin final : public ImagePlugin {
 public:
  PluginStatus OpenMemory(const std::string& format, const std::string& name, const std::string& bytes,
                          std::unique_ptr<ImageReader>* reader, std::string* error) const override {
    auto proxy = std::make_unique<OIIO::Filesystem::IOMemReader>(bytes.data(), bytes.size());
    OIIO::ImageSpec config = ReadConfig();  // OpenImageIO 2.4 readers take the proxy from the config at open
    void* proxy_ptr = proxy.get();
    config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy_ptr);
    // The reader is chosen by the extension and given the bytes; OpenImageIO 2.4's open(name, ...)
    // would read the file again from disk.
    auto in = OIIO::ImageInput::create(format, false, &config, proxy.get());
    if (!in || !in->supports("ioproxy")) return PluginStatus::kUnsupported;
    OIIO::ImageSpec opened;
    if (!in->open(name, opened, config)) {
      *error = in->geterror();
      return PluginStatus::kFailed;
    }
    *reader = std::make_unique<OiioReader>(std::move(proxy), std::move(in));
    return PluginStatus::kOk;
  }

  std::unique_ptr<ImageReader> OpenFile(const std::string& path, std::string* error) const override {
    const OIIO::ImageSpec config = ReadConfig();
    auto in = OIIO::ImageInput::open(path, &config);
    if (!in) {
      *error = OIIO::geterror();
      return nullptr;
    }
    return std::make_unique<OiioReader>(nullptr, std::move(in));
  }

  PluginStatus Encode(const std::string& path, int width, int height, int channels, const ImageEncoding& encoding,
                      const float* pixels, std::vector<unsigned char>* bytes, bool* writer_found,
                      std::string* error) const override {
    auto writer = OIIO::ImageOutput::create(path);
    *writer_found = writer != nullptr;
    if (!writer || !writer->supports("ioproxy")) return PluginStatus::kUnsupported;
    OIIO::Filesystem::IOVecOutput proxy(*bytes);
    if (!writer->set_ioproxy(&proxy) || !writer->open(path, WriteSpec(width, height, channels, encoding, path)) ||
        !writer->write_image(OIIO::TypeDesc::FLOAT, pixels) || !writer->close() || writer->has_error()) {
      *error = writer->geterror();
      return PluginStatus::kFailed;
    }
    return PluginStatus::kOk;
  }

  bool WriteFile(const std::string& path, const std::string& file, int width, int height, int channels,
                 const ImageEncoding& encoding, const float* pixels, std::string* error) const override {
    auto writer = OIIO::ImageOutput::create(path);
    if (!writer) {
      *error = OIIO::geterror();
      return false;
    }
    if (!writer->open(file, WriteSpec(width, height, channels, encoding, path)) ||
        !writer->write_image(OIIO::TypeDesc::FLOAT, pixels) || !writer->close() || writer->has_error()) {
      *error = writer->geterror();
      return false;
    }
    return true;
  }

  bool RenderText(Image& image, int x, int y, const std::string& text, int size, const std::string& font,
                  const std::vector<float>& color) const override {
    OIIO::ImageBuf buf(SpecOf(image), image.pixels.data());  // writes straight into the image's pixels
    const bool ok = OIIO::ImageBufAlgo::render_text(buf, x, y, text, size, font, color,
                                                    OIIO::ImageBufAlgo::TextAlignX::Left,
                                                    OIIO::ImageBufAlgo::TextAlignY::Top);
    if (!ok) (void)buf.geterror();  // clear it: the caller reports the missing text
    return ok;
  }

  bool TextWidth(const std::string& text, int size, const std::string& font, int* width) const override {
    const OIIO::ROI r = OIIO::ImageBufAlgo::text_size(text, size, font);
    if (!r.defined()) {
      (void)OIIO::geterror();
      return false;
    }
    *width = r.width();
    return true;
  }

  bool ColorMap(const float* values, int width, int height, const std::string& map, Image* out,
                std::string* error) const override {
    // Wraps the caller's values without a copy; color_map only reads them.
    const OIIO::ImageBuf src(OIIO::ImageSpec(width, height, 1, OIIO::TypeDesc::FLOAT), const_cast<float*>(values));
    const OIIO::ImageBuf mapped = OIIO::ImageBufAlgo::color_map(src, 0, map);
    if (mapped.has_error()) {
      *error = "color_map: " + mapped.geterror();
      return false;
    }
    const OIIO::ImageSpec& spec = mapped.spec();
    *out = Image(spec.width, spec.height, spec.nchannels);
    if (!mapped.get_pixels(mapped.roi(), OIIO::TypeDesc::FLOAT, out->pixels.data())) {
      *error = "get_pixels: " + mapped.geterror();
      return false;
    }
    return true;
  }

  bool Paste(Image& dst, const Image& src, int x, int y, int zoom, std::string* error) const override {
    Image copy = src;
    OIIO::ImageBuf from(SpecOf(copy), copy.pixels.data());
    if (zoom > 1) {
      OIIO::ROI roi(0, src.width * zoom, 0, src.height * zoom, 0, 1, 0, src.channels);
      from = OIIO::ImageBufAlgo::resample(from, /*interpolate=*/false, roi);
      if (from.has_error()) {
        *error = "resample: " + from.geterror();
        return false;
      }
    }
    OIIO::ImageBuf to(SpecOf(dst), dst.pixels.data());
    if (!OIIO::ImageBufAlgo::paste(to, x, y, 0, 0, from)) {
      *error = "paste: " + to.geterror();
      return false;
    }
    return true;
  }
};

}  // namespace
}  // namespace btf

extern "C" __attribute__((visibility("default"))) const btf::ImagePlugin* btf_image_plugin(int abi) {
  static const btf::OiioPlugin plugin;
  return abi == btf::kImagePluginAbi ? &plugin : nullptr;
}
