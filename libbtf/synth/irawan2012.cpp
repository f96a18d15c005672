#include "libbtf/synth/irawan2012.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>

#include "libbtf/core/error.h"
#include "libbtf/core/hash.h"

namespace btf {
namespace irawan2012 {

double SpineRadius(double u, double umax, double kappa, double w, double l) {
  if (!(umax > 0) || !(kappa > -1)) return 0;
  const double s = std::sin(umax), c = std::cos(umax);
  const double C = 0.5 * l - 0.5 * w * s;
  if (!(C > 0)) return 0;
  const double cot = c / s;
  const double rhat = 1 + kappa * (1 + cot);
  const double q = rhat * std::abs(rhat);
  const double at_max = cot * cot + q;  // (1 + q tan^2 umax) / tan^2 umax: > 0 iff kappa > -1
  const double su = std::sin(u), cu = std::cos(u);
  const double den = cu * cu + q * su * su;
  if (!(at_max > 0) || !(den > 0)) return 0;
  return C * std::sqrt(at_max) / (den * std::sqrt(den));
}

namespace {
// e^{-x} I0(x) for x >= 0: libstdc++'s Bessel function below 700 (no overflow there), the
// asymptotic series (relative error < 1e-11) above.
double ScaledI0(double x) {
  if (x < 700) return std::cyl_bessel_i(0.0, x) * std::exp(-x);
  const double t = 1 / x;
  return (1 + t * (1.0 / 8 + t * (9.0 / 128 + t * 225.0 / 3072))) / std::sqrt(2 * kPi * x);
}

}  // namespace

double VonMisesNorm(double b) { return 1 / (2 * kPi * ScaledI0(std::abs(b))); }

double VonMises(double cos_x, double b) { return std::exp(b * cos_x - std::abs(b)) * VonMisesNorm(b); }

double Seeliger(double cos1, double cos2) {
  const double c1 = std::max(0.0, cos1), c2 = std::max(0.0, cos2);
  if (c1 == 0 || c2 == 0) return 0;
  return c1 * c2 / (c1 + c2) / (4 * kPi);
}

FibreFrame MakeFibreFrame(double u, double v, double psi) {
  const double su = std::sin(u), cu = std::cos(u), sv = std::sin(v), cv = std::cos(v);
  const double sp = std::sin(psi), cp = std::cos(psi);
  const Vec3 ex(1, 0, 0), en(0, su, cu), et(0, cu, -su);
  return {sv * ex + cv * en, -sp * cv * ex + sp * sv * en + cp * et, cp * cv * ex - cp * sv * en + sp * et};
}

}  // namespace irawan2012

namespace {

using irawan2012::Seeliger;
using irawan2012::SmoothStep01;
using irawan2012::SpineRadius;

// Our own hashing (splitmix64 finalizer); used only when noise is on.
std::uint64_t Mix(std::uint64_t z) { return MixBits(z + 0x9e3779b97f4a7c15ULL); }
// Integer keys are hashed as unsigned (wrapping) so no key arithmetic can overflow.
std::uint64_t Hash(std::uint64_t a, std::uint64_t b, std::uint64_t stream) { return Mix(Mix(Mix(stream) ^ a) ^ b); }
// Uniform in (0, 1] (never 0, so -log stays finite).
double Hash01(std::uint64_t a, std::uint64_t b, std::uint64_t stream) {
  return static_cast<double>((Hash(a, b, stream) >> 11) + 1) * 0x1.0p-53;
}
// Lattice key of a coordinate: floor(x) as a wrapping integer; coordinates too large (or not
// finite) to hold a fraction map to key 0 instead of an undefined float-to-int conversion.
std::uint64_t LatticeKey(double x) {
  return std::abs(x) < 0x1p62 ? static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(x))) : 0;
}
// 1-D gradient noise with quintic fade, gradients uniform in [-1, 1]: |n(x)| <= 1/2.
double GradientNoise1(double x) {
  if (!(std::abs(x) < 0x1p52)) return 0;  // no fraction left: the noise is 0 at lattice points
  const double i = std::floor(x), f = x - i;
  const std::uint64_t k = LatticeKey(i);
  const double g0 = 2 * Hash01(k, 0, 0x6e6f697365ULL) - 1, g1 = 2 * Hash01(k + 1, 0, 0x6e6f697365ULL) - 1;
  const double s = f * f * f * (f * (f * 6 - 15) + 10);
  return (1 - s) * g0 * f + s * g1 * (f - 1);
}

