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

// 1 / (2 pi e^{-|b|} I0(|b|)): the part of VonMises that depends on b alone (cached per kernel).
double VonMisesNorm(double b) { return 1 / (2 * kPi * ScaledI0(std::abs(b))); }

}  // namespace

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
using irawan2012::SpineRadius;

double SmoothStep01(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3 - 2 * x);
}

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

namespace {

// ---------------------------------------------------------------------------------------------
// N_spec by deterministic quadrature (docs/btf-synth.md, "Normalization N_spec").
//
// E[g] = (1 / (pi^2 A_uv)) int_uv int_wi int_wo g cos(theta_i) cos(theta_o). Per yarn segment the
// band is a box of width Delta along one yarn coordinate (filament: y, staple: x): that coordinate
// is integrated exactly (overlap of the band with the cell, piecewise linear in the highlight
// position). The directions are written relative to the highlight point (u, v) on the yarn
// (filament: u = u*, v = pi x / w; staple: u = 2 umax y / l, v = v*) in the fibre frame there:
//   wi = sin(theta) t + cos(theta) (cos(phi_i) n + sin(phi_i) b),
//   wo = -sin(theta) t + cos(theta) (cos(phi_o) n + sin(phi_o) b),
// so t . h = 0 and h = cos(a) n + sin(a) b, a = (phi_i + phi_o) / 2. Then
//   dwi dwo = 2 cos(theta_d) J cos(theta) ds dtheta dphi_i dphi_o,
// s = u, J = cos(a + v) at fixed v (filament); s = v, J = |sin psi| cos(a) at fixed u (staple),
// and 2 cos(theta_d) J is exactly the denominator of the model's geometry factor G (the
// reference's "domain transform"). What is left is smooth:
//   E[g] = sum_segments C int du int dv K(u, v) (R(u) + (w/2) cos v) Phi(u, v),
//   Phi(u, v) = (1/4pi) int dtheta cos(theta)^2 int dphi_i int dphi_o wi_z wo_z fc c_i c_o / (c_i + c_o),
// K the band overlap (times smoothing, area factor, iv), C = 2 (w/2) w l / (pi^2 Delta),
// c = cos(phi). Seeliger's A > 0 is |phi| < pi/2; wi_z, wo_z > 0 cut each phi to an arc whose
// ends depend on theta only. Every kink then lies on a coordinate line: K's kinks and ends, the
// smoothing and clamp points, u = 0, v = 0, v = +-pi/2 and (staple) the curves where z_t or
// z_b = 0 (outer); the theta where an arc end meets +-pi/2 (inner). Tensor Gauss-Legendre between
// kinks converges fast (order 16: 1e-8 .. 1e-6 relative on the presets); the inner rules are
// composed with t -> t^2 (3 - 2t), which absorbs the square-root ends where an arc closes.
// Staple quirk: the reference takes v* = atan2(-B, h_x) + acos(D) and requires |v*| < pi/2, so
// for v < 0 the pairs with v + atan(cos(psi) tan(a)) <= -pi/2 (whose v* comes out 2 pi too large)
// have no highlight; the quadrature cuts them off (phi_i + phi_o > 2 atan(cot(v) / cos(psi))).

struct QuadRule {
  std::vector<double> x, w;  // nodes and weights on [0, 1]
};

QuadRule GaussLegendre(int n) {
  QuadRule r{std::vector<double>(static_cast<std::size_t>(n)), std::vector<double>(static_cast<std::size_t>(n))};
  auto legendre = [n](double z, double* pn, double* pn1) {  // P_n(z), P_{n-1}(z)
    double p0 = 1, p1 = z;
    for (int k = 2; k <= n; ++k) {
      const double p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k;
      p0 = p1;
      p1 = p2;
    }
    *pn = n == 0 ? 1 : p1;
    *pn1 = p0;
  };
  for (int i = 0; i < n; ++i) {
    double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), pn = 0, pn1 = 0;
    for (int it = 0; it < 100; ++it) {
      legendre(z, &pn, &pn1);
      const double dz = pn / (n * (z * pn - pn1) / (z * z - 1));
      z -= dz;
      if (std::abs(dz) < 1e-16) break;
    }
    legendre(z, &pn, &pn1);
    const double dp = n * (z * pn - pn1) / (z * z - 1);
    r.x[static_cast<std::size_t>(i)] = 0.5 * (1 - z);
    r.w[static_cast<std::size_t>(i)] = 1 / ((1 - z * z) * dp * dp);
  }
  return r;
}

