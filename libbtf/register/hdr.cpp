#include "libbtf/register/hdr.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "libbtf/core/error.h"

namespace btf {

void HdrOptions::Check() const {
  BTF_CHECK_OPTION(response == "linear" || response == "debevec", "hdr_response", "linear or debevec");
  BTF_CHECK_OPTION(std::isfinite(saturation) && saturation > 0 && saturation <= 1, "hdr_saturation", "(0, 1]");
  BTF_CHECK_OPTION(std::isfinite(dark) && dark >= 0 && dark < saturation, "hdr_dark", "0 .. < hdr_saturation");
  BTF_CHECK_OPTION(debevec_samples >= 16 && debevec_samples <= 4000, "hdr_samples", "16..4000");
  BTF_CHECK_OPTION(std::isfinite(debevec_lambda) && debevec_lambda > 0, "hdr_lambda", "> 0");
}

namespace {

void CheckSameShape(const std::vector<Image>& images, const std::vector<double>& exposures,
                    const std::vector<std::string>& files, const std::string& what) {
  if (images.size() != exposures.size() || images.size() < 2)
    ThrowBadInput("{}: a bracket needs at least 2 exposures, found {}", what, images.size());
  for (std::size_t k = 0; k < images.size(); ++k) {
    const std::string& name = k < files.size() ? files[k] : what;
    if (!(exposures[k] > 0) || !std::isfinite(exposures[k]))
      ThrowBadInput("'{}': exposure {} must be > 0 and finite", name, exposures[k]);
    const Image& a = images[0];
    const Image& b = images[k];
    if (b.width != a.width || b.height != a.height || b.channels != a.channels)
      ThrowBadInput("'{}' is {}x{} px with {} channel(s) but '{}' of the same bracket is {}x{} with {}: every "
                    "exposure of a bracket must have the same size and channels",
                    name, b.width, b.height, b.channels, k < files.size() ? files[0] : what, a.width, a.height,
                    a.channels);
  }
}

std::vector<unsigned char> ToCodes(const Image& im, const std::string& what) {
  std::vector<unsigned char> out(im.pixels.size());
  for (std::size_t i = 0; i < im.pixels.size(); ++i) {
    const double c = 255.0 * im.pixels[i];
    const long r = std::lround(c);
    if (!(std::abs(c - r) < 0.01) || r < 0 || r > 255)
      ThrowBadInput("{}: value {} at sample {} is not an 8-bit code: response recovery needs 8-bit photos read as "
                    "stored (bit_depth 8)",
                    what, im.pixels[i], i);
    out[i] = static_cast<unsigned char>(r);
  }
  return out;
}

}  // namespace

ResponseCurve RecoverResponse(const std::vector<Image>& codes, const std::vector<double>& exposures,
                              const HdrOptions& o, const std::string& what) {
  CheckSameShape(codes, exposures, {}, what);
  const int C = codes[0].channels;
  std::vector<std::vector<unsigned char>> z8;
  for (const Image& im : codes) z8.push_back(ToCodes(im, what));
  const std::size_t np = static_cast<std::size_t>(codes[0].width) * codes[0].height, K = codes.size();
  const double lo = 255.0 * o.dark, hi = 255.0 * o.saturation;
  // Debevec & Malik's weight: a hat between the dark and the clipped code, 0 outside, so clipped
  // and dark samples do not enter (OpenCV's CalibrateDebevec weights code 255 too, and a clipped
  // pixel then pulls the curve's top up).
  const auto weight = [&](int z) { return z > lo && z < hi ? std::min(z - lo, hi - z) : 0.0; };
  ResponseCurve curve;
  curve.lut.assign(static_cast<std::size_t>(C), std::vector<float>(256, 0.0f));
  for (int c = 0; c < C; ++c) {
    // Sample pixels: those with >= 2 usable exposures, spread evenly over their brightness (the sum
    // of their codes, monotone in radiance), so that the curve is constrained over its whole range.
    std::vector<std::pair<int, std::size_t>> cand;
    for (std::size_t p = 0; p < np; ++p) {
      int usable = 0, key = 0;
      for (std::size_t k = 0; k < K; ++k) {
        const int z = z8[k][p * C + c];
        usable += weight(z) > 0;
        key += z;
      }
      if (usable >= 2) cand.emplace_back(key, p);
    }
    if (static_cast<int>(cand.size()) < 16)
      ThrowBadInput("{}: only {} pixels of channel {} are usable (neither clipped nor dark) in at least 2 exposures "
                    "of the bracket: response recovery needs exposures that overlap",
                    what, cand.size(), c);
    std::sort(cand.begin(), cand.end());
    const std::size_t N = std::min<std::size_t>(cand.size(), static_cast<std::size_t>(o.debevec_samples));
    // Unknowns: g(0..255) = ln(linear value of the code), then ln E of each sample pixel. Normal
    // equations of the weighted least squares, accumulated row by row (each row touches 2 or 3).
    const int n = 256 + static_cast<int>(N);
    Eigen::MatrixXd AtA = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd Atb = Eigen::VectorXd::Zero(n);
    const auto add_row = [&](std::initializer_list<std::pair<int, double>> row, double b) {
      for (const auto& [i, a] : row) {
        Atb(i) += a * b;
        for (const auto& [j, aj] : row) AtA(i, j) += a * aj;
      }
    };
    std::vector<int> seen(256, 0);
    for (std::size_t s = 0; s < N; ++s) {
      const std::size_t p = cand[(s * (cand.size() - 1)) / std::max<std::size_t>(N - 1, 1)].second;
      for (std::size_t k = 0; k < K; ++k) {
        const int z = z8[k][p * C + c];
        const double w = weight(z);
        if (w > 0) add_row({{z, w}, {256 + static_cast<int>(s), -w}}, w * std::log(exposures[k]));
        if (w > 0) ++seen[static_cast<std::size_t>(z)];
      }
    }
    // The codes the data constrain: from the 3rd-lowest to the 3rd-highest observation.
    int below = 0, above = 0, zmin = 0, zmax = 255;
    while (zmin < 255 && (below += seen[static_cast<std::size_t>(zmin)]) < 3) ++zmin;
    while (zmax > 0 && (above += seen[static_cast<std::size_t>(zmax)]) < 3) --zmax;
    curve.min_code = std::max(curve.min_code, zmin);
    curve.max_code = std::min(curve.max_code, zmax);
    add_row({{255, 1e3}}, 0.0);  // the scale: g(255) = 0, code 255 -> 1 (the white level)
    // Smoothness of g; codes without data (beyond the thresholds) are extrapolated by it.
    for (int z = 1; z < 255; ++z) {
      const double w = o.debevec_lambda * std::max(weight(z), 1.0);
      add_row({{z - 1, w}, {z, -2 * w}, {z + 1, w}}, 0.0);
    }
    const Eigen::VectorXd x = AtA.ldlt().solve(Atb);
    std::vector<float>& l = curve.lut[static_cast<std::size_t>(c)];
    for (int z = 0; z < 256; ++z) l[static_cast<std::size_t>(z)] = static_cast<float>(std::exp(x(z)));
    for (int z = 1; z < 256; ++z) l[z] = std::max(l[z], l[z - 1]);  // monotone (the ends can dip)
    if (!std::all_of(l.begin(), l.end(), [](float v) { return std::isfinite(v) && v >= 0; }) || !(l[255] > 0))
      ThrowBadInput("{}: the recovered response curve of channel {} is degenerate: the bracket's exposures must "
                    "differ and the photos must show a range of brightness",
                    what, c);
    for (float& v : l) v /= l[255];
  }
  return curve;
}

namespace {
float CodeToLinear(const ResponseCurve& curve, int c, float stored) {
  return curve.lut[static_cast<std::size_t>(c)][static_cast<std::size_t>(std::clamp(std::lround(255.0 * stored), 0L, 255L))];
}
}  // namespace

void ApplyResponse(Image& codes, const ResponseCurve& curve, const std::string& file) {
  if (static_cast<int>(curve.lut.size()) != codes.channels)
    ThrowBadInput("'{}' has {} channel(s) but the response curve {}", file, codes.channels, curve.lut.size());
  for (std::size_t i = 0; i < codes.pixels.size(); ++i)
    codes.pixels[i] = CodeToLinear(curve, static_cast<int>(i % static_cast<std::size_t>(codes.channels)), codes.pixels[i]);
}

namespace {

// True if a stored value (as MergeBracket's `stored`) is clipped: >= options.saturation of full
// scale (or NaN), or with a curve, beyond its last constrained code.
bool IsClipped(float stored, const ResponseCurve& curve, const HdrOptions& o) {
  if (!(stored < o.saturation)) return true;                                 // clipped (NaN too)
  return !curve.empty() && 255.0 * stored > curve.max_code + 0.5;           // beyond the curve's data: as clipped
}

}  // namespace

HdrMerge ClippedPixels(const Image& stored, const ResponseCurve& curve, const HdrOptions& o) {
  HdrMerge m;
  m.clipped = Image(stored.width, stored.height, 1);
  const std::size_t np = static_cast<std::size_t>(stored.width) * stored.height;
  const int C = stored.channels;
  for (std::size_t p = 0; p < np; ++p)
    for (int c = 0; c < C; ++c)
      if (IsClipped(stored.pixels[p * C + c], curve, o)) {
        m.clipped.pixels[p] = 1, ++m.clipped_pixels;
        break;
      }
  return m;
}

HdrMerge MergeBracket(const std::vector<Image>& stored, const std::vector<double>& exposures,
                      const std::vector<std::string>& files, const ResponseCurve& curve, const HdrOptions& o,
                      const Image* dark) {
  CheckSameShape(stored, exposures, files, files.empty() ? std::string("bracket") : files[0]);
  const Image& first = stored[0];
  const int C = first.channels;
  if (!curve.empty() && static_cast<int>(curve.lut.size()) != C)
    ThrowBadInput("'{}' has {} channel(s) but the response curve {}", files.empty() ? "bracket" : files[0], C,
                  curve.lut.size());
  HdrMerge m;
  m.radiance = Image(first.width, first.height, C);
  m.clipped = Image(first.width, first.height, 1);
  const std::size_t np = static_cast<std::size_t>(first.width) * first.height, K = stored.size();
  // Shortest exposure first for the clipped fallback; the longest for the dark one.
  const std::size_t k_short = static_cast<std::size_t>(std::min_element(exposures.begin(), exposures.end()) - exposures.begin());
  std::size_t clipped_pixels = 0;
#pragma omp parallel for reduction(+ : clipped_pixels)
  for (std::ptrdiff_t p = 0; p < static_cast<std::ptrdiff_t>(np); ++p) {
    bool pixel_clipped = false;
    for (int c = 0; c < C; ++c) {
      const std::size_t i = static_cast<std::size_t>(p) * C + c;
      double sw = 0, swx = 0, dark_best_e = -1, dark_value = 0;
      for (std::size_t k = 0; k < K; ++k) {
        const float s = stored[k].pixels[i];
        double v = s;
        if (!curve.empty()) v = CodeToLinear(curve, c, s);
        if (dark) v -= dark->pixels[i];
        if (IsClipped(s, curve, o)) continue;
        const double e = exposures[k];
        if (s <= o.dark || (!curve.empty() && 255.0 * s < curve.min_code - 0.5)) {  // dark, or below the curve's data
          if (e > dark_best_e) dark_best_e = e, dark_value = v / e;
          continue;
        }
        sw += e * e;
        swx += e * e * (v / e);
      }
      double out;
      if (sw > 0) {
        out = swx / sw;
      } else if (dark_best_e > 0) {
        out = dark_value;
      } else {  // clipped in every exposure: a lower bound
        pixel_clipped = true;
        const float s = stored[k_short].pixels[i];
        out = ((curve.empty() ? s : CodeToLinear(curve, c, s)) - (dark ? dark->pixels[i] : 0.0)) / exposures[k_short];
      }
      m.radiance.pixels[i] = static_cast<float>(std::isfinite(out) ? std::max(0.0, out) : 0.0);
    }
    if (pixel_clipped) m.clipped.pixels[static_cast<std::size_t>(p)] = 1, ++clipped_pixels;
  }
  m.clipped_pixels = clipped_pixels;
  return m;
}

}  // namespace btf