Rgb ParseColor(const nlohmann::json& v, const std::string& field) {
  auto ok = [](const nlohmann::json& x) { return x.is_number() && std::isfinite(x.get<double>()) && x.get<double>() >= 0; };
  if (ok(v)) return {v.get<double>(), v.get<double>(), v.get<double>()};
  if (v.is_array() && v.size() == 3 && ok(v[0]) && ok(v[1]) && ok(v[2]))
    return {v[0].get<double>(), v[1].get<double>(), v[2].get<double>()};
  ThrowUsage("irawan2012 parameter '{}' must be a number >= 0 or [r, g, b] (linear RGB albedo), got {}", field, v.dump());
}

double ParsePositive(const nlohmann::json& v, const std::string& field) {
  if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() <= 0)
    ThrowUsage("irawan2012 parameter '{}' must be a number > 0, got {}", field, v.dump());
  return v.get<double>();
}

nlohmann::json RgbJson(const Rgb& c) { return nlohmann::json::array({c[0], c[1], c[2]}); }

}  // namespace

void Irawan2012Options::Check() const {
  BTF_CHECK_OPTION(std::isfinite(repeat_u) && repeat_u > 0, "repeat_u", "must be > 0");
  BTF_CHECK_OPTION(std::isfinite(repeat_v) && repeat_v > 0, "repeat_v", "must be > 0");
  BTF_CHECK_OPTION(nspec_order >= 4 && nspec_order <= 64, "nspec_order", "must lie in [4, 64]");
  BTF_CHECK_OPTION(std::isfinite(tile_mm) && tile_mm > 0, "tile_mm", "must be > 0");
}

Irawan2012Model::Irawan2012Model(std::string preset_name, WeavePattern pattern, const Irawan2012Options& options)
    : preset_(std::move(preset_name)), pattern_(std::move(pattern)), options_(options) {
  ValidateWeavePattern(pattern_, "irawan2012/" + preset_);
  options_.Check();
  const double total_area = pattern_.warp_area + pattern_.weft_area;
  for (std::size_t i = 0; i < pattern_.yarns.size(); ++i) {
    const WeaveYarn& y = pattern_.yarns[i];
    YarnCache c{};
    c.alpha = pattern_.AlphaOf(y);
    c.beta = pattern_.BetaOf(y);
    c.ss = pattern_.SsOf(y);
    c.vm_norm = irawan2012::VonMisesNorm(c.beta);
    const double area = y.type == WeaveYarn::Type::kWarp ? pattern_.warp_area : pattern_.weft_area;
    c.area_factor = area > 0 ? total_area / area : 0;
    // The reference guard: C = l/2 - (w/2) sin(umax) <= 0 has no spine; the highlight is zeroed.
    c.disabled = y.width * std::sin(y.umax) >= y.length;
    c.staple = y.psi != 0;
    if (c.disabled) disabled_.push_back(static_cast<int>(i) + 1);
    cache_.push_back(c);
  }
  ComputeNormalization();
}

Irawan2012Model::Local Irawan2012Model::Locate(const Vec2& uv_in) const {
  // Beyond 2^30 a double uv has no sub-cell precision left; such (and non-finite) uv read as 0.
  const auto usable = [](double t) { return std::abs(t) < 0x1p30 ? t : 0.0; };
  const double u = usable(uv_in.x()), v = usable(uv_in.y());
  // Pattern rows are listed from the top, hence the v flip.
  return LocateCell(u * options_.repeat_u * pattern_.tile_width, (1 - v) * options_.repeat_v * pattern_.tile_height);
}

Irawan2012Model::Local Irawan2012Model::LocateCell(double cell_x, double cell_y) const {
  const double W = pattern_.tile_width, H = pattern_.tile_height;
  Local loc{};
  loc.cell_x = cell_x;
  loc.cell_y = cell_y;
  const double tx = std::floor(loc.cell_x / W), ty = std::floor(loc.cell_y / H);
  int cx = static_cast<int>(std::floor(loc.cell_x - tx * W));
  int cy = static_cast<int>(std::floor(loc.cell_y - ty * H));
  cx = std::clamp(cx, 0, pattern_.tile_width - 1);  // rounding at the tile edge
  cy = std::clamp(cy, 0, pattern_.tile_height - 1);
  loc.yarn = pattern_.pattern[static_cast<std::size_t>(cy * pattern_.tile_width + cx)] - 1;
  const WeaveYarn& y = pattern_.yarns[static_cast<std::size_t>(loc.yarn)];
  loc.center_x = tx * W + y.center_u * W;
  loc.center_y = ty * H + (1 - y.center_v) * H;
  loc.x = loc.cell_x - loc.center_x;
  loc.y = -(loc.cell_y - loc.center_y);
  if (y.type == WeaveYarn::Type::kWeft) {  // weft runs along x: rotate by +90 deg about z
    const double t = loc.x;
    loc.x = -loc.y;
    loc.y = t;
  }
  return loc;
}

