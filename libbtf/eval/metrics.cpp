#include "libbtf/eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <type_traits>
#include <vector>

#include "libbtf/core/distributed.h"
#include "libbtf/core/error.h"
#include "libbtf/core/error_stats.h"
#include "libbtf/eval/annotate.h"
#include "libbtf/eval/codec_at_directions.h"

namespace btf {

void CompareOptions::Check() const {
  BTF_CHECK_OPTION(std::isfinite(peak) && peak >= 0, "peak", "must be 0 (reference max) or a positive value");
  BTF_CHECK_OPTION(std::isfinite(ssim_sigma) && ssim_sigma > 0 && ssim_sigma <= 64, "ssim_sigma", "must be in (0, 64]");
  BTF_CHECK_OPTION(error_maps >= 0 && error_maps <= 1000, "error_maps", "must be 0..1000");
  BTF_CHECK_OPTION(worst_images >= 0, "worst_images", "must be >= 0");
}

namespace {

// Normalized Gaussian taps for offsets -r..r, r = ceil(3 sigma).
std::vector<double> GaussianTaps(double sigma) {
  const int r = std::max(1, int(std::ceil(3 * sigma)));
  std::vector<double> w(2 * r + 1);
  for (int i = -r; i <= r; ++i) w[i + r] = std::exp(-0.5 * i * i / (sigma * sigma));
  return w;
}

// Separable Gaussian blur of a height x width plane; taps outside the image are dropped and the
// remaining weights renormalized, so borders are local means rather than means with zeros.
void Blur(const std::vector<double>& in, int h, int w, const std::vector<double>& taps, std::vector<double>& tmp,
          std::vector<double>& out) {
  const int r = int(taps.size() / 2);
  tmp.assign(in.size(), 0.0);
  out.assign(in.size(), 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double s = 0, ws = 0;
      for (int k = std::max(-r, -x); k <= std::min(r, w - 1 - x); ++k) s += taps[k + r] * in[y * w + x + k], ws += taps[k + r];
      tmp[y * w + x] = s / ws;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double s = 0, ws = 0;
      for (int k = std::max(-r, -y); k <= std::min(r, h - 1 - y); ++k) s += taps[k + r] * tmp[(y + k) * w + x], ws += taps[k + r];
      out[y * w + x] = s / ws;
    }
}

struct ImageStats {
  ErrorStats errors;  // max_abs_index: the worst value within the image
  double ssim = 0;
};

// Distributed compare: each rank measured the view slots it owns; afterwards every rank holds
// every slot's statistics (raw bytes: ImageStats is plain data), so all ranks merge the same.
void ShareImageStats(int V, int L, std::vector<ImageStats>* stats) {
  static_assert(std::is_trivially_copyable_v<ImageStats>);
  std::vector<std::uint8_t> mine;
  for (int v = 0; v < V; ++v) {
    if (!dist::Owns(v)) continue;
    const auto* p = reinterpret_cast<const std::uint8_t*>(stats->data() + std::size_t(v) * L);
    mine.insert(mine.end(), p, p + sizeof(ImageStats) * L);
  }
  const auto all = dist::AllGather(mine);
  for (int r = 0; r < dist::Size(); ++r) {
    std::size_t at = 0;
    for (int v = r; v < V; v += dist::Size()) {
      BTF_CHECK(at + sizeof(ImageStats) * L <= all[r].size());
      std::memcpy(stats->data() + std::size_t(v) * L, all[r].data() + at, sizeof(ImageStats) * L);
      at += sizeof(ImageStats) * L;
    }
  }
}

ImageStats MeasureImage(const float* ref, const float* test, int h, int w, int c, double peak, bool ssim,
                        double sigma) {
  ImageStats s;
  s.errors.Add(ref, test, std::size_t(h) * w * c);
  if (ssim) s.ssim = MeanSsim(ref, test, h, w, c, peak, sigma);
  return s;
}

std::string Fmt(double v) { return fmt::format("{:.6g}", v); }

}  // namespace

double MeanSsim(const float* ref, const float* test, int h, int w, int c, double peak, double sigma) {
  const auto taps = GaussianTaps(sigma);
  const double c1 = (0.01 * peak) * (0.01 * peak), c2 = (0.03 * peak) * (0.03 * peak);
  const std::size_t n = std::size_t(h) * w;
  std::vector<double> a(n), b(n), prod(n), tmp, mu_a, mu_b, e_aa, e_bb, e_ab;
  double total = 0;
  for (int ch = 0; ch < c; ++ch) {
    for (std::size_t i = 0; i < n; ++i) a[i] = ref[i * c + ch], b[i] = test[i * c + ch];
    Blur(a, h, w, taps, tmp, mu_a);
    Blur(b, h, w, taps, tmp, mu_b);
    for (std::size_t i = 0; i < n; ++i) prod[i] = a[i] * a[i];
    Blur(prod, h, w, taps, tmp, e_aa);
    for (std::size_t i = 0; i < n; ++i) prod[i] = b[i] * b[i];
    Blur(prod, h, w, taps, tmp, e_bb);
    for (std::size_t i = 0; i < n; ++i) prod[i] = a[i] * b[i];
    Blur(prod, h, w, taps, tmp, e_ab);
    double sum = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double ma = mu_a[i], mb = mu_b[i];
      // Variances can come out slightly negative from rounding: clamp.
      const double va = std::max(e_aa[i] - ma * ma, 0.0), vb = std::max(e_bb[i] - mb * mb, 0.0);
      const double cov = e_ab[i] - ma * mb;
      sum += ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
    }
    total += sum / double(n);
  }
  return total / c;
}