// Gauss-Legendre composed with t -> t^2 (3 - 2t) (zero slope at both ends).
QuadRule EndClustered(int n) {
  QuadRule r = GaussLegendre(n);
  for (std::size_t i = 0; i < r.x.size(); ++i) {
    const double t = r.x[i];
    r.x[i] = t * t * (3 - 2 * t);
    r.w[i] *= 6 * t * (1 - t);
  }
  return r;
}

// e^x for x <= 0 (x < -700 reads as -700), ~1 ulp, written so that loops over it vectorise: Cody-Waite
// reduction x = k ln2 + r, Taylor polynomial of degree 13 for |r| <= ln2 / 2, 2^k built in the bits.
inline double ExpNonPositive(double x) {
  x = std::max(x, -700.0);
  const double k = std::floor(x * 1.4426950408889634 + 0.5);
  const double r = (x - k * 6.93147180369123816490e-01) - k * 1.90821492927058770002e-10;
  double p = 1.0 / 6227020800.0;
  p = p * r + 1.0 / 479001600.0;
  p = p * r + 1.0 / 39916800.0;
  p = p * r + 1.0 / 3628800.0;
  p = p * r + 1.0 / 362880.0;
  p = p * r + 1.0 / 40320.0;
  p = p * r + 1.0 / 5040.0;
  p = p * r + 1.0 / 720.0;
  p = p * r + 1.0 / 120.0;
  p = p * r + 1.0 / 24.0;
  p = p * r + 1.0 / 6.0;
  p = p * r + 0.5;
  p = p * r + 1.0;
  p = p * r + 1.0;
  // k + 1.5 * 2^52 holds k in its low mantissa bits; k + 1023 in [1, 1023] is the exponent of 2^k.
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(k + 0x1.8p52);
  return p * std::bit_cast<double>((bits + 1023) << 52);
}

// sin and cos for |x| <= 1.6 (Taylor series to x^23 / x^22, error < 1e-19), vectorisable.
inline void SinCosSmall(double x, double* s, double* c) {
  const double x2 = x * x;
  double ps = 1 - x2 * (1.0 / 506), pc = 1 - x2 * (1.0 / 462);
  ps = 1 - x2 * (1.0 / 420) * ps;
  pc = 1 - x2 * (1.0 / 380) * pc;
  ps = 1 - x2 * (1.0 / 342) * ps;
  pc = 1 - x2 * (1.0 / 306) * pc;
  ps = 1 - x2 * (1.0 / 272) * ps;
  pc = 1 - x2 * (1.0 / 240) * pc;
  ps = 1 - x2 * (1.0 / 210) * ps;
  pc = 1 - x2 * (1.0 / 182) * pc;
  ps = 1 - x2 * (1.0 / 156) * ps;
  pc = 1 - x2 * (1.0 / 132) * pc;
  ps = 1 - x2 * (1.0 / 110) * ps;
  pc = 1 - x2 * (1.0 / 90) * pc;
  ps = 1 - x2 * (1.0 / 72) * ps;
  pc = 1 - x2 * (1.0 / 56) * pc;
  ps = 1 - x2 * (1.0 / 42) * ps;
  pc = 1 - x2 * (1.0 / 30) * pc;
  ps = 1 - x2 * (1.0 / 20) * ps;
  pc = 1 - x2 * (1.0 / 12) * pc;
  ps = 1 - x2 * (1.0 / 6) * ps;
  pc = 1 - x2 * 0.5 * pc;
  *s = x * ps;
  *c = pc;
}

// The phase function and frame parameters Phi depends on.
struct PhiParams {
  double alpha, beta, vm_norm, psi;
  bool staple;
};