int Irawan2012Model::YarnIndexAt(const Vec2& uv) const { return Locate(uv).yarn + 1; }

double Irawan2012Model::NoisyUmax(const Local& loc, const WeaveYarn& y) const {
  if (!options_.noise || pattern_.period <= 0) return y.umax;
  const bool warp = y.type == WeaveYarn::Type::kWarp;
  const double d_warp = warp ? pattern_.d_warp_umax_over_d_warp : pattern_.d_weft_umax_over_d_warp;
  const double d_weft = warp ? pattern_.d_warp_umax_over_d_weft : pattern_.d_weft_umax_over_d_weft;
  // One seed per segment (its center, quantized to 1/64 cell), one noise value along each
  // thread direction: the same structure as Mitsuba's, with our own hash and noise.
  const std::uint64_t kx = LatticeKey(std::round(loc.center_x * 64)), ky = LatticeKey(std::round(loc.center_y * 64));
  const double sx = pattern_.tile_height * options_.repeat_v + Hash01(kx, 2 * ky, 0x756d6178ULL);
  const double sy = pattern_.tile_width * options_.repeat_u + Hash01(kx, 2 * ky + 1, 0x756d6178ULL);
  const double r1 = GradientNoise1((loc.center_x * sx + loc.center_y) / pattern_.period);
  const double r2 = GradientNoise1((loc.center_y * sy + loc.center_x) / pattern_.period);
  // Clamped to the model's domain [0, 90 deg] (Mitsuba does not clamp).
  return std::clamp(y.umax + r1 * d_warp + r2 * d_weft, 0.0, kPi / 2);
}

double Irawan2012Model::IntensityVariation(const Local& loc) const {
  if (!options_.noise || pattern_.fineness <= 0) return 1;
  // Exp(1) factor per 1/fineness grid cell of the (unrotated) pattern position.
  const std::uint64_t ix = LatticeKey(loc.cell_x * pattern_.fineness), iy = LatticeKey(loc.cell_y * pattern_.fineness);
  return std::min(-std::log(Hash01(ix, iy, 0x69765f6eULL)), 10.0);
}

