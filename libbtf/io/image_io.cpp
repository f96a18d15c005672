#include "libbtf/io/image_io.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/dataset.h"
#include "libbtf/core/error.h"
#include "libbtf/io/image_plugin.h"

namespace btf {

float SrgbToLinear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}
float LinearToSrgb(float v) {
  v = std::clamp(v, 0.0f, 1.0f);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

namespace {
std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// OpenEXR 3.1 allocates whatever size a header attribute claims before reading it, so a damaged
// header can cost gigabytes and seconds (found by fuzz_image). Walk the attribute list first
// (name\0 type\0 int32 size, value; one or more headers, each ending in an empty name) and refuse
// any attribute larger than the bytes left in the file. Files that are not OpenEXR pass through.
void CheckExrHeader(const std::string& name, const std::string& bytes) {
  const auto* head = reinterpret_cast<const unsigned char*>(bytes.data());
  if (bytes.size() < 8 || head[0] != 0x76 || head[1] != 0x2f || head[2] != 0x31 || head[3] != 0x01) return;
  const long long file_size = static_cast<long long>(bytes.size());
  const bool multipart = head[5] & 0x10;  // version flags: bit 12
  const auto fail = [&](const std::string& what) {
    ThrowBadInput("cannot read image '{}': corrupt OpenEXR header ({}); re-export or re-copy the file", name, what);
  };
  std::size_t pos = 8;
  const auto read_string = [&](std::string& out) {
    out.clear();
    for (;;) {
      if (pos >= bytes.size()) fail("truncated");
      const char c = bytes[pos++];
      if (c == 0) break;
      if (out.size() >= 255) fail("attribute name longer than 255 bytes");
      out.push_back(c);
    }
  };
  std::string attr, type;
  for (int header = 0, attributes = 0;; ++header) {
    read_string(attr);
    if (attr.empty()) {
      if (header == 0) fail("no attributes");
      break;  // single part: end of the header; multipart: the empty header ending the list
    }
    for (;; read_string(attr)) {
      if (attr.empty()) break;
      if (++attributes > 100000) fail("too many attributes");
      read_string(type);
      if (pos + 4 > bytes.size()) fail("truncated");
      const auto* b = head + pos;
      pos += 4;
      const std::int32_t size = std::int32_t(std::uint32_t(b[0]) | std::uint32_t(b[1]) << 8 | std::uint32_t(b[2]) << 16 |
                                             std::uint32_t(b[3]) << 24);
      const long long left = file_size - static_cast<long long>(pos);
      if (size < 0 || size > left)
        fail(fmt::format("attribute '{}' of type '{}' claims {} bytes, {} left in the file", attr, type, size, left));
      pos += static_cast<std::size_t>(size);
    }
    if (!multipart) break;
  }
}
}  // namespace

void ImageReadOptions::Check() const {
  BTF_CHECK_OPTION(colorspace == "auto" || colorspace == "linear" || colorspace == "srgb" || colorspace == "gamma",
                   "colorspace", "auto, linear, srgb or gamma");
  BTF_CHECK_OPTION(std::isfinite(gamma) && gamma >= 0.2 && gamma <= 5, "input-gamma", "0.2..5");
}

Image ReadImage(const std::filesystem::path& path) { return ReadImage(path, ImageReadOptions()); }

namespace {
// Decodes `bytes`, an image file whose format the extension of `name` gives; `name` is used in
// messages. Formats without I/O proxies are opened from `file`, or refused when there is none.
Image Decode(const std::string& name, const std::string& bytes, const ImageReadOptions& options,
             const std::filesystem::path* file) {
  CheckExrHeader(name, bytes);
  const ImagePlugin& plugin = LoadImagePlugin();
  // The reader is chosen by the extension and given the bytes. Formats without I/O proxies, or
  // unknown extensions, are opened from the file.
  const std::string ext = Lower(std::filesystem::path(name).extension().string());
  const std::string format = ext.empty() ? ext : ext.substr(1);
  std::unique_ptr<ImageReader> in;
  std::string error;
  const PluginStatus status =
      format.empty() ? PluginStatus::kUnsupported : plugin.OpenMemory(format, name, bytes, &in, &error);
  if (status == PluginStatus::kFailed) {
    ThrowBadInput("cannot read image '{}': {}", name, error);
  } else if (status == PluginStatus::kUnsupported && file) {
    in = plugin.OpenFile(file->string(), &error);
    if (!in) ThrowBadInput("cannot read image '{}': {}", name, error);
  } else if (status == PluginStatus::kUnsupported) {
    ThrowBadInput("cannot read image '{}': its format{} cannot be decoded from memory (only from a file): unpack it",
                  name, format.empty() ? "" : " '" + format + "'");
  }
  const ImageHeader& spec = in->header();
  if (spec.width < 1 || spec.height < 1 || spec.channels < 1)
    ThrowBadInput("image '{}' has an invalid size {}x{}x{}", name, spec.width, spec.height, spec.channels);
  if (spec.depth > 1)
    ThrowBadInput("image '{}' is a volume of {} slices: only 2-D images are read", name, spec.depth);
  const std::uint64_t pixels = std::uint64_t(spec.width) * std::uint64_t(spec.height);
  if (options.max_pixels > 0 && pixels > options.max_pixels)
    ThrowBadInput("image '{}' claims {} x {} = {} pixels, over the limit of {} (--max-pixels); if the image is real "
                  "and the machine has the memory ({:.3g} GiB for its {} channel(s) as float), pass --max-pixels {} "
                  "or more",
                  name, spec.width, spec.height, pixels, options.max_pixels,
                  4.0 * double(pixels) * spec.channels / double(1ull << 30), spec.channels, pixels);
  CheckAllocation(4.0 * spec.width * spec.height * spec.channels, "image '" + name + "'");
  Image img(spec.width, spec.height, spec.channels);
  if (!in->Read(img.pixels.data(), &error))
    ThrowBadInput("cannot decode image '{}' (truncated or corrupt?): {}", name, error);
  const bool integer = spec.integer;
  const std::string cs = Lower(spec.colorspace);
  bool srgb = integer && (cs == "srgb" || (cs.empty() && (ext == ".png" || ext == ".jpg" || ext == ".jpeg")));
  if (integer && options.colorspace != "auto") srgb = options.colorspace == "srgb";
  if (integer && options.colorspace == "gamma") {
    const float g = static_cast<float>(options.gamma);
    const int alpha = spec.alpha_channel;
    for (std::size_t i = 0; i < img.pixels.size(); ++i)
      if (static_cast<int>(i % std::size_t(spec.channels)) != alpha) img.pixels[i] = std::pow(std::max(img.pixels[i], 0.0f), g);
  }
  if (srgb) {
    const int alpha = spec.alpha_channel;
    for (std::size_t i = 0; i < img.pixels.size(); ++i)
      if (static_cast<int>(i % std::size_t(spec.channels)) != alpha) img.pixels[i] = SrgbToLinear(img.pixels[i]);
  }
  return img;
}

}  // namespace

Image ReadImage(const std::filesystem::path& path, const ImageReadOptions& options) {
  options.Check();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) ThrowIo("cannot read image '{}': no such file", path.string());
  // Read with checked system calls (a failing disk is an I/O error, not a corrupt image), then
  // decoded from memory.
  return Decode(path.string(), ReadFileBytes(path, "image"), options, &path);
}