// Phi(u, v): the inner three-dimensional integral (see above). One instance per thread (scratch).
class DirectionIntegral {
 public:
  explicit DirectionIntegral(int order) : theta_(EndClustered(order)), phi_(EndClustered(order)) {
    const std::size_t n = phi_.x.size();
    for (auto* a : {&ci_, &si_, &wzi_, &co_, &so_, &wzo_}) a->resize(n);
  }

  double operator()(double u, double v, const PhiParams& p) {
    const irawan2012::FibreFrame f = irawan2012::MakeFibreFrame(u, v, p.psi);
    zt_ = f.t.z();
    zn_ = f.n.z();
    zb_ = f.b.z();
    const double rho = std::hypot(zn_, zb_);
    if (!(rho > 0)) return 0;
    phz_ = std::atan2(zb_, zn_);
    // wi_z > 0 and wo_z > 0 need |tan(theta) z_t| < rho (theta_max); an arc end crosses +-pi/2
    // where |tan(theta) z_t| = rho |sin(phi_z)| (theta_b): the two inner theta panels. The
    // integrand is even under (theta, phi_i, phi_o) -> (-theta, phi_o, phi_i): theta >= 0 only.
    const double theta_max = std::atan2(rho, std::abs(zt_));
    const double theta_b = std::min(theta_max, std::atan2(rho * std::abs(std::sin(phz_)), std::abs(zt_)));
    constrained_ = p.staple && v < 0;
    two_a_min_ = constrained_ ? 2 * std::atan(1 / (std::tan(v) * std::cos(p.psi))) : 0;
    p_ = &p;
    double total = 0;
    const double panels[3] = {0, theta_b, theta_max};
    for (int k = 0; k < 2; ++k) {
      const double t0 = panels[k], t1 = panels[k + 1];
      if (!(t1 > t0)) continue;
      for (std::size_t i = 0; i < theta_.x.size(); ++i) {
        const double th = t0 + (t1 - t0) * theta_.x[i];
        total += (t1 - t0) * theta_.w[i] * AtTheta(th, rho);
      }
    }
    return total / (4 * kPi);
  }

 private:
  // Arcs {phi in (-pi/2, pi/2) : cos(phi - phi_z) > kappa}: at most two intervals.
  int Arcs(double kappa, double lo[2], double hi[2]) const {
    if (kappa < -1) {
      lo[0] = -kPi / 2;
      hi[0] = kPi / 2;
      return 1;
    }
    if (!(kappa < 1)) return 0;
    const double g = std::acos(kappa);
    int n = 0;
    for (double shift : {-2 * kPi, 0.0, 2 * kPi}) {
      const double a = std::max(-kPi / 2, phz_ + shift - g), b = std::min(kPi / 2, phz_ + shift + g);
      if (b > a && n < 2) {
        lo[n] = a;
        hi[n] = b;
        ++n;
      }
    }
    return n;
  }

  // Nodes of an interval: cos, sin and weight * omega_z (sign = +1 for wi, -1 for wo).
  void FillNodes(double lo, double hi, double c, double s, double sign, double* cs, double* sn, double* wz) const {
    const std::size_t n = phi_.x.size();
    const double len = hi - lo, zn = zn_, zb = zb_, zt = zt_;
#pragma omp simd
    for (std::size_t k = 0; k < n; ++k) {
      double sk, ck;
      SinCosSmall(lo + len * phi_.x[k], &sk, &ck);
      cs[k] = ck;
      sn[k] = sk;
      wz[k] = len * phi_.w[k] * std::max(0.0, c * (ck * zn + sk * zb) + sign * s * zt);
    }
  }

  // Sum over the phi_o nodes for one phi_i node.
  double SumOut(double cpi, double spi, double e0, double bc2) const {
    const std::size_t n = phi_.x.size();
    const double alpha = p_->alpha, vmn = p_->vm_norm, beta_c2 = bc2;
    const double* co = co_.data();
    const double* so = so_.data();
    const double* wz = wzo_.data();
    double acc = 0;
#pragma omp simd reduction(+ : acc)
    for (std::size_t k = 0; k < n; ++k) {
      const double cos_d = cpi * co[k] + spi * so[k];  // cos(phi_i - phi_o)
      const double fc = alpha + vmn * ExpNonPositive(e0 - beta_c2 * cos_d);
      acc += wz[k] * fc * co[k] / (cpi + co[k]);
    }
    return acc;
  }

