#pragma once
// Exposure brackets -> linear radiance (docs/btf-register.md, "Exposure brackets").
//
// A bracket is several photos of one (view, light) at exposures e_k (pixel value = e_k * radiance,
// clipped at the sensor's white level = full scale). Per pixel and channel, each exposure gives
// the estimate v_k / e_k from its linear value v_k; exposures whose stored value is clipped
// (>= `saturation` of full scale) or dark (<= `dark`) are left out, and the rest are averaged with
// weights e_k^2 (inverse variance under a constant read noise: the longest usable exposure
// dominates). If every exposure of a sample is dark, the longest unclipped one is used alone;
// if every exposure is clipped, the sample is marked clipped (the shortest one's value, a lower
// bound, is stored).
//
// Linear values: the photos' decoded values (known-linear data), or, for photos through an
// unknown camera response, codes mapped by a response curve recovered from a bracket by Debevec
// and Malik's method (SIGGRAPH 1997) with the same hat weights, zero at the thresholds (OpenCV's
// cv::CalibrateDebevec weights clipped codes too, which bends the curve's top: see hdr.cpp). The thresholds apply to the linear values
// (fraction of full scale) of decoded photos, and to the codes (code / 255) with a curve.
#include <string>
#include <vector>

#include "libbtf/io/image_io.h"

namespace btf {

struct HdrOptions {
  std::string response = "linear";  // "linear": decoded values are linear; "debevec": recover a response curve
                                     // from the first bracket (8-bit photos, read as raw codes)
  double saturation = 0.99;  // stored value >= this fraction of full scale: clipped
  double dark = 0.02;        // stored value <= this fraction of full scale: dark
  int debevec_samples = 500;      // response recovery: sample pixels, spread evenly over their brightness
  double debevec_lambda = 30;     // its smoothness weight (on the second difference of ln(response))
  void Check() const;             // names the bad field
};

// Response curve: linear value (relative to the white level) of each 8-bit code, per channel
// (lut[c][code]); monotone, normalized so that code 255 maps to 1 (a camera whose response maps
// the white level to full scale; the curve itself is defined only up to that scale).
struct ResponseCurve {
  std::vector<std::vector<float>> lut;  // channels x 256; empty = linear data (no curve)
  // Codes constrained by the bracket's data (all channels); beyond them the curve is the fit's
  // smooth extrapolation, and the merge treats such codes as dark (below) or clipped (above).
  int min_code = 0, max_code = 255;
  bool empty() const { return lut.empty(); }
};

// Recovers the response from one bracket of 8-bit photos (any channel count), `codes` holding stored values / 255
// (read with colorspace "linear"). Throws btf::Error (bad input) naming `what` for fewer than
// 2 exposures, images that are not 8-bit codes or differ in size.
ResponseCurve RecoverResponse(const std::vector<Image>& codes, const std::vector<double>& exposures,
                              const HdrOptions& options, const std::string& what);

// Maps one photo's stored codes (values / 255) through the curve, in place.
void ApplyResponse(Image& codes, const ResponseCurve& curve, const std::string& file);

struct HdrMerge {
  Image radiance;               // value / exposure, channels as the photos
  Image clipped;                // 1 channel: 1 where some channel is clipped in every exposure, else 0
  std::size_t clipped_pixels = 0;
};

// A single photo's clipped pixels (a stored value >= options.saturation of full scale, NaN, or
// with a curve beyond its last constrained code, in some channel): `clipped` and `clipped_pixels`
// set, `radiance` left empty.
HdrMerge ClippedPixels(const Image& stored, const ResponseCurve& curve, const HdrOptions& options);

// Merges one bracket: `stored` are the photos' values as read (decoded linear when `curve` is
// empty; raw codes / 255 with a curve), `files` name them in errors. With a `dark` frame (linear,
// the photos' shape) each exposure's estimate is (v_k - dark) / e_k; the thresholds still apply
// to the stored values. Throws btf::Error (bad input) if the sizes or channel counts differ, or
// exposures are not > 0.
HdrMerge MergeBracket(const std::vector<Image>& stored, const std::vector<double>& exposures,
                      const std::vector<std::string>& files, const ResponseCurve& curve, const HdrOptions& options,
                      const Image* dark = nullptr);

}  // namespace btf
