#pragma once
// Image files through OpenImageIO, loaded on first use with the image plugin (image_plugin.h).
// Pixels in memory are always linear float32, row-major,
// channel fastest, y down (row 0 = top of the picture).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace btf {

struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> pixels;
  Image() = default;
  Image(int w, int h, int c) : width(w), height(h), channels(c), pixels(std::size_t(w) * h * c, 0.0f) {}
  float& at(int x, int y, int c) { return pixels[(std::size_t(y) * width + x) * channels + c]; }
  float at(int x, int y, int c) const { return pixels[(std::size_t(y) * width + x) * channels + c]; }
};

enum class PixelFormat { kUint8, kUint16, kHalf, kFloat };

struct ImageWriteOptions {
  // Default: float for .exr, uint16 for .png/.tif, uint8 for .jpg.
  bool has_format = false;
  PixelFormat format = PixelFormat::kFloat;
  // Integer formats: encode with the sRGB transfer curve (true) or store linear values (false).
  bool srgb = false;
  int jpeg_quality = 0;  // JPEG quality 1..100; 0 = OpenImageIO's default (95)
};

// The default ImageReadOptions::max_pixels: 2^27 (134217728) pixels, a 100-megapixel camera's
// photo with room to spare; 4 channels of float32 take 2 GiB.
inline constexpr std::uint64_t kDefaultMaxImagePixels = std::uint64_t(1) << 27;

// How integer pixel values are decoded to linear (float files are always read as stored), and
// the largest image read.
struct ImageReadOptions {
  // "auto": the file's colour-space metadata (oiio:ColorSpace; sRGB if untagged PNG/JPEG), as
  // ReadImage(path); "linear": values as stored; "srgb": the sRGB curve; "gamma": v^gamma.
  std::string colorspace = "auto";
  double gamma = 2.2;  // with colorspace "gamma"
  // Width x height the header may claim (0: no limit but the allocation limit); checked before
  // any pixel is read, since a few compressed bytes can claim gigapixels. The tools' --max-pixels.
  std::uint64_t max_pixels = kDefaultMaxImagePixels;
  void Check() const;  // names the bad field
};

// Reads any format OpenImageIO reads. Integer files tagged sRGB (PNG and JPEG by default, or an
// "oiio:ColorSpace" of sRGB) are decoded to linear; everything else is read as stored and
// normalized to [0, 1] for integer types. Throws btf::Error naming the file.
Image ReadImage(const std::filesystem::path& path);
Image ReadImage(const std::filesystem::path& path, const ImageReadOptions& options);
// The same for the bytes of an image file held in memory (an entry of a zip archive, say): the
// extension of `name` picks the format, and messages name `name`. Formats OpenImageIO cannot
// decode from memory are btf::Error (bad input).
Image DecodeImage(const std::string& name, const std::string& bytes, const ImageReadOptions& options = {});
// Writes atomically. Values are clamped to the integer range for integer formats.
void WriteImage(const std::filesystem::path& path, const Image& image, const ImageWriteOptions& options = {});

float SrgbToLinear(float v);
float LinearToSrgb(float v);

}  // namespace btf