double Irawan2012Model::Band(const Local& loc, Vec3 wi, Vec3 wo) const {
  const WeaveYarn& y = pattern_.yarns[static_cast<std::size_t>(loc.yarn)];
  const YarnCache& yc = cache_[static_cast<std::size_t>(loc.yarn)];
  if (yc.disabled) return 0;
  if (y.type == WeaveYarn::Type::kWeft) {
    wi = Vec3(-wi.y(), wi.x(), wi.z());
    wo = Vec3(-wo.y(), wo.x(), wo.z());
  }
  const double umax = NoisyUmax(loc, y);
  const double w = y.width, l = y.length, a = 0.5 * w;
  if (w * std::sin(umax) >= l) return 0;  // noise may push a yarn into the guard
  const Vec3 sum = wi + wo;
  const double len = sum.norm();  // = 2 cos(theta_d)
  if (!(len > 1e-12)) return 0;
  const Vec3 h = sum / len;
  const double hw = pattern_.h_width;

  if (!yc.staple) {
    // Filament: the highlight sits where the fibre tangent (0, cos u, -sin u) is normal to h.
    if (!(umax > 0)) return 0;
    const double u_star = std::atan(h.y() / h.z());  // h.z > 0 above the surface
    if (!(std::abs(u_star) < umax)) return 0;
    // Band test first: most points of a segment lie outside its highlight band.
    const double dy = l * hw;
    const double y_star = std::clamp(u_star * 0.5 * l / umax, -0.5 * (l - dy), 0.5 * (l - dy));
    if (!(std::abs(y_star - loc.y) < 0.5 * dy)) return 0;
    const double v = loc.x * kPi / w;
    const double umax_s = (1 - yc.ss) * umax;
    const double R = SpineRadius(std::min(std::abs(u_star), umax_s), umax_s, y.kappa, w, l);
    const double cross = std::sqrt(h.y() * h.y() + h.z() * h.z());  // |(t x h).x| at u*
    if (!(cross > 0)) return 0;
    const double Gu = a * (R + a * std::cos(v)) / (len * cross);
    const Vec3 n(std::sin(v), std::sin(u_star) * std::cos(v), std::cos(u_star) * std::cos(v));
    double A = Seeliger(n.dot(wi), n.dot(wo));
    if (yc.ss > 0) A *= 1 - SmoothStep01((std::abs(u_star) - umax_s) / (yc.ss * umax));
    const double fc = yc.alpha + std::exp(yc.beta * (-wi.dot(wo)) - std::abs(yc.beta)) * yc.vm_norm;
    const double value = Gu * fc * A * kPi * l / dy;  // pi l: the reference's domain transform
    return std::isfinite(value) && value > 0 ? value : 0.0;
  }

  // Staple: solve t(u, v) . h = 0 for v at this point's u (one root, as the reference).
  const double u = loc.y / (0.5 * l) * umax;
  const double su = std::sin(u), cu = std::cos(u);
  const double B = h.y() * su + h.z() * cu;
  const double den = std::sqrt(h.x() * h.x() + B * B) * std::tan(y.psi);
  if (!(std::abs(den) > 0)) return 0;
  const double D = (h.y() * cu - h.z() * su) / den;
  if (!(std::abs(D) < 1)) return 0;
  const double v_star = std::atan2(-B, h.x()) + std::acos(D);
  if (!(std::abs(v_star) < kPi / 2)) return 0;
  const double dx = w * hw;
  const double x_star = std::clamp(v_star * w / kPi, -0.5 * (w - dx), 0.5 * (w - dx));
  if (!(std::abs(x_star - loc.x) < 0.5 * dx)) return 0;  // outside the highlight band
  const Vec3 n(std::sin(v_star), su * std::cos(v_star), cu * std::cos(v_star));
  const double A = Seeliger(n.dot(wi), n.dot(wo));
  if (A == 0) return 0;  // also guarantees n.h > 0 below
  const double R = SpineRadius(std::abs(u), umax, y.kappa, w, l);
  const double Gv = a * (R + a * std::cos(v_star)) / (len * n.dot(h) * std::abs(std::sin(y.psi)));
  const double fc = yc.alpha + std::exp(yc.beta * (-wi.dot(wo)) - std::abs(yc.beta)) * yc.vm_norm;
  const double value = Gv * fc * A * 2 * w * umax / dx;  // 2 w umax: the reference's domain transform
  return std::isfinite(value) && value > 0 ? value : 0.0;
}

namespace {
bool Normalize(const Vec3& in, Vec3* out) {
  const double n = in.norm();
  if (!(n > 0) || !std::isfinite(n)) return false;
  *out = in / n;
  return true;
}
}  // namespace

double Irawan2012Model::BandValue(const Vec2& uv, const Vec3& wi_in, const Vec3& wo_in) const {
  Vec3 wi, wo;
  if (!Normalize(wi_in, &wi) || !Normalize(wo_in, &wo) || wi.z() <= 0 || wo.z() <= 0) return 0;
  return Band(Locate(uv), wi, wo);
}

double Irawan2012Model::SpecularIntegrand(const Vec2& uv, const Vec3& wi_in, const Vec3& wo_in) const {
  Vec3 wi, wo;
  if (!Normalize(wi_in, &wi) || !Normalize(wo_in, &wo) || wi.z() <= 0 || wo.z() <= 0) return 0;
  const Local loc = Locate(uv);
  const double band = Band(loc, wi, wo);
  if (band == 0) return 0;
  return band * IntensityVariation(loc) * cache_[static_cast<std::size_t>(loc.yarn)].area_factor;
}

void Irawan2012Model::EvalUnit(const Vec2& uv, const Vec3& wi, const Vec3& wo, double out[3]) const {
  const Local loc = Locate(uv);
  const WeaveYarn& y = pattern_.yarns[static_cast<std::size_t>(loc.yarn)];
  double spec = Band(loc, wi, wo);
  if (spec > 0) spec *= IntensityVariation(loc) * cache_[static_cast<std::size_t>(loc.yarn)].area_factor * nspec_;
  for (std::size_t c = 0; c < 3; ++c) out[c] = y.kd[c] / kPi + y.ks[c] * spec;
}

