#pragma once
// btf-register's photo input (register.cpp; not part of the public API): a manifest's photos as
// linear images, through the camera response recovered from a bracket, with the manifest's dark
// frame subtracted and its flat field divided out.
#include <filesystem>
#include <string>
#include <vector>

#include "libbtf/io/image_io.h"
#include "libbtf/io/rig.h"
#include "libbtf/register/hdr.h"

namespace btf::register_detail {

// Reads a photo; non-finite values become 0 (counted in a warning) so nothing non-finite escapes.
// A photo named by the manifest but missing is the manifest's problem (bad input, reported per
// photo); one that exists and cannot be read is a failing disk (I/O: ends the run).
Image ReadPhoto(const std::filesystem::path& path, std::vector<std::string>* warnings, const ImageReadOptions& input);

class PhotoLoader {
 public:
  // Recovers the response curve (hdr.response not "linear") and reads the reference frames; throws
  // btf::Error (bad input) naming the manifest for what they lack. `manifest` must outlive this.
  PhotoLoader(const Manifest& manifest, const std::filesystem::path& manifest_path, const ImageReadOptions& input,
              const HdrOptions& hdr);

  // The photo's linear image: one photo as read (through the response curve if one was
  // recovered), or a bracket merged to value / exposure (then `*exposure_out` = 1); the dark
  // frame subtracted and the flat field divided out.
  HdrMerge Load(const PhotoEntry& e, std::vector<std::string>* warnings, double* exposure_out) const;

  const ResponseCurve& response() const { return response_; }
  const std::vector<std::string>& response_files() const { return response_files_; }

 private:
  void RecoverResponseCurve();
  void ReadReferenceFrames();
  Image ReadReferenceFrame(const std::string& file) const;
  void Correct(Image& im, const std::string& file, bool subtract_dark) const;

  const Manifest& manifest_;
  const std::filesystem::path manifest_path_, dir_;
  ImageReadOptions input_;
  const HdrOptions hdr_;
  ResponseCurve response_;
  std::vector<std::string> response_files_;
  Image dark_, gain_;  // the manifest's dark frame and flat-field gain (empty = none)
};

}  // namespace btf::register_detail
