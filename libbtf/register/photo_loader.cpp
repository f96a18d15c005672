#include "libbtf/register/photo_loader.h"

#include <algorithm>
#include <cmath>

#include "libbtf/core/error.h"

namespace btf::register_detail {
namespace {

void CheckSameSize(const Image& a, const Image& b, const std::string& fa, const std::string& fb) {
  if (a.width != b.width || a.height != b.height || a.channels != b.channels)
    ThrowBadInput("'{}' is {}x{} px with {} channel(s) but '{}' is {}x{} with {}: the photos and reference frames "
                  "must have one size",
                  fa, a.width, a.height, a.channels, fb, b.width, b.height, b.channels);
}

// The relative illumination gain of a flat field (dark frame already subtracted): divided by its
// mean over the central tenth of the image (width and height / 10), per channel; `path` names it
// in errors.
Image FlatFieldGain(Image flat, const std::filesystem::path& path) {
  const int C = flat.channels, x0 = flat.width * 9 / 20, x1 = std::max(x0 + 1, flat.width * 11 / 20),
            y0 = flat.height * 9 / 20, y1 = std::max(y0 + 1, flat.height * 11 / 20);
  std::vector<double> center(static_cast<std::size_t>(C), 0.0);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x)
      for (int c = 0; c < C; ++c) center[static_cast<std::size_t>(c)] += flat.at(x, y, c);
  for (int c = 0; c < C; ++c) {
    const double mean = center[static_cast<std::size_t>(c)] / double((x1 - x0) * (y1 - y0));
    if (!(mean > 0.01))
      ThrowBadInput("'{}': channel {} is {:.3g} of full scale at the image center (dark frame subtracted): a flat "
                    "field must be a photo of a uniformly lit white target filling the frame",
                    path.string(), c, mean);
    for (int y = 0; y < flat.height; ++y)
      for (int x = 0; x < flat.width; ++x) {
        float& g = flat.at(x, y, c);
        g = static_cast<float>(g / mean);
        // A flat field is a photo of a uniformly lit white target: nowhere near black.
        if (!(g >= 0.05f))
          ThrowBadInput("'{}': pixel ({}, {}) channel {} is {:.3g} of the image center's level (dark frame "
                        "subtracted): a flat field must be a photo of a uniformly lit white target filling the "
                        "frame, nowhere below 0.05 of its center",
                        path.string(), x, y, c, g);
      }
  }
  return flat;
}

}  // namespace

Image ReadPhoto(const std::filesystem::path& path, std::vector<std::string>* warnings, const ImageReadOptions& input) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) ThrowBadInput("'{}': no such photo file", path.string());
  Image im = ReadImage(path, input);
  if (im.width < 2 || im.height < 2 || im.channels < 1) ThrowBadInput("'{}': empty image", path.string());
  std::size_t bad = 0;
  for (float& v : im.pixels)
    if (!std::isfinite(v)) v = 0, ++bad;
  if (bad && warnings) warnings->push_back(fmt::format("{} non-finite pixel values replaced by 0", bad));
  return im;
}

PhotoLoader::PhotoLoader(const Manifest& manifest, const std::filesystem::path& manifest_path,
                         const ImageReadOptions& input, const HdrOptions& hdr)
    : manifest_(manifest), manifest_path_(manifest_path), dir_(manifest_path.parent_path()), input_(input), hdr_(hdr) {
  if (hdr_.response != "linear") RecoverResponseCurve();
  ReadReferenceFrames();
}

// The camera response from the first bracket of the manifest; every photo is then read as
// stored (raw codes) and mapped through it.
void PhotoLoader::RecoverResponseCurve() {
  if (manifest_.bit_depth != 8)
    ThrowBadInput("'{}': --hdr-response {} recovers the response of 8-bit photos; this manifest's bit_depth is {} "
                  "(use --hdr-response linear for linear data)",
                  manifest_path_.string(), hdr_.response, manifest_.bit_depth);
  const auto first = std::find_if(manifest_.photos.begin(), manifest_.photos.end(),
                                  [](const PhotoEntry& e) { return e.brackets.size() >= 2; });
  if (first == manifest_.photos.end())
    ThrowBadInput("'{}': --hdr-response {} needs an exposure bracket ('brackets' in a photo entry) to recover the "
                  "response from; the manifest has none",
                  manifest_path_.string(), hdr_.response);
  input_.colorspace = "linear";
  std::vector<Image> codes;
  std::vector<double> exposures;
  for (const auto& b : first->brackets) {
    codes.push_back(ReadPhoto(dir_ / b.file, nullptr, input_));
    exposures.push_back(b.exposure);
    response_files_.push_back(b.file);
  }
  response_ = RecoverResponse(codes, exposures, hdr_, fmt::format("'{}' (bracket of photos[{}])",
                                                                  first->file, first - manifest_.photos.begin()));
}