void Irawan2012Model::EvalRgb(const Vec2& uv, const Vec3& wi_in, const Vec3& wo_in, double out[3]) const {
  out[0] = out[1] = out[2] = 0;
  Vec3 wi, wo;
  if (!Normalize(wi_in, &wi) || !Normalize(wo_in, &wo) || wi.z() <= 0 || wo.z() <= 0) return;
  EvalUnit(uv, wi, wo, out);
}

void Irawan2012Model::Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const {
  double v[3];
  EvalRgb(uv, wi, wo, v);
  for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(v[c]);
}

void Irawan2012Model::EvalBatch(const Vec3& wi_in, const Vec3& wo_in, const Vec2* uv, int n, float* out) const {
  Vec3 wi, wo;
  const bool above = Normalize(wi_in, &wi) && Normalize(wo_in, &wo) && wi.z() > 0 && wo.z() > 0;
  for (int i = 0; i < n; ++i) {
    double v[3] = {0, 0, 0};
    if (above) EvalUnit(uv[i], wi, wo, v);
    for (int c = 0; c < 3; ++c) out[static_cast<std::ptrdiff_t>(i) * 3 + c] = static_cast<float>(v[c]);
  }
}

nlohmann::json Irawan2012Model::Describe() const {
  nlohmann::json yarns = nlohmann::json::array();
  for (std::size_t i = 0; i < pattern_.yarns.size(); ++i) {
    const WeaveYarn& y = pattern_.yarns[i];
    const YarnCache& c = cache_[i];
    yarns.push_back({{"index", i + 1},
                     {"type", y.type == WeaveYarn::Type::kWarp ? "warp" : "weft"},
                     {"kind", c.staple ? "staple" : "filament"},
                     {"psi_deg", RadToDeg(y.psi)},
                     {"umax_deg", RadToDeg(y.umax)},
                     {"kappa", y.kappa},
                     {"width", y.width},
                     {"length", y.length},
                     {"center_u", y.center_u},
                     {"center_v", y.center_v},
                     {"kd", RgbJson(y.kd)},
                     {"ks", RgbJson(y.ks)},
                     {"alpha", c.alpha},
                     {"beta", c.beta},
                     {"ss", c.ss},
                     {"specular_disabled_by_guard", c.disabled}});
  }
  nlohmann::json disabled = nlohmann::json::array();
  for (int i : disabled_) {
    const WeaveYarn& y = pattern_.yarns[static_cast<std::size_t>(i - 1)];
    disabled.push_back({{"index", i},
                        {"type", y.type == WeaveYarn::Type::kWarp ? "warp" : "weft"},
                        {"reason", fmt::format("w sin(umax) = {:.6g} >= l = {:.6g} (reference guard: specular term is 0)",
                                               y.width * std::sin(y.umax), y.length)}});
  }
  return {
      {"model", "irawan2012"},
      {"preset", preset_},
      {"reference", "Irawan & Marschner 2012 as implemented by Mitsuba 0.6 'irawan' (our own code)"},
      {"units", "BRDF in 1/sr without cos(theta_i) or cos(theta_o); kd, ks are albedos (f = kd/pi + ks*N_spec*...)"},
      {"weave",
       {{"name", pattern_.name},
        {"tile_width", pattern_.tile_width},
        {"tile_height", pattern_.tile_height},
        {"alpha", pattern_.alpha},
        {"beta", pattern_.beta},
        {"ss", pattern_.ss},
        {"h_width", pattern_.h_width},
        {"warp_area", pattern_.warp_area},
        {"weft_area", pattern_.weft_area},
        {"d_warp_umax_over_d_warp_deg", RadToDeg(pattern_.d_warp_umax_over_d_warp)},
        {"d_warp_umax_over_d_weft_deg", RadToDeg(pattern_.d_warp_umax_over_d_weft)},
        {"d_weft_umax_over_d_warp_deg", RadToDeg(pattern_.d_weft_umax_over_d_warp)},
        {"d_weft_umax_over_d_weft_deg", RadToDeg(pattern_.d_weft_umax_over_d_weft)},
        {"fineness", pattern_.fineness},
        {"period", pattern_.period},
        {"pattern", pattern_.pattern},
        {"yarns", yarns}}},
      {"repeat_u", options_.repeat_u},
      {"repeat_v", options_.repeat_v},
      {"tile_mm", options_.tile_mm},
      {"noise", options_.noise},
      {"noise_note", options_.noise ? "umax noise and intensity variation use libbtf's own hash and gradient noise; "
                                      "no equivalence with Mitsuba's random sequence is claimed"
                                    : "off: period and fineness are ignored (ground truth)"},
      {"specular_normalization",
       {{"value", nspec_},
        {"method", "deterministic quadrature: band coordinate exact, tensor Gauss-Legendre over the highlight "
                   "point (u, v) and the direction pair (theta, phi_i, phi_o), split at every kink"},
        {"order", options_.nspec_order},
        {"outer_nodes", nspec_nodes_},
        {"relative_error_estimate", nspec_rel_err_},
        {"error_estimate_order", options_.nspec_order - std::max(2, options_.nspec_order / 4)}}},
      {"disabled_yarns", disabled},
  };
}

