#include "libbtf/stability/stability.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/core/error.h"
#include "libbtf/core/hash.h"
#include "libbtf/compress/codec_source.h"
#include "libbtf/eval/metrics.h"
#include "libbtf/eval/render.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/synth/model.h"
#include "libbtf/synth/sadeghi2013.h"
#include "libbtf/synth/weave_pattern.h"

namespace btf {

namespace {

struct Outcome {
  bool passed = false;
  std::string figure;
};

// Finite/non-negative scan of a model over a uv grid and a set of direction pairs.
struct ModelScan {
  std::uint64_t evaluated = 0, non_finite = 0, negative = 0, below_horizon_nonzero = 0;
  double max_value = 0;
};

ModelScan ScanModel(const SvbrdfModel& m, const std::vector<std::pair<Vec3, Vec3>>& pairs, int uv_grid = 4) {
  ModelScan s;
  std::vector<float> out(std::max(m.channels(), 1));
  for (const auto& [wi, wo] : pairs) {
    const bool below = wi.z() < 0 || wo.z() < 0;
    for (int j = 0; j < uv_grid; ++j)
      for (int i = 0; i < uv_grid; ++i) {
        m.Eval(Vec2((i + 0.37) / uv_grid, (j + 0.61) / uv_grid), wi, wo, out.data());
        for (float v : out) {
          ++s.evaluated;
          if (!std::isfinite(v)) ++s.non_finite;
          else if (v < 0) ++s.negative;
          else s.max_value = std::max(s.max_value, double(v));
          if (below && v != 0) ++s.below_horizon_nonzero;
        }
      }
  }
  return s;
}

Outcome JudgeScan(const ModelScan& s, bool check_below) {
  Outcome o;
  o.passed = s.non_finite == 0 && s.negative == 0 && (!check_below || s.below_horizon_nonzero == 0);
  o.figure = fmt::format("{} values: {} non-finite, {} negative, {} non-zero below the horizon, max {:.4g}",
                         s.evaluated, s.non_finite, s.negative, s.below_horizon_nonzero, s.max_value);
  return o;
}

std::vector<std::pair<Vec3, Vec3>> GrazingPairs() {
  std::vector<std::pair<Vec3, Vec3>> pairs;
  const double thetas[] = {85, 87, 89, 89.9, 89.99};
  for (double ti : thetas)
    for (double to : thetas)
      for (int pi = 0; pi < 4; ++pi)
        for (int po = 0; po < 4; ++po)
          pairs.emplace_back(DirectionFromAngles(DegToRad(ti), DegToRad(90.0 * pi + 10)),
                             DirectionFromAngles(DegToRad(to), DegToRad(90.0 * po + 55)));
  // At and below the horizon: must give exactly 0 below.
  for (double t : {90.5, 120.0, 180.0})
    pairs.emplace_back(DirectionFromAngles(DegToRad(t), 0.3), DirectionFromAngles(DegToRad(45), 1.0)),
        pairs.emplace_back(DirectionFromAngles(DegToRad(45), 1.0), DirectionFromAngles(DegToRad(t), 2.0));
  return pairs;
}

std::vector<std::pair<Vec3, Vec3>> RetroPairs() {
  std::vector<std::pair<Vec3, Vec3>> pairs;
  for (double t : {0.0, 1e-6, 15.0, 45.0, 75.0, 85.0, 89.0, 89.9, 89.99})
    for (int p = 0; p < 8; ++p) {
      const Vec3 d = DirectionFromAngles(DegToRad(t), DegToRad(45.0 * p + 3));
      pairs.emplace_back(d, d);
    }
  return pairs;
}

std::unique_ptr<SvbrdfModel> NamedModel(const std::string& which) {
  if (which == "irawan2006") return MakeModel("irawan2006", "twill");
  if (which == "irawan2012") return MakeModel("irawan2012", WeavePresetNames().front());
  return MakeModel("sadeghi2013", Sadeghi2013PresetNames().front());
}

// Expects `f` to throw btf::Error with `code` and a message containing `needle`.
Outcome ExpectRefused(const std::function<void()>& f, ExitCode code, const std::string& needle) {
  try {
    f();
  } catch (const Cancelled&) {
    throw;
  } catch (const Error& e) {
    const bool ok = e.code() == code && std::string(e.what()).find(needle) != std::string::npos;
    return {ok, fmt::format("refused (exit {}): {}", int(e.code()), e.what())};
  }
  return {false, "accepted: no error raised"};
}

// A small BTF on a Bonn 81 subset with values from f(v, l, y, x, c).
Dataset MakeData(int views, int lights, int size, const std::function<double(int, int, int, int, int)>& f) {
  const Sampling all = Sampling::Bonn81();
  std::vector<int> vi, li;
  for (int i = 0; i < views; ++i) vi.push_back((i * 11) % 81);
  for (int i = 0; i < lights; ++i) li.push_back((i * 7 + 3) % 81);
  Dataset d(all.Subset(vi), all.Subset(li), size, size, 3);
  for (int v = 0; v < views; ++v)
    for (int l = 0; l < lights; ++l)
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x)
          for (int c = 0; c < 3; ++c) d.at(v, l, y, x, c) = float(f(v, l, y, x, c));
  return d;
}

// Reproducible noise in [0, 1) for test data, keyed by (v, l, y, x, c).
double Noise(int v, int l, int y, int x, int c) {
  return HashUniform(std::uint64_t(v) << 32 | std::uint32_t(l), std::uint64_t(y) << 32 | std::uint32_t(x), c);
}

struct RoundTrip {
  CompareSummary errors;
  CompressSummary summary;
  std::uint64_t non_finite = 0;
};

// Compress + decode + compare (metrics refuse NaN/Inf, so a non-finite decode fails loudly).
// lpca_matrix: LPCA's texel matrix ("half", the default, rounds the input by up to 2^-11).
RoundTrip Roundtrip(const Dataset& d, CodecMethod method, int components, int clusters, bool log_transform = false,
                    const std::string& lpca_matrix = "half") {
  CompressOptions o;
  o.method = method;
  o.components = components;
  o.clusters = std::max(clusters, 1);  // pca-view ignores it
  o.log_transform = log_transform;
  o.lpca.matrix = lpca_matrix;
  RoundTrip r;
  Codec codec;
  r.summary = Compress(o, *MemorySource(d), &codec);
  const Dataset out = codec.DecodeAll();
  for (float v : out.data()) r.non_finite += !std::isfinite(v);
  if (r.non_finite) return r;
  CompareOptions co;
  co.ssim = false;
  r.errors = Compare(co, *MemorySource(d, "input"), *MemorySource(out, "decoded"));
  return r;
}

std::string MethodLabel(CodecMethod m, int c, int k) {
  return m == CodecMethod::kLpca ? fmt::format("lpca k={} c={}", k, c) : fmt::format("pca-view c={}", c);
}

// The half texel matrix's rounding of LPCA's input, relative: lossless data come back within it.
constexpr double kHalfMatrixRounding = 1.0 / 2048;

// Round trips of both methods must be finite with relative L2 error <= bound; LPCA with the float
// texel matrix, and with the default half one within max(bound, 2^-11).
Outcome RoundTripsWithin(const Dataset& d, double bound, const std::vector<std::tuple<CodecMethod, int, int>>& settings) {
  Outcome o{true, ""};
  for (const auto& [m, c, k] : settings)
    for (const std::string matrix : {"float", "half"}) {
      if (m != CodecMethod::kLpca && matrix == "half") continue;
      const RoundTrip r = Roundtrip(d, m, c, k, false, matrix);
      const double rel = r.errors.rel_l2 ? *r.errors.rel_l2 : std::numeric_limits<double>::infinity();
      const bool ok = r.non_finite == 0 && rel <= (matrix == "half" ? std::max(bound, kHalfMatrixRounding) : bound);
      o.passed = o.passed && ok;
      o.figure += fmt::format("{}{}{}: {}", o.figure.empty() ? "" : "; ", MethodLabel(m, c, k),
                              m == CodecMethod::kLpca ? " " + matrix : "",
                              r.non_finite ? fmt::format("{} non-finite decoded values", r.non_finite)
                                           : fmt::format("rel L2 {:.3g}, max abs {:.3g}, stored c {}{}", rel,
                                                         r.errors.max_abs, r.summary.components,
                                                         r.summary.warnings.empty() ? "" : " (clamped/dropped, warned)"));
    }
  return o;
}

Dataset HdrData() {
  // Log-uniform over 1e-6 .. 1e4: log10 = -6 + 10 (1 + sin(A + B)) / 2 with A from the texel and B
  // from the directions, so the log-domain data have rank 2 but the linear data high rank.
  return MakeData(3, 8, 16, [](int v, int l, int y, int x, int c) {
    const double a = 0.7 * x + 0.3 * y, b = 1.3 * l + 0.9 * v + 0.2 * c;
    return std::pow(10.0, -6 + 10 * 0.5 * (1 + std::sin(a + b)));
  });
}

double MedianRelativeError(const Dataset& a, const Dataset& b) {
  std::vector<double> rel;
  for (std::size_t i = 0; i < a.size(); ++i) rel.push_back(std::abs(double(b.data()[i]) - a.data()[i]) / a.data()[i]);
  std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
  return rel[rel.size() / 2];
}

// ---- The cases: one function each; Cases() lists them with their names and criteria. ----------

std::vector<std::pair<Vec3, Vec3>> GrazingAndRetroPairs() {
  auto pairs = GrazingPairs();
  const auto retro = RetroPairs();
  pairs.insert(pairs.end(), retro.begin(), retro.end());
  return pairs;
}

Outcome Irawan2006Eccentricity() {
  const nlohmann::json p = {{"warp", {{"eta", 0.999999}}}, {"weft", {{"eta", 0.999999}}}};
  const auto model = MakeModel("irawan2006", "twill", p);
  const Outcome o = JudgeScan(ScanModel(*model, GrazingAndRetroPairs()), true);
  const Outcome r =
      ExpectRefused([] { MakeModel("irawan2006", "twill", {{"warp", {{"eta", 1.0}}}}); }, ExitCode::kUsage, "eta");
  return Outcome{o.passed && r.passed, o.figure + "; eta = 1: " + r.figure};
}

// An Irawan 2012 model from the first weave preset with `edit` applied (written to a .wv file).
std::unique_ptr<SvbrdfModel> EditedWeave(const std::string& what, const std::function<void(WeavePattern&)>& edit,
                                         const std::filesystem::path& tmp) {
  WeavePattern w = WeavePreset(WeavePresetNames().front());
  edit(w);
  const auto path = tmp / (what + ".wv");
  std::ofstream(path) << FormatWeavePattern(w);
  return MakeModel("irawan2012", path.string());
}

Outcome Irawan2012Kappa(const std::filesystem::path& tmp) {
  const auto model = EditedWeave("kappa_near", [](WeavePattern& w) { for (auto& y : w.yarns) y.kappa = -0.999; }, tmp);
  const Outcome o = JudgeScan(ScanModel(*model, GrazingAndRetroPairs()), true);
  const Outcome r = ExpectRefused([&] { EditedWeave("kappa_edge", [](WeavePattern& w) { w.yarns[0].kappa = -1; }, tmp); },
                                  ExitCode::kBadInput, "kappa");
  return Outcome{o.passed && r.passed, o.figure + "; kappa = -1: " + r.figure};
}

Outcome Irawan2012Umax(double umax_deg, const std::filesystem::path& tmp) {
  const auto model = EditedWeave(fmt::format("umax{:g}", umax_deg), [&](WeavePattern& w) {
    for (auto& y : w.yarns) y.psi = 0, y.umax = DegToRad(umax_deg);
  }, tmp);
  return JudgeScan(ScanModel(*model, GrazingAndRetroPairs()), true);
}

Outcome BarycentricGrazing() {
  const Sampling s = Sampling::Bonn81();
  double worst_sum = 0;
  int bad = 0, n = 0;
  for (double t : {0.0, 1e-9, 30.0, 75.0, 80.0, 85.0, 89.0, 89.9, 89.99, 90.0, 95.0})
    for (int p = 0; p < 24; ++p) {
      const Interpolant ip = s.Barycentric(DirectionFromAngles(DegToRad(t), DegToRad(15.0 * p + 0.5)));
      double sum = 0;
      for (int k = 0; k < ip.count; ++k) {
        if (!std::isfinite(ip.weight[k]) || ip.weight[k] < 0 || ip.index[k] < 0 || ip.index[k] >= 81) ++bad;
        sum += ip.weight[k];
      }
      worst_sum = std::max(worst_sum, std::abs(sum - 1));
      ++n;
    }
  return Outcome{bad == 0 && worst_sum <= 1e-12,
                 fmt::format("{} directions: {} bad weights, max |sum - 1| = {:.3g}", n, bad, worst_sum)};
}

Outcome CompressHugeDynamicRange() {
  const Dataset d = HdrData();
  Outcome o{true, ""};
  for (CodecMethod m : {CodecMethod::kPcaView, CodecMethod::kLpca}) {
    double med[2];
    std::uint64_t bad = 0;
    for (int log = 0; log < 2; ++log) {
      CompressOptions co;
      co.method = m;
      co.components = 2;
      co.clusters = 4;
      co.log_transform = log;
      co.log_epsilon = 1e-7;  // below the smallest value, so the log resolves it
      Codec codec;
      Compress(co, *MemorySource(d), &codec);
      const Dataset out = codec.DecodeAll();
      for (float v : out.data()) bad += !std::isfinite(v);
      med[log] = bad ? std::numeric_limits<double>::infinity() : MedianRelativeError(d, out);
    }
    const bool ok = bad == 0 && med[1] < 0.1 && med[1] < med[0];
    o.passed = o.passed && ok;
    o.figure += fmt::format("{}{}: median relative error {:.3g} without log, {:.3g} with log, {} non-finite",
                            o.figure.empty() ? "" : "; ", MethodLabel(m, 2, 4), med[0], med[1], bad);
  }
  return o;
}

Outcome MetricsHugeDynamicRange() {
  const Dataset a = HdrData();
  Dataset b = a;
  for (auto& v : b.data()) v = float(double(v) * (1 + 1e-3));
  const auto s = Compare(CompareOptions(), *MemorySource(a), *MemorySource(b));
  const double rel = s.rel_l2.value_or(-1);
  return Outcome{std::abs(rel - 1e-3) <= 1e-6 && s.psnr_db && std::isfinite(*s.psnr_db) && s.mean_ssim &&
                     std::isfinite(*s.mean_ssim),
                 fmt::format("rel L2 {:.9g}, PSNR {:.3f} dB, SSIM {:.6f}", rel, s.psnr_db.value_or(0),
                             s.mean_ssim.value_or(0))};
}

Outcome CompressRank1() {
  const Dataset d = MakeData(4, 6, 8, [](int v, int l, int y, int x, int c) {
    return (0.2 + 0.1 * std::sin(x + 2.0 * y)) * (1.0 + 0.5 * std::cos(v + 0.7 * l)) * (1 + 0.3 * c);
  });
  return RoundTripsWithin(d, 1e-5, {{CodecMethod::kPcaView, 1, 0}, {CodecMethod::kPcaView, 8, 0},
                                    {CodecMethod::kLpca, 1, 1}, {CodecMethod::kLpca, 8, 4}});
}

Outcome CompressConstant() {
  Outcome o{true, ""};
  for (double value : {0.37, 0.0}) {
    const Dataset d = MakeData(3, 5, 8, [value](int, int, int, int, int) { return value; });
    const Outcome r = RoundTripsWithin(d, 1e-6, {{CodecMethod::kPcaView, 4, 0}, {CodecMethod::kLpca, 4, 4}});
    o.passed = o.passed && r.passed;
    o.figure += fmt::format("{}value {:g}: {}", o.figure.empty() ? "" : "; ", value, r.figure);
  }
  return o;
}

Outcome CompressNearDuplicateTexels() {
  const Dataset d = MakeData(3, 6, 12, [](int v, int l, int y, int x, int c) {
    return (0.3 + 0.2 * std::sin(v + 0.5 * l + c)) * (1 + 1e-7 * (Noise(v, l, y, x, c) - 0.5));
  });
  return RoundTripsWithin(d, 1e-5, {{CodecMethod::kPcaView, 2, 0}, {CodecMethod::kLpca, 2, 8}});
}

Outcome CompressSingleViewOrLight() {
  auto f = [](int v, int l, int y, int x, int c) { return 0.1 + 0.05 * Noise(v, l, y, x, c) + 0.02 * (v + l); };
  const Outcome a = RoundTripsWithin(MakeData(1, 6, 6, f), 1e-5, {{CodecMethod::kPcaView, 32, 0}, {CodecMethod::kLpca, 32, 1}});
  const Outcome b = RoundTripsWithin(MakeData(5, 1, 6, f), 1e-5, {{CodecMethod::kPcaView, 32, 0}, {CodecMethod::kLpca, 32, 1}});
  return Outcome{a.passed && b.passed, "1 view: " + a.figure + " | 1 light: " + b.figure};
}

Outcome CompressMoreClustersThanTexels() {
  const Dataset d = MakeData(3, 4, 2, [](int v, int l, int y, int x, int c) { return 0.2 + Noise(v, l, y, x, c); });
  const RoundTrip r = Roundtrip(d, CodecMethod::kLpca, 2, 32, false, "float");
  const double rel = r.errors.rel_l2.value_or(1e30);
  const bool ok = r.non_finite == 0 && r.summary.clusters == 4 && !r.summary.warnings.empty() && rel <= 1e-5;
  return Outcome{ok, fmt::format("stored clusters {}, {} warning(s), rel L2 {:.3g}, {} non-finite", r.summary.clusters,
                                 r.summary.warnings.size(), rel, r.non_finite)};
}

Outcome NonFiniteInputRefused(const std::string& b, const std::filesystem::path& tmp) {
  Dataset d = MakeData(2, 3, 4, [](int v, int l, int y, int x, int c) { return 0.1 + Noise(v, l, y, x, c); });
  const Dataset clean = d;
  d.at(1, 2, 3, 0, 1) = b == "NaN" ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
  const auto file = tmp / ("bad_" + b + ".h5");
  WriteDataset(file, d);
  std::string figure;
  bool ok = true;
  for (CodecMethod m : {CodecMethod::kPcaView, CodecMethod::kLpca}) {
    CompressOptions co;
    co.method = m;
    co.components = 2, co.clusters = 2;
    Codec codec;
    const Outcome a = ExpectRefused([&] { Compress(co, *MemorySource(d), &codec); }, ExitCode::kBadInput, b);
    const Outcome f = ExpectRefused([&] { Compress(co, *OpenDatasetSource(file), &codec); }, ExitCode::kBadInput, b);
    ok = ok && a.passed && f.passed;
    figure += fmt::format("{} memory: {}; file: {}; ", MethodName(m), a.figure, f.figure);
  }
  const Outcome mt =
      ExpectRefused([&] { Compare(CompareOptions(), *MemorySource(clean), *OpenSource(file)); }, ExitCode::kBadInput, b);
  return Outcome{ok && mt.passed, figure + "metrics: " + mt.figure};
}

Outcome RenderHugeDynamicRange() {
  const Dataset d = HdrData();
  RenderOptions ro;
  ro.scene = "cylinder";
  ro.lighting = "environment";
  ro.width = 48, ro.height = 40;
  const Image img = Render(*DatasetEvaluator(d), ro);
  int bad = 0;
  double mx = 0;
  for (float v : img.pixels) {
    if (!std::isfinite(v) || v < 0)
      ++bad;
    else
      mx = std::max(mx, double(v));
  }
  return Outcome{bad == 0, fmt::format("{} pixels values, {} non-finite or negative, max {:.4g}", img.pixels.size(), bad, mx)};
}

struct Case {
  std::string name;
  std::string stage;
  std::string criterion;
  std::function<Outcome(const std::filesystem::path& tmp)> run;
};

std::vector<Case> Cases() {
  using Path = const std::filesystem::path&;
  std::vector<Case> cases;
  for (const char* model : {"irawan2006", "irawan2012", "sadeghi2013"}) {
    const std::string m = model;
    cases.push_back({"grazing/" + m, "synth",
                     "theta 85-89.99 deg for wi and wo: every value finite and >= 0; exactly 0 below the horizon",
                     [m](Path) { return JudgeScan(ScanModel(*NamedModel(m), GrazingPairs()), true); }});
    cases.push_back({"retro-reflection/" + m, "synth", "wi = wo from the pole to theta 89.99 deg: every value finite and >= 0",
                     [m](Path) { return JudgeScan(ScanModel(*NamedModel(m), RetroPairs()), false); }});
  }
  cases.push_back({"irawan2006/eccentricity", "synth",
                   "eta = 0.999999 (warp and weft): finite, >= 0 at grazing and retro directions; eta = 1 refused (usage)",
                   [](Path) { return Irawan2006Eccentricity(); }});
  cases.push_back({"irawan2012/kappa", "synth",
                   "kappa = -0.999 (every yarn): finite, >= 0 at grazing and retro directions; kappa = -1 refused (bad input)",
                   Irawan2012Kappa});
  for (double umax_deg : {0.0, 90.0})
    cases.push_back({fmt::format("irawan2012/umax={:g}", umax_deg), "synth",
                     "umax at the edge of [0, 90] deg for every yarn (filaments, psi = 0): every value finite and >= 0",
                     [umax_deg](Path tmp) { return Irawan2012Umax(umax_deg, tmp); }});
  cases.push_back({"directions/barycentric-grazing", "directions",
                   "Bonn 81 barycentric weights for theta 0-90 deg and below: finite, >= 0, summing to 1 within 1e-12",
                   [](Path) { return BarycentricGrazing(); }});
  cases.push_back({"compress/huge-dynamic-range", "compress",
                   "values 1e-6..1e4, pca-view c=2 and lpca k=4 c=2, with and without --log: decoded values finite; "
                   "with the log transform the median relative error is below 10 % and below the one without",
                   [](Path) { return CompressHugeDynamicRange(); }});
  cases.push_back({"metrics/huge-dynamic-range", "metrics",
                   "reference 1e-6..1e4 against reference x (1 + 1e-3): rel L2 = 1e-3 within 1e-6, PSNR finite",
                   [](Path) { return MetricsHugeDynamicRange(); }});
  cases.push_back({"compress/rank-1", "compress",
                   "rank-1 data (texel x direction x channel factors): c = 1 and c = 8 reconstruct to rel L2 <= 1e-5 (lpca: float texel matrix; the default half one within 2^-11)",
                   [](Path) { return CompressRank1(); }});
  cases.push_back({"compress/constant", "compress",
                   "constant 0.37 and all-zero data: every codec reconstructs with rel L2 <= 1e-6, nothing non-finite (lpca: float texel matrix; the default half one within 2^-11)",
                   [](Path) { return CompressConstant(); }});
  cases.push_back({"compress/near-duplicate-texels", "compress",
                   "all texels equal up to 1e-7 relative noise, lpca k=8 and pca-view: rel L2 <= 1e-5, finite (lpca: float texel matrix; the default half one within 2^-11)",
                   [](Path) { return CompressNearDuplicateTexels(); }});
  cases.push_back({"compress/single-view-or-light", "compress",
                   "1 view x 6 lights and 5 views x 1 light, c = 32 (clamped to what the data allows, so lossless): "
                   "rel L2 <= 1e-5, finite (lpca: float texel matrix; the default half one within 2^-11)",
                   [](Path) { return CompressSingleViewOrLight(); }});
  cases.push_back({"compress/k-greater-than-texels", "compress",
                   "2x2 texels with lpca k = 32: clamped to 4 clusters with a warning, rel L2 <= 1e-5, finite (float texel matrix)",
                   [](Path) { return CompressMoreClustersThanTexels(); }});
  for (const char* bad : {"NaN", "Inf"}) {
    const std::string b = bad;
    cases.push_back({"input/" + b, "compress+metrics",
                     "a dataset holding one non-finite value is refused (bad input, message naming it) by compression "
                     "from memory and from a file, and by the metrics",
                     [b](Path tmp) { return NonFiniteInputRefused(b, tmp); }});
  }
  cases.push_back({"render/huge-dynamic-range", "render",
                   "cylinder under the sky environment with the 1e-6..1e4 BTF: every pixel finite and >= 0",
                   [](Path) { return RenderHugeDynamicRange(); }});
  return cases;
}

}  // namespace