Image ErrorMapImage(const float* ref, const float* test, int h, int w, int c, double scale, int min_size) {
  std::vector<float> rms(std::size_t(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double s = 0;
      for (int k = 0; k < c; ++k) {
        const std::size_t i = (std::size_t(y) * w + x) * c + k;
        const double d = double(test[i]) - double(ref[i]);
        s += d * d;
      }
      rms[std::size_t(y) * w + x] = float(std::sqrt(s / c));
    }
  const int zoom = std::max(1, (min_size + std::max(w, h) - 1) / std::max(w, h));
  const int mw = w * zoom, mh = h * zoom, pad = 8, bar_h = 12, text_size = 13;
  const int width = std::max(mw, 240) + 2 * pad, height = pad + mh + 6 + bar_h + 4 + text_size + 6;
  Image picture = Filled(width, height, {1, 1, 1});
  Paste(picture, FalseColorImage(rms.data(), w, h, scale), pad, pad, zoom);
  // Color bar with its scale, so the map can be read without the JSON (the numbers need a font:
  // without one, see LabelFont, the bar is left unlabelled).
  const int bar_w = width - 2 * pad;
  std::vector<float> ramp(std::size_t(bar_w) * bar_h);
  for (std::size_t i = 0; i < ramp.size(); ++i) ramp[i] = float(double(i % bar_w) / (bar_w - 1));
  const int bar_y = pad + mh + 6;
  Paste(picture, FalseColorImage(ramp.data(), bar_w, bar_h, 1.0), pad, bar_y);
  // Text is drawn on display values, so its anti-aliased edges look as the font intends.
  picture = ToDisplay(picture);
  const std::string hi = fmt::format("{:.3g} (RMS over channels)", scale);
  DrawText(picture, pad, bar_y + bar_h + 4, "0", text_size, {0, 0, 0});
  DrawText(picture, width - pad - TextWidth(hi, text_size), bar_y + bar_h + 4, hi, text_size, {0, 0, 0});
  return ToLinear(picture);
}

double CompareSummary::Metric(const std::string& metric) const {
  if (metric == "rmse") return rmse;
  if (metric == "rel") {
    if (!rel_l2)
      ThrowBadInput("the reference '{}' is all zero, so the relative error is undefined: use --metric rmse",
                    reference);
    return *rel_l2;
  }
  if (metric == "psnr") {
    if (!(peak > 0))
      ThrowBadInput("the reference '{}' is all zero, so PSNR has no peak: give --peak or use --metric rmse", reference);
    return psnr_db ? *psnr_db : std::numeric_limits<double>::infinity();
  }
  ThrowUsage("unknown metric '{}': use rmse, rel or psnr", metric);
}

nlohmann::json CompareSummary::ToJson() const {
  nlohmann::json j;
  j["reference"] = reference;
  j["test"] = test;
  j["test_decoded_at_reference_directions"] = test_at_reference_directions;
  j["shape"] = {{"views", views}, {"lights", lights}, {"height", height}, {"width", width}, {"channels", channels}};
  j["values"] = values;
  j["rmse"] = rmse;
  j["rel_l2"] = rel_l2 ? nlohmann::json(*rel_l2) : nlohmann::json(nullptr);
  j["psnr_db"] = psnr_db ? nlohmann::json(*psnr_db) : nlohmann::json(nullptr);
  j["identical"] = rmse == 0;
  j["peak"] = peak;
  j["peak_source"] = peak_source;
  j["max_abs"] = max_abs;
  j["max_abs_at"] = {{"view", max_view}, {"light", max_light}, {"y", max_y}, {"x", max_x}, {"channel", max_channel}};
  j["mean_ssim"] = mean_ssim ? nlohmann::json(*mean_ssim) : nlohmann::json(nullptr);
  j["notes"] = notes;
  j["skipped_images"] = skipped_images;
  j["view_rmse"] = view_rmse;
  j["light_rmse"] = light_rmse;
  j["worst_images"] = nlohmann::json::array();
  for (const auto& w : worst)
    j["worst_images"].push_back({{"view", w.view}, {"light", w.light}, {"rmse", w.rmse}, {"max_abs", w.max_abs}});
  j["error_maps"] = error_map_files;
  j["seconds"] = times.ToJson();
  return j;
}

std::string CompareSummary::Report() const {
  std::string r = fmt::format("reference  {}\ntest       {}\n", reference, test);
  if (test_at_reference_directions)
    r += "           (test decoded at the reference's directions: Codec::Value at texel centres)\n";
  r += fmt::format("shape      {} views x {} lights x {}x{} texels x {} channels ({} values)\n", views, lights, width,
                   height, channels, values);
  r += fmt::format("rmse       {:.6g}\n", rmse);
  r += fmt::format("rel_l2     {}\n", rel_l2 ? fmt::format("{:.6g}", *rel_l2) : "undefined (reference all zero)");
  if (peak > 0)
    r += fmt::format("psnr       {} (peak {:.6g}, {})\n", psnr_db ? fmt::format("{:.3f} dB", *psnr_db) : "inf (identical)",
                     peak, peak_source);
  else
    r += "psnr       undefined (reference all zero: give --peak)\n";
  r += fmt::format("max_abs    {:.6g} at view {} light {} texel (y {}, x {}) channel {}\n", max_abs, max_view, max_light,
                   max_y, max_x, max_channel);
  if (mean_ssim) r += fmt::format("mean_ssim  {:.6f}\n", *mean_ssim);
  for (const auto& n : notes) r += fmt::format("note       {}\n", n);
  r += fmt::format("\n{:>5} {:>9} {:>9} {:>12}   per-view RMSE\n", "view", "theta", "phi", "rmse");
  for (std::size_t v = 0; v < view_rmse.size() && v < view_angles.size(); ++v)
    r += fmt::format("{:>5} {:>9.2f} {:>9.2f} {:>12.6g}\n", v, RadToDeg(view_angles[v].theta),
                     RadToDeg(view_angles[v].phi), view_rmse[v]);
  r += fmt::format("\n{:>5} {:>9} {:>9} {:>12}   per-light RMSE\n", "light", "theta", "phi", "rmse");
  for (std::size_t l = 0; l < light_rmse.size() && l < light_angles.size(); ++l)
    r += fmt::format("{:>5} {:>9.2f} {:>9.2f} {:>12.6g}\n", l, RadToDeg(light_angles[l].theta),
                     RadToDeg(light_angles[l].phi), light_rmse[l]);
  r += "\nworst images\n";
  for (const auto& w : worst)
    r += fmt::format("  view {:>3} light {:>3}  rmse {:.6g}  max_abs {:.6g}\n", w.view, w.light, w.rmse, w.max_abs);
  for (const auto& f : error_map_files) r += fmt::format("error map  {}\n", f);
  r += fmt::format("time       {}\n", times.Report());
  return r;
}

namespace {

// Pass 1: the peak for PSNR and SSIM (the option, or the largest |reference value|; the SSIM
// constants depend on it, so it comes before the other metrics).
void FindPeak(const CompareOptions& options, const SlotSource& ref, const Reporter& reporter, float* rslot,
              CompareSummary* s) {
  if (options.peak > 0) {
    s->peak = options.peak;
    s->peak_source = "option";
    return;
  }
  Timer timer;
  const int V = s->views;
  double mx = 0;
  for (int v = 0; v < V; ++v) {
    reporter.Progress(v, V, "reference peak");
    if (!dist::Owns(v)) continue;
    ref.ReadViewSlot(v, rslot);
    CheckFiniteSlot(ref, v, rslot);
    for (std::size_t i = 0; i < ref.slot_size(); ++i) mx = std::max(mx, std::abs(double(rslot[i])));
  }
  mx = dist::AllMax(mx);
  reporter.Progress(V, V, "reference peak");
  if (mx > 0) {
    s->peak = mx;
    s->peak_source = "max |reference value|";
  } else {
    s->peak = 0;
    s->peak_source = "none (reference all zero)";
    s->notes.push_back("the reference is all zero: the relative error is undefined, and PSNR and SSIM too unless "
                       "--peak gives the peak");
    reporter.Warn("the reference '{}' is all zero: relative error, PSNR and SSIM are undefined (give --peak for PSNR "
                  "and SSIM)",
                  ref.name());
  }
  s->times.Add("peak", timer.Seconds());
}

// Pass 2: every image's error sums and SSIM, one view slot of each input at a time (each rank
// its own views, then shared so that every rank holds all of them).
std::vector<ImageStats> MeasureImages(const CompareOptions& options, const SlotSource& ref, const SlotSource& test,
                                      const std::vector<char>& skip, const Reporter& reporter, double peak,
                                      float* rslot, float* tslot) {
  const int V = int(ref.views().size()), L = int(ref.lights().size());
  const int H = ref.height(), W = ref.width(), C = ref.channels();
  const std::size_t image = ref.image_size();
  std::vector<ImageStats> stats(std::size_t(V) * L);
  for (int v = 0; v < V; ++v) {
    reporter.Progress(v, V, "compare");
    if (!dist::Owns(v)) continue;
    ref.ReadViewSlot(v, rslot);
    test.ReadViewSlot(v, tslot);
    CheckFiniteSlot(ref, v, rslot);
    CheckFiniteSlot(test, v, tslot);
#pragma omp parallel for schedule(dynamic)
    for (int l = 0; l < L; ++l)
      if (!skip[std::size_t(v) * L + l])
        stats[std::size_t(v) * L + l] = MeasureImage(rslot + l * image, tslot + l * image, H, W, C,
                                                     peak, options.ssim, options.ssim_sigma);
  }
  reporter.Progress(V, V, "compare");
  if (dist::Distributed()) ShareImageStats(V, L, &stats);
  return stats;
}

// The per-image statistics merged into the summary's totals, per-view and per-light RMSE and the
// largest error, in a fixed order (deterministic sums), the same on every rank and for any rank
// count. Returns every image's error, for the worst-image list.
std::vector<ImageError> MergeImageStats(const CompareOptions& options, const std::vector<ImageStats>& stats,
                                        const std::vector<char>& skip, CompareSummary* s) {
  const int V = s->views, L = s->lights, W = s->width, C = s->channels;
  ErrorStats total;
  double ssim = 0;
  std::vector<ErrorStats> per_view(V), per_light(L);
  std::vector<ImageError> images;
  for (int v = 0; v < V; ++v)
    for (int l = 0; l < L; ++l) {
      if (skip[std::size_t(v) * L + l]) continue;
      const ImageStats& st = stats[std::size_t(v) * L + l];
      const ErrorStats& e = st.errors;
      total.Merge(e);
      per_view[v].Merge(e);
      per_light[l].Merge(e);
      ssim += st.ssim;
      if (e.max_abs_error > s->max_abs || (v == 0 && l == 0)) {
        const std::size_t i = e.max_abs_index;
        s->max_abs = e.max_abs_error;
        s->max_view = v, s->max_light = l, s->max_channel = int(i % C), s->max_x = int((i / C) % W),
        s->max_y = int(i / (std::size_t(C) * W));
      }
      images.push_back({v, l, e.Rmse(), e.max_abs_error});
    }
  s->values = total.count;
  s->rmse = total.Rmse();
  s->rel_l2 = total.RelativeL2();
  s->psnr_db = total.PsnrDb(s->peak);
  if (options.ssim && s->peak > 0 && !images.empty()) s->mean_ssim = ssim / double(images.size());
  if (const std::string w = total.PeakDominance(); !w.empty()) s->notes.push_back(w);
  for (const auto& e : per_view) s->view_rmse.push_back(e.Rmse());
  for (const auto& e : per_light) s->light_rmse.push_back(e.Rmse());
  return images;
}

// Error maps of the worst images (`images` sorted worst first), on one common scale so their
// colors compare.
void WriteErrorMaps(const CompareOptions& options, const SlotSource& ref, const SlotSource& test,
                    const std::vector<ImageError>& images, CompareSummary* s) {
  Timer timer;
  const int H = s->height, W = s->width, C = s->channels;
  const std::size_t image = ref.image_size();
  if (!std::filesystem::is_directory(options.error_maps_dir))
    ThrowIo("error-map folder '{}' does not exist: create it first", options.error_maps_dir.string());
  const int n = std::min<int>(options.error_maps, int(images.size()));
  std::vector<std::vector<float>> refs(n, std::vector<float>(image)), tests(n, std::vector<float>(image));
  double scale = 0;
  for (int i = 0; i < n; ++i) {
    ref.ReadImage(images[i].view, images[i].light, refs[i].data());
    test.ReadImage(images[i].view, images[i].light, tests[i].data());
    for (std::size_t t = 0; t < image / C; ++t) {
      double e = 0;
      for (int k = 0; k < C; ++k) {
        const double d = double(tests[i][t * C + k]) - refs[i][t * C + k];
        e += d * d;
      }
      scale = std::max(scale, std::sqrt(e / C));
    }
  }
  for (int i = 0; i < n; ++i) {
    const auto path = options.error_maps_dir / fmt::format("error_{:02d}_view{}_light{}.png", i, images[i].view,
                                                           images[i].light);
    ImageWriteOptions wo;
    wo.has_format = true;
    wo.format = PixelFormat::kUint8;
    wo.srgb = true;
    WriteImage(path, ErrorMapImage(refs[i].data(), tests[i].data(), H, W, C, scale), wo);
    s->error_map_files.push_back(path.string());
  }
  s->times.Add("error maps", timer.Seconds());
}

}  // namespace

CompareSummary Compare(const CompareOptions& options, const SlotSource& ref, const SlotSource& given_test,
                       const Reporter& reporter) {
  options.Check();
  const std::unique_ptr<SlotSource> resampled = CodecAtReferenceDirections(ref, given_test);
  const SlotSource& test = resampled ? *resampled : given_test;
  CheckCompatible(ref, test);
  CompareSummary s;
  s.reference = ref.name();
  s.test = test.name();
  s.test_at_reference_directions = resampled != nullptr;
  if (resampled)
    reporter.Info("'{}' is a codec sampled on other directions: decoded at the reference's directions", test.name());
  s.views = ref.views().size();
  s.lights = ref.lights().size();
  s.height = ref.height();
  s.width = ref.width();
  s.channels = ref.channels();
  std::vector<float> rslot(ref.slot_size()), tslot(ref.slot_size());
  // Images either input marks missing hold no measurement: left out of every figure.
  std::vector<char> skip(std::size_t(s.views) * s.lights, 0);
  for (const SlotSource* src : {&ref, &test})
    for (const auto& [v, l] : src->missing()) skip[std::size_t(v) * s.lights + l] = 1;
  s.skipped_images = int(std::count(skip.begin(), skip.end(), 1));
  if (s.skipped_images > 0)
    s.notes.push_back(fmt::format("{} of {} images are marked missing (not measured) and left out of every figure",
                                  s.skipped_images, skip.size()));

  FindPeak(options, ref, reporter, rslot.data(), &s);
  Timer timer;
  const std::vector<ImageStats> stats =
      MeasureImages(options, ref, test, skip, reporter, s.peak, rslot.data(), tslot.data());
  std::vector<ImageError> images = MergeImageStats(options, stats, skip, &s);
  for (int v = 0; v < s.views; ++v) s.view_angles.push_back(ref.views().angles(v));
  for (int l = 0; l < s.lights; ++l) s.light_angles.push_back(ref.lights().angles(l));
  std::stable_sort(images.begin(), images.end(), [](const ImageError& a, const ImageError& b) { return a.rmse > b.rmse; });
  s.worst.assign(images.begin(), images.begin() + std::min<std::size_t>(images.size(), options.worst_images));
  s.times.Add("compare", timer.Seconds());

  // Written by rank 0 alone in a distributed run.
  if (!options.error_maps_dir.empty() && options.error_maps > 0 && s.rmse > 0 && dist::Rank() == 0)
    WriteErrorMaps(options, ref, test, images, &s);
  reporter.Info("rmse {} rel {} psnr {} dB (peak {}), max abs {}", Fmt(s.rmse), s.rel_l2 ? Fmt(*s.rel_l2) : "undefined",
                s.psnr_db ? Fmt(*s.psnr_db) : "inf", Fmt(s.peak), Fmt(s.max_abs));
  return s;
}

}  // namespace btf