std::unique_ptr<Irawan2012Model> MakeIrawan2012(const std::string& preset, const nlohmann::json& params_in) {
  const nlohmann::json params = params_in.is_null() ? nlohmann::json::object() : params_in;
  if (!params.is_object()) ThrowUsage("irawan2012 parameters must be a JSON object, got {}", params.dump());
  static const char* const kKnown[] = {"repeat_u", "repeat_v", "noise",   "nspec_order", "tile_mm",  "kd",
                                       "ks",       "warp_kd",  "warp_ks", "weft_kd",     "weft_ks",  "variables"};
  for (const auto& item : params.items()) {
    const std::string& key = item.key();  // not a structured binding: clang 14 cannot capture those
    if (std::find_if(std::begin(kKnown), std::end(kKnown), [&](const char* k) { return key == k; }) == std::end(kKnown))
      ThrowUsage("unknown irawan2012 parameter '{}' (known: repeat_u, repeat_v, noise, nspec_order, tile_mm, kd, ks, "
                 "warp_kd, warp_ks, weft_kd, weft_ks, variables)",
                 key);
  }
  const nlohmann::json vars = params.value("variables", nlohmann::json::object());
  if (!vars.is_object()) ThrowUsage("irawan2012 parameter 'variables' must be a JSON object of $name values");

  WeavePattern pattern;
  std::string name = preset;
  const auto names = WeavePresetNames();
  if (std::find(names.begin(), names.end(), preset) != names.end()) {
    pattern = WeavePreset(preset);
  } else if (preset.size() > 3 && (preset.ends_with(".wv") || std::filesystem::exists(preset))) {
    pattern = LoadWeavePattern(preset, vars);
    name = "file:" + std::filesystem::path(preset).stem().string();
  } else {
    WeavePreset(preset);  // throws the usage error listing the presets
  }

  Irawan2012Options o;
  if (params.contains("repeat_u")) o.repeat_u = ParsePositive(params["repeat_u"], "repeat_u");
  if (params.contains("repeat_v")) o.repeat_v = ParsePositive(params["repeat_v"], "repeat_v");
  if (params.contains("tile_mm")) o.tile_mm = ParsePositive(params["tile_mm"], "tile_mm");
  if (params.contains("noise")) {
    if (!params["noise"].is_boolean()) ThrowUsage("irawan2012 parameter 'noise' must be true or false");
    o.noise = params["noise"].get<bool>();
  }
  if (params.contains("nspec_order")) {
    const auto& v = params["nspec_order"];
    if (!v.is_number_integer() || v.get<long long>() < 4 || v.get<long long>() > 64)
      ThrowUsage("irawan2012 parameter 'nspec_order' must be an integer in [4, 64], got {}", v.dump());
    o.nspec_order = static_cast<int>(v.get<long long>());
  }
  for (const char* field : {"kd", "ks", "warp_kd", "warp_ks", "weft_kd", "weft_ks"}) {
    if (!params.contains(field)) continue;
    const Rgb c = ParseColor(params[field], field);
    const std::string f(field);
    const bool diffuse = f.ends_with("kd");
    for (auto& y : pattern.yarns) {
      const bool applies = f.size() == 2 || (f.starts_with("warp") == (y.type == WeaveYarn::Type::kWarp));
      if (applies) (diffuse ? y.kd : y.ks) = c;
    }
  }
  return std::make_unique<Irawan2012Model>(name, std::move(pattern), o);
}

std::unique_ptr<SvbrdfModel> MakeIrawan2012Model(const std::string& preset, const nlohmann::json& params) {
  return MakeIrawan2012(preset, params);
}

}  // namespace btf