void StabilityOptions::Check() const {
  for (const auto& p : only) BTF_CHECK_OPTION(!p.empty(), "only", "prefixes must not be empty");
}

nlohmann::json StabilitySummary::ToJson() const {
  nlohmann::json j;
  j["passed"] = passed;
  j["failed"] = failed;
  j["cases"] = nlohmann::json::array();
  for (const auto& c : cases)
    j["cases"].push_back({{"name", c.name}, {"stage", c.stage}, {"criterion", c.criterion}, {"passed", c.passed},
                          {"figure", c.figure}, {"seconds", {{"total", c.seconds}}}});
  j["seconds"] = times.ToJson();
  return j;
}

std::string StabilitySummary::Report() const {
  std::string r;
  for (const auto& c : cases)
    r += fmt::format("{} {:<34} {:>6.2f} s  {}\n     criterion: {}\n", c.passed ? "PASS" : "FAIL", c.name, c.seconds,
                     c.figure, c.criterion);
  return r + fmt::format("{} passed, {} failed ({})\n", passed, failed, times.Report());
}

std::vector<std::string> StabilityCaseNames() {
  std::vector<std::string> names;
  for (const auto& c : Cases()) names.push_back(c.name);
  return names;
}

StabilitySummary RunStability(const StabilityOptions& options, const Reporter& reporter) {
  options.Check();
  const auto tmp = std::filesystem::temp_directory_path() / fmt::format("libbtf-stability-{}", ::getpid());
  std::filesystem::create_directories(tmp);
  StabilitySummary s;
  const auto cases = Cases();
  std::vector<const Case*> selected;
  for (const auto& c : cases) {
    bool take = options.only.empty();
    for (const auto& p : options.only) take = take || c.name.rfind(p, 0) == 0;
    if (take) selected.push_back(&c);
  }
  if (selected.empty()) ThrowUsage("no stability case matches --only; cases: {}", fmt::join(StabilityCaseNames(), ", "));
  for (std::size_t i = 0; i < selected.size(); ++i) {
    const Case& c = *selected[i];
    reporter.Progress(i, selected.size(), "stability");
    StabilityCase r;
    r.name = c.name, r.stage = c.stage, r.criterion = c.criterion;
    Timer t;
    try {
      const Outcome o = c.run(tmp);
      r.passed = o.passed;
      r.figure = o.figure;
    } catch (const Cancelled&) {
      std::filesystem::remove_all(tmp);
      throw;
    } catch (const std::exception& e) {
      r.passed = false;
      r.figure = fmt::format("unexpected error: {}", e.what());
    }
    r.seconds = t.Seconds();
    s.times.Add(r.stage, r.seconds);
    (r.passed ? s.passed : s.failed)++;
    if (r.passed)
      reporter.Info("PASS {}: {}", r.name, r.figure);
    else
      reporter.Warn("FAIL {}: {}", r.name, r.figure);
    s.cases.push_back(std::move(r));
  }
  reporter.Progress(selected.size(), selected.size(), "stability");
  std::error_code ec;
  std::filesystem::remove_all(tmp, ec);
  return s;
}

}  // namespace btf