  // cos(theta) * int dphi_i int dphi_o wi_z wo_z fc A * 4 pi at one theta.
  double AtTheta(double th, double rho) {
    const double c = std::cos(th), s = std::sin(th);
    const double k = std::tan(th) * zt_ / rho;
    double loi[2], hii[2], loo[2], hio[2];
    const int ni = Arcs(-k, loi, hii), no = Arcs(k, loo, hio);
    if (ni == 0 || no == 0) return 0;
    // fc = alpha + vm_norm exp(beta (-wi.wo) - |beta|), -wi.wo = s^2 - c^2 cos(phi_i - phi_o).
    const double beta = p_->beta, e0 = beta * s * s - std::abs(beta), bc2 = beta * c * c;
    const std::size_t n = phi_.x.size();
    double total = 0;
    for (int a = 0; a < ni; ++a) {
      FillNodes(loi[a], hii[a], c, s, 1, ci_.data(), si_.data(), wzi_.data());
      for (int b = 0; b < no; ++b) {
        if (!constrained_) {
          FillNodes(loo[b], hio[b], c, s, -1, co_.data(), so_.data(), wzo_.data());
          for (std::size_t i = 0; i < n; ++i)
            if (wzi_[i] > 0) total += wzi_[i] * ci_[i] * SumOut(ci_[i], si_[i], e0, bc2);
          continue;
        }
        // phi_o > 2 a_min - phi_i: the phi_i range where that leaves an interval, split where the
        // cut takes over from the arc's lower end.
        const double start = std::max(loi[a], two_a_min_ - hio[b]), kink = two_a_min_ - loo[b];
        const double ends[3] = {start, std::clamp(kink, start, hii[a]), hii[a]};
        for (int q = 0; q < 2; ++q) {
          const double lo = ends[q], hi = ends[q + 1];
          if (!(hi > lo)) continue;
          const double len = hi - lo;
          for (std::size_t i = 0; i < n; ++i) {
            const double ph = lo + len * phi_.x[i];
            double sp, cp;
            SinCosSmall(ph, &sp, &cp);
            const double wz = len * phi_.w[i] * std::max(0.0, c * (cp * zn_ + sp * zb_) + s * zt_);
            if (!(wz > 0)) continue;
            FillNodes(std::max(loo[b], two_a_min_ - ph), hio[b], c, s, -1, co_.data(), so_.data(), wzo_.data());
            total += wz * cp * SumOut(cp, sp, e0, bc2);
          }
        }
      }
    }
    return c * c * total;  // cos(theta) measure, and the cos(theta) of A
  }

  QuadRule theta_, phi_;
  std::vector<double> ci_, si_, wzi_, co_, so_, wzo_;
  double zt_ = 0, zn_ = 0, zb_ = 0, phz_ = 0, two_a_min_ = 0;
  bool constrained_ = false;
  const PhiParams* p_ = nullptr;
};

// A piece of a segment (one cell, or part of one) in the yarn's local frame, with its weight.
struct NormPiece {
  double x0, x1, y0, y1, weight;
};
// Segments that share every parameter Phi and the outer integrand depend on.
struct NormClass {
  double psi, umax, kappa, w, l, alpha, beta, ss;
  std::vector<NormPiece> pieces;
};

double Overlap(double a0, double a1, double b0, double b1) { return std::max(0.0, std::min(a1, b1) - std::max(a0, b0)); }

// Sorted breakpoints inside [lo, hi] (ends included), near-duplicates merged.
std::vector<double> Breakpoints(std::vector<double> b, double lo, double hi) {
  b.push_back(lo);
  b.push_back(hi);
  std::vector<double> in;
  for (double x : b)
    if (x >= lo && x <= hi) in.push_back(x);
  std::sort(in.begin(), in.end());
  std::vector<double> out;
  const double tol = 1e-12 * (hi - lo);
  for (double x : in)
    if (out.empty() || x - out.back() > tol) out.push_back(x);
  out.back() = hi;
  return out;
}