Image DecodeImage(const std::string& name, const std::string& bytes, const ImageReadOptions& options) {
  options.Check();
  return Decode(name, bytes, options, nullptr);
}

void WriteImage(const std::filesystem::path& path, const Image& image, const ImageWriteOptions& options) {
  const std::string ext = Lower(path.extension().string());
  PixelFormat fmt = options.format;
  if (!options.has_format) fmt = ext == ".exr" ? PixelFormat::kFloat : (ext == ".jpg" ? PixelFormat::kUint8 : PixelFormat::kUint16);
  std::vector<float> buf = image.pixels;
  const bool integer = fmt == PixelFormat::kUint8 || fmt == PixelFormat::kUint16;
  for (auto& v : buf) {
    if (!std::isfinite(v)) v = 0;
    if (integer) v = options.srgb ? LinearToSrgb(v) : std::clamp(v, 0.0f, 1.0f);
  }
  ImageEncoding encoding;
  encoding.format = fmt;
  encoding.srgb = integer && options.srgb;
  encoding.exr_zip = ext == ".exr";
  if ((ext == ".jpg" || ext == ".jpeg") && options.jpeg_quality > 0) encoding.jpeg_quality = std::clamp(options.jpeg_quality, 1, 100);
  const ImagePlugin& plugin = LoadImagePlugin();
  // Encoded in memory, then written by WriteFileAtomic, whose every write is checked: OpenImageIO
  // 2.4 does not check the buffered writes its file layer flushes at close (a full disk would
  // pass unnoticed). Formats without I/O proxies are written to a temporary file directly.
  std::vector<unsigned char> bytes;
  bool writer_found = false;
  std::string error;
  const PluginStatus status = plugin.Encode(path.string(), image.width, image.height, image.channels, encoding,
                                            buf.data(), &bytes, &writer_found, &error);
  if (status == PluginStatus::kOk) {
    WriteFileAtomic(path, bytes.data(), bytes.size());
    return;
  }
  if (!writer_found) ThrowUsage("cannot write image '{}': unsupported file type '{}'", path.string(), ext);
  if (status == PluginStatus::kFailed) ThrowIo("cannot encode image '{}': {}", path.string(), error);
  AtomicOutput out(path);
  if (!plugin.WriteFile(path.string(), out.temp_path().string(), image.width, image.height, image.channels, encoding,
                        buf.data(), &error))
    ThrowIo("cannot write image '{}': {}", path.string(), error);
  out.Commit();
}

}  // namespace btf