// A reference frame, which must match the photos (checked against the first one's camera).
Image PhotoLoader::ReadReferenceFrame(const std::string& file) const {
  Image im = ReadPhoto(dir_ / file, nullptr, input_);
  if (!manifest_.photos.empty()) {
    const CameraModel& cam = manifest_.photos[0].camera;
    if (cam.width > 0 && (im.width != cam.width || im.height != cam.height))
      ThrowBadInput("'{}' is {}x{} px but the photos' camera is {}x{}: reference frames must come from the same camera",
                    (dir_ / file).string(), im.width, im.height, cam.width, cam.height);
  }
  return im;
}

// The manifest's dark frame and flat field (linear values, as the photos are decoded): the
// black level, and the relative illumination gain (FlatFieldGain of flat - dark), per pixel and
// channel.
void PhotoLoader::ReadReferenceFrames() {
  if (manifest_.dark_frame.empty() && manifest_.flat_field.empty()) return;
  if (!response_.empty())
    ThrowBadInput("'{}': dark_frame and flat_field need linear photos (--hdr-response linear), not --hdr-response {}",
                  manifest_path_.string(), hdr_.response);
  if (!manifest_.dark_frame.empty()) dark_ = ReadReferenceFrame(manifest_.dark_frame);
  if (manifest_.flat_field.empty()) return;
  Image flat = ReadReferenceFrame(manifest_.flat_field);
  if (!dark_.pixels.empty()) {
    CheckSameSize(flat, dark_, manifest_.flat_field, manifest_.dark_frame);
    for (std::size_t i = 0; i < flat.pixels.size(); ++i) flat.pixels[i] -= dark_.pixels[i];
  }
  gain_ = FlatFieldGain(std::move(flat), dir_ / manifest_.flat_field);
}

// Dark frame and flat field applied to a linear image (a merged bracket's dark frame is
// subtracted per exposure by MergeBracket: subtract_dark false).
void PhotoLoader::Correct(Image& im, const std::string& file, bool subtract_dark) const {
  if (subtract_dark && !dark_.pixels.empty()) {
    CheckSameSize(im, dark_, file, manifest_.dark_frame);
    for (std::size_t i = 0; i < im.pixels.size(); ++i) im.pixels[i] = std::max(0.0f, im.pixels[i] - dark_.pixels[i]);
  }
  if (!gain_.pixels.empty()) {
    CheckSameSize(im, gain_, file, manifest_.flat_field);
    for (std::size_t i = 0; i < im.pixels.size(); ++i) im.pixels[i] /= gain_.pixels[i];
  }
}

HdrMerge PhotoLoader::Load(const PhotoEntry& e, std::vector<std::string>* warnings, double* exposure_out) const {
  *exposure_out = e.exposure;
  HdrMerge m;
  if (e.brackets.empty()) {
    const Image stored = ReadPhoto(dir_ / e.file, warnings, input_);
    // An integer photo's saturated pixels (as a bracket's: stored value >= hdr.saturation of full
    // scale) have no value: masked like a bracket's pixels clipped in every exposure.
    if (manifest_.bit_depth > 0) m = ClippedPixels(stored, response_, hdr_);
    m.radiance = stored;
    if (!response_.empty()) ApplyResponse(m.radiance, response_, e.file);
    Correct(m.radiance, e.file, true);
    return m;
  }
  std::vector<Image> stored;
  std::vector<double> exposures;
  std::vector<std::string> files;
  for (const auto& b : e.brackets) {
    stored.push_back(ReadPhoto(dir_ / b.file, warnings, input_));
    exposures.push_back(b.exposure);
    files.push_back(b.file);
  }
  *exposure_out = 1;
  for (std::size_t k = 0; k < stored.size() && !dark_.pixels.empty(); ++k)
    CheckSameSize(stored[k], dark_, files[k], manifest_.dark_frame);
  m = MergeBracket(stored, exposures, files, response_, hdr_, dark_.pixels.empty() ? nullptr : &dark_);
  Correct(m.radiance, e.file, false);
  return m;
}

}  // namespace btf::register_detail