// Gauss-Legendre nodes (position, weight) of every panel between breakpoints: per_range nodes
// over the whole range, shared out by panel width, at least min_nodes per panel, except narrow
// panels (slivers that rounded segment centers leave): an n-node rule on a fraction f of the range
// errs by ~f^(2n+1), so 3 nodes below f = 8 %, 2 below 2 %, 1 below 0.2 %. With
// `shape` (a cheap factor of the integrand, e.g. the spine radius), panels where Gauss-Legendre
// cannot integrate it to 1e-10 of its total are bisected first.
class OuterRule {
 public:
  OuterRule(int per_range, int min_nodes) : per_range_(per_range), min_nodes_(min_nodes) {}

  void Nodes(const std::vector<double>& breaks, double range, std::vector<std::pair<double, double>>* out,
             const std::function<double(double)>& shape = {}) {
    out->clear();
    std::vector<Panel> panels;
    for (std::size_t i = 0; i + 1 < breaks.size(); ++i)
      panels.push_back({breaks[i], breaks[i + 1], Count(breaks[i + 1] - breaks[i], range)});
    if (shape) {
      double total = 0;
      for (const Panel& pn : panels) total += std::abs(Integrate(shape, pn.a, pn.b, 2 * pn.n));
      std::vector<Panel> refined;
      for (const Panel& pn : panels) Refine(shape, pn, range, 1e-10 * total, 0, &refined);
      panels.swap(refined);
    }
    for (const Panel& pn : panels) {
      const QuadRule& r = Rule(pn.n);
      for (std::size_t k = 0; k < r.x.size(); ++k) out->push_back({pn.a + (pn.b - pn.a) * r.x[k], (pn.b - pn.a) * r.w[k]});
    }
  }

 private:
  struct Panel {
    double a, b;
    int n;
  };
  int Count(double width, double range) const {
    const double f = width / range;
    const int floor_nodes = f < 2e-3 ? 1 : f < 2e-2 ? 2 : f < 0.08 ? std::min(3, min_nodes_) : min_nodes_;
    return std::max(floor_nodes, static_cast<int>(std::ceil(per_range_ * f - 1e-9)));
  }
  const QuadRule& Rule(int n) {
    if (static_cast<std::size_t>(n) >= rules_.size()) rules_.resize(static_cast<std::size_t>(n) + 1);
    QuadRule& r = rules_[static_cast<std::size_t>(n)];
    if (r.x.empty()) r = GaussLegendre(n);
    return r;
  }
  double Integrate(const std::function<double(double)>& f, double a, double b, int n) {
    const QuadRule& r = Rule(n);
    double s = 0;
    for (std::size_t k = 0; k < r.x.size(); ++k) s += r.w[k] * f(a + (b - a) * r.x[k]);
    return s * (b - a);
  }
  // Bisects until the panel's rule integrates f to tol; halves get at least min_nodes nodes.
  void Refine(const std::function<double(double)>& f, const Panel& pn, double range, double tol, int depth,
              std::vector<Panel>* out) {
    if (depth < 30 && std::abs(Integrate(f, pn.a, pn.b, pn.n) - Integrate(f, pn.a, pn.b, 2 * pn.n)) > tol) {
      const double mid = 0.5 * (pn.a + pn.b);
      const int n = std::max(min_nodes_, Count(mid - pn.a, range));
      Refine(f, {pn.a, mid, n}, range, tol, depth + 1, out);
      Refine(f, {mid, pn.b, n}, range, tol, depth + 1, out);
    } else {
      out->push_back(pn);
    }
  }

  int per_range_, min_nodes_;
  std::vector<QuadRule> rules_;
};

}  // namespace

double Irawan2012Model::SpecularMean(int order) const { return SpecularMean(order, nullptr); }

