#pragma once
// The image plugin: libbtf's only code that calls OpenImageIO lives in a shared module,
// libbtf_oiio.so (libbtf/io/oiio/oiio_plugin.cpp), loaded with dlopen() the first time an image is
// read or written or a picture annotated (docs/architecture.md, "The image plugin"). Neither the
// libbtf libraries nor the tools link OpenImageIO, whose ~260 shared libraries would otherwise be
// loaded and initialised at every start of every program (~0.45 s).
//
// The plugin implements ImagePlugin. It links OpenImageIO only, not libbtf, and never throws
// (but std::bad_alloc): every call returns whether it worked and fills `error`; image_io.cpp and
// eval/annotate.cpp turn that into btf::Error.
#include <memory>
#include <string>
#include <vector>

#include "libbtf/io/image_io.h"

namespace btf {

// Bumped whenever ImagePlugin or the structs below change: a plugin of another version is refused.
inline constexpr int kImagePluginAbi = 1;

// What an image file's header says, read before any pixel is.
struct ImageHeader {
  int width = 0, height = 0, channels = 0, depth = 1;
  bool integer = false;    // stored as an integer type (not float, half or double)
  std::string colorspace;  // "oiio:ColorSpace", as stored ("" when untagged)
  int alpha_channel = -1;
};

class ImageReader {
 public:
  virtual ~ImageReader() = default;
  virtual const ImageHeader& header() const = 0;
  // Every channel of the first subimage as float32 into `pixels` (width * height * channels).
  virtual bool Read(float* pixels, std::string* error) = 0;
};

// How WriteImage encodes: the pixel type and the metadata it sets.
struct ImageEncoding {
  PixelFormat format = PixelFormat::kFloat;
  bool srgb = false;       // tagged sRGB (else linear)
  bool exr_zip = false;    // OpenEXR zip compression
  int jpeg_quality = 0;    // > 0: "Compression" = "jpeg:<quality>"
};

enum class PluginStatus {
  kOk,
  kUnsupported,  // no reader/writer for the extension, or it cannot work on memory (I/O proxies)
  kFailed,       // the reader/writer failed: `error` says why
};

class ImagePlugin {
 public:
  virtual ~ImagePlugin() = default;
  // The bytes of an image file in memory, in the format named by `format` (an extension without
  // its dot); `name` is what messages call it. `bytes` must outlive the reader.
  virtual PluginStatus OpenMemory(const std::string& format, const std::string& name, const std::string& bytes,
                                  std::unique_ptr<ImageReader>* reader, std::string* error) const = 0;
  virtual std::unique_ptr<ImageReader> OpenFile(const std::string& path, std::string* error) const = 0;

  // Encodes `pixels` (float32, already clamped and curved as `encoding.format` needs) as the type
  // the extension of `path` names, into `bytes`. kUnsupported when no writer takes the extension
  // (`*writer_found` false) or the writer cannot encode to memory (`*writer_found` true: use
  // WriteFile).
  virtual PluginStatus Encode(const std::string& path, int width, int height, int channels, const ImageEncoding& encoding,
                              const float* pixels, std::vector<unsigned char>* bytes, bool* writer_found,
                              std::string* error) const = 0;
  // The same written to the file `file` by the writer the extension of `path` names.
  virtual bool WriteFile(const std::string& path, const std::string& file, int width, int height, int channels,
                         const ImageEncoding& encoding, const float* pixels, std::string* error) const = 0;

  // ImageBufAlgo::render_text onto `image` (top-left aligned); false when it could not.
  virtual bool RenderText(Image& image, int x, int y, const std::string& text, int size, const std::string& font,
                          const std::vector<float>& color) const = 0;
  // ImageBufAlgo::text_size's width; false when it could not measure.
  virtual bool TextWidth(const std::string& text, int size, const std::string& font, int* width) const = 0;
  // ImageBufAlgo::color_map(`map`) of a one-channel width x height plane.
  virtual bool ColorMap(const float* values, int width, int height, const std::string& map, Image* out,
                        std::string* error) const = 0;
  // `src` resampled `zoom` times (nearest pixel) and pasted into `dst` at (x, y); `error` starts
  // with the ImageBufAlgo function that failed.
  virtual bool Paste(Image& dst, const Image& src, int x, int y, int zoom, std::string* error) const = 0;
};

// The plugin's one exported symbol: returns its ImagePlugin (a static object), or null when
// `abi` is not its kImagePluginAbi.
using ImagePluginEntry = const ImagePlugin* (*)(int abi);
inline constexpr const char* kImagePluginEntry = "btf_image_plugin";
inline constexpr const char* kImagePluginFile = "libbtf_oiio.so";

// The plugin, loaded on the first call (thread-safe) and kept for the life of the process.
// Looked for in $BTF_PLUGIN_DIR when that is set, else beside the program or library holding
// libbtf's code (the relative places the build and install trees put it), then in the install
// prefix. Throws btf::Error (I/O) naming the places tried and what to do when it cannot be loaded.
const ImagePlugin& LoadImagePlugin();

}  // namespace btf