double Irawan2012Model::SpecularMean(int order, long long* node_count) const {
  BTF_CHECK_OPTION(order >= 2 && order <= 64, "order", "must lie in [2, 64]");
  const WeavePattern& p = pattern_;
  const double W = p.tile_width, H = p.tile_height;
  const double NX = options_.repeat_u * W, NY = options_.repeat_v * H;  // cells covered by uv in [0, 1]^2
  const double norm = 1 / (NX * NY);

  // 1. Pieces: (part of) a cell in the local frame of its segment, with weight
  //    multiplicity * iv * areaFactor / cells, grouped into classes.
  std::vector<NormClass> classes;
  std::map<std::array<double, 8>, std::size_t> class_of;
  auto add_piece = [&](double X0, double X1, double Y0, double Y1, double mult) {
    const Local loc = LocateCell(0.5 * (X0 + X1), 0.5 * (Y0 + Y1));
    const WeaveYarn& y = p.yarns[static_cast<std::size_t>(loc.yarn)];
    const YarnCache& yc = cache_[static_cast<std::size_t>(loc.yarn)];
    const double umax = NoisyUmax(loc, y);
    if (yc.disabled || !(umax > 0) || y.width * std::sin(umax) >= y.length) return;  // no highlight
    const double weight = mult * IntensityVariation(loc) * yc.area_factor * norm;
    if (!(weight > 0)) return;
    NormPiece q{};
    q.weight = weight;
    const double cx = loc.center_x, cy = loc.center_y;
    if (y.type == WeaveYarn::Type::kWarp) {
      q.x0 = X0 - cx, q.x1 = X1 - cx, q.y0 = cy - Y1, q.y1 = cy - Y0;
    } else {  // rotated: (x, y) = (-y_l, x_l)
      q.x0 = Y0 - cy, q.x1 = Y1 - cy, q.y0 = X0 - cx, q.y1 = X1 - cx;
    }
    const std::array<double, 8> key{y.psi, umax, y.kappa, y.width, y.length, yc.alpha, yc.beta, yc.ss};
    auto [it, inserted] = class_of.try_emplace(key, classes.size());
    if (inserted) classes.push_back({y.psi, umax, y.kappa, y.width, y.length, yc.alpha, yc.beta, yc.ss, {}});
    classes[it->second].pieces.push_back(q);
  };
  if (!options_.noise) {
    // Tile-periodic: every cell of the tile with its number of full copies, plus the cut cells of
    // a fractional repeat (their local frame is that of tile 0).
    auto parts = [](int c, int n_tile, double n_cells) {
      std::vector<std::array<double, 3>> r;  // lo, hi, multiplicity
      const double full = std::floor(n_cells), frac = n_cells - full;
      if (c < full) r.push_back({double(c), double(c) + 1, std::floor((full - 1 - c) / n_tile) + 1});
      if (frac > 0 && std::fmod(full, n_tile) == c) r.push_back({double(c), c + frac, 1});
      return r;
    };
    for (int r = 0; r < p.tile_height; ++r)
      for (int c = 0; c < p.tile_width; ++c)
        for (const auto& xp : parts(c, p.tile_width, NX))
          for (const auto& yp : parts(r, p.tile_height, NY)) add_piece(xp[0], xp[1], yp[0], yp[1], xp[2] * yp[2]);
  } else {
    // Every cell is different (iv per 1/fineness cell, umax per segment): all cells, split at the
    // intensity-variation grid.
    const double f = p.fineness > 0 ? p.fineness : 0;
    const double cells_x = std::ceil(NX), cells_y = std::ceil(NY);
    const double per_cell = f > 0 ? (std::ceil(f) + 1) * (std::ceil(f) + 1) : 1;
    if (cells_x * cells_y * per_cell > 4e6)
      ThrowUsage("irawan2012: noise with repeat_u = {}, repeat_v = {} makes {:.3g} normalization pieces (limit 4e6); "
                 "lower the repeats or turn noise off",
                 options_.repeat_u, options_.repeat_v, cells_x * cells_y * per_cell);
    auto splits = [f](double lo, double hi) {
      std::vector<double> s{lo};
      if (f > 0)
        for (double k = std::floor(lo * f) + 1; k / f < hi; ++k) s.push_back(k / f);
      s.push_back(hi);
      return s;
    };
    for (double j = 0; j < cells_y; ++j)
      for (double i = 0; i < cells_x; ++i) {
        const auto xs = splits(i, std::min(i + 1, NX)), ys = splits(j, std::min(j + 1, NY));
        for (std::size_t a = 0; a + 1 < xs.size(); ++a)
          for (std::size_t b = 0; b + 1 < ys.size(); ++b) add_piece(xs[a], xs[a + 1], ys[b], ys[b + 1], 1);
      }
  }

  // 2. Outer nodes (u, v) of every class with their weights (quadrature * C * K * geometry).
  struct Node {
    double u, v, weight;
    std::size_t cls;
  };
  std::vector<Node> nodes;
  std::vector<PhiParams> phi_params;
  OuterRule outer((3 * order + 1) / 2, std::max(3, order / 4));
  std::vector<std::pair<double, double>> un, vn;
  const double hw = p.h_width;
  for (std::size_t ci = 0; ci < classes.size(); ++ci) {
    const NormClass& k = classes[ci];
    phi_params.push_back({k.alpha, k.beta, irawan2012::VonMisesNorm(k.beta), k.psi, k.psi != 0});
    const double w = k.w, l = k.l, a = 0.5 * w, umax = k.umax;
    if (k.psi == 0) {
      // Filament: u = u*, v = pi x / w; K(u, v) = sum_pieces weight * |band(u) ^ [y0, y1]| * [x in [x0, x1]].
      const double dy = l * hw, ums = (1 - k.ss) * umax, clamp = 0.5 * (l - dy), C = 2 * a * w * l / (kPi * kPi * dy);
      std::vector<double> ub{0, ums, -ums, umax * (l - dy) / l, -umax * (l - dy) / l}, vb{0, -kPi / 2, kPi / 2};
      double vlo = 1e300, vhi = -1e300;
      for (const NormPiece& q : k.pieces) {
        for (double e : {q.y0 - 0.5 * dy, q.y0 + 0.5 * dy, q.y1 - 0.5 * dy, q.y1 + 0.5 * dy})
          if (std::abs(e) <= clamp) ub.push_back(e * 2 * umax / l);
        vb.push_back(kPi * q.x0 / w);
        vb.push_back(kPi * q.x1 / w);
        vlo = std::min(vlo, kPi * q.x0 / w);
        vhi = std::max(vhi, kPi * q.x1 / w);
      }
      // Phi is even in u and in v (filament): fold the integral onto u, v >= 0.
      for (double& b : ub) b = std::abs(b);
      for (double& b : vb) b = std::abs(b);
      const double vmax = std::max(std::abs(vlo), std::abs(vhi));
      auto shape = [&](double u) {
        const double sm = k.ss > 0 ? 1 - SmoothStep01((u - ums) / (k.ss * umax)) : 1.0;
        return sm * (SpineRadius(std::min(u, ums), ums, k.kappa, w, l) + a);
      };
      outer.Nodes(Breakpoints(ub, 0, umax), 2 * umax, &un, shape);  // node density of the unfolded range
      outer.Nodes(Breakpoints(vb, 0, vmax), kPi, &vn);
      for (const auto& [u, wu] : un) {
        double sm = 1;
        if (k.ss > 0) sm = 1 - SmoothStep01((u - ums) / (k.ss * umax));
        const double R = SpineRadius(std::min(u, ums), ums, k.kappa, w, l);
        for (const auto& [v, wv] : vn) {
          double K = 0;
          for (double su : {-1.0, 1.0}) {
            const double ystar = std::clamp(su * u * 0.5 * l / umax, -clamp, clamp);
            for (double sv : {-1.0, 1.0}) {
              const double x = sv * v * w / kPi;
              for (const NormPiece& q : k.pieces)
                if (x > q.x0 && x < q.x1) K += q.weight * Overlap(q.y0, q.y1, ystar - 0.5 * dy, ystar + 0.5 * dy);
            }
          }
          const double weight = C * wu * wv * K * sm * (R + a * std::cos(v));
          if (weight != 0) nodes.push_back({u, v, weight, ci});
        }
      }
    } else {
      // Staple: u = 2 umax y / l, v = v*; K(u, v) = sum_pieces weight * [y in [y0, y1]] * |band(v) ^ [x0, x1]|.
      const double dx = w * hw, clamp = 0.5 * (w - dx), C = 2 * a * w * l / (kPi * kPi * dx);
      std::vector<double> ub{0}, vb{0, kPi * clamp / w, -kPi * clamp / w};
      double ulo = 1e300, uhi = -1e300;
      for (const NormPiece& q : k.pieces) {
        for (double e : {q.x0 - 0.5 * dx, q.x0 + 0.5 * dx, q.x1 - 0.5 * dx, q.x1 + 0.5 * dx})
          if (std::abs(e) <= clamp) vb.push_back(e * kPi / w);
        ub.push_back(2 * umax * q.y0 / l);
        ub.push_back(2 * umax * q.y1 / l);
        ulo = std::min(ulo, 2 * umax * q.y0 / l);
        uhi = std::max(uhi, 2 * umax * q.y1 / l);
      }
      outer.Nodes(Breakpoints(ub, ulo, uhi), 2 * umax, &un,
                  [&](double u) { return SpineRadius(std::abs(u), umax, k.kappa, w, l) + a; });
      const double tan_psi = std::tan(k.psi);
      for (const auto& [u, wu] : un) {
        const double yl = u * 0.5 * l / umax;
        const double R = SpineRadius(std::abs(u), umax, k.kappa, w, l);
        // Phi is not smooth where phi_z = 0 (z_b = 0) or z_t = 0: curves v(u), split there too.
        std::vector<double> vbu = vb;
        for (double sv : {-tan_psi * std::tan(u), std::tan(u) / tan_psi})
          if (std::abs(sv) < 1) vbu.push_back(std::asin(sv));
        outer.Nodes(Breakpoints(vbu, -kPi / 2, kPi / 2), kPi, &vn);
        for (const auto& [v, wv] : vn) {
          const double xstar = std::clamp(v * w / kPi, -clamp, clamp);
          double K = 0;
          for (const NormPiece& q : k.pieces)
            if (yl > q.y0 && yl < q.y1) K += q.weight * Overlap(q.x0, q.x1, xstar - 0.5 * dx, xstar + 0.5 * dx);
          const double weight = C * wu * wv * K * (R + a * std::cos(v));
          if (weight != 0) nodes.push_back({u, v, weight, ci});
        }
      }
    }
  }

  // 3. Phi at every node (in parallel), summed in a fixed order: the same result on any thread count.
  std::vector<double> phi(nodes.size());
  const auto count = static_cast<std::ptrdiff_t>(nodes.size());
#pragma omp parallel
  {
    DirectionIntegral inner(order);
#pragma omp for schedule(dynamic, 8)
    for (std::ptrdiff_t i = 0; i < count; ++i) {
      const Node& nd = nodes[static_cast<std::size_t>(i)];
      phi[static_cast<std::size_t>(i)] = inner(nd.u, nd.v, phi_params[nd.cls]);
    }
  }
  double mean = 0;
  for (std::size_t i = 0; i < nodes.size(); ++i) mean += nodes[i].weight * phi[i];
  if (node_count) *node_count = static_cast<long long>(nodes.size());
  return mean;
}

void Irawan2012Model::ComputeNormalization() {
  // N_spec = 1 / (pi E[g]) with wi, wo cosine-distributed and uv uniform, so that the specular
  // lobe's cosine-weighted, uv-averaged bihemispherical albedo equals k_s (as Mitsuba's).
  const int order = options_.nspec_order, lower = order - std::max(2, order / 4);
  const double mean = SpecularMean(order, &nspec_nodes_);
  if (!(mean > 0)) {  // every yarn disabled (e.g. velvet): no specular lobe to normalize
    nspec_ = 0;
    nspec_rel_err_ = 0;
    return;
  }
  nspec_ = 1 / (kPi * mean);
  const double mean_lower = SpecularMean(lower);
  nspec_rel_err_ = std::abs(mean / mean_lower - 1);  // |N(order) - N(lower)| / N(order)
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
