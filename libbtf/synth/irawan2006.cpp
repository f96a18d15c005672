#include "libbtf/synth/irawan2006.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "libbtf/core/error.h"

namespace btf {
namespace {

double Cross(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }
// Signed angle from p to q in (-pi, pi].
double Angle(const Vec2& p, const Vec2& q) { return std::atan2(Cross(p, q), p.dot(q)); }

// Signed area of unit disk ∩ triangle(O, a, b).
double TriangleDiskArea(const Vec2& a, const Vec2& b) {
  const Vec2 d = b - a;
  double t1, t2;
  if (!UnitCircleRoots(a, d, &t1, &t2) || t2 <= 0 || t1 >= 1) return 0.5 * Angle(a, b);  // pure sector
  const double s1 = std::max(t1, 0.0), s2 = std::min(t2, 1.0);
  const Vec2 p1 = a + s1 * d, p2 = a + s2 * d;
  double area = 0.5 * Cross(p1, p2);            // the chord part inside the disk
  if (s1 > 0) area += 0.5 * Angle(a, p1);       // sector before entering
  if (s2 < 1) area += 0.5 * Angle(p2, b);       // sector after leaving
  return area;
}

constexpr double kTwoPi = 2 * kPi;

}  // namespace

bool UnitCircleRoots(const Vec2& a, const Vec2& d, double* t1, double* t2) {
  const double A = d.squaredNorm();
  if (A <= 0) return false;
  const double B = a.dot(d);
  const double C = a.squaredNorm() - 1;
  const double disc = B * B - A * C;
  if (disc <= 0) return false;
  const double sq = std::sqrt(disc);
  // Stable quadratic: avoid subtracting nearly equal numbers.
  const double q = -(B + std::copysign(sq, B));
  double r1 = q / A, r2 = (q != 0) ? C / q : -r1;
  if (r1 > r2) std::swap(r1, r2);
  *t1 = r1;
  *t2 = r2;
  return true;
}

double CircularSegmentArea(double theta) {
  theta = std::clamp(theta, 0.0, kTwoPi);
  if (theta < 0.05) {
    // (theta - sin theta)/2 loses all digits for tiny theta; the series keeps them.
    const double t2 = theta * theta, t3 = t2 * theta;
    return t3 * (1.0 / 12 - t2 * (1.0 / 240 - t2 * (1.0 / 10080 - t2 / 725760)));
  }
  return 0.5 * (theta - std::sin(theta));
}

double DiskPolygonArea(const std::vector<Vec2>& poly) {
  double sum = 0;
  for (std::size_t k = 0; k < poly.size(); ++k) sum += TriangleDiskArea(poly[k], poly[(k + 1) % poly.size()]);
  return std::max(0.0, sum);
}

std::array<Vec2, 4> EllipseWindowInDisk(const EllipseSegment& s, double hx, double hy) {
  const double beta = s.alpha * std::sqrt((1 - s.eta) * (1 + s.eta));
  const double cx = 0.5 * s.sx * (s.kx * hx + 1), cy = 0.5 * s.sy * (s.ky * hy + 1);
  const double c = std::cos(s.phi), sn = std::sin(s.phi);
  // M^-1 for M = [a b | center], a = alpha (c, s), b = beta (-s, c): orthogonal axes, so the inverse
  // is a rotation followed by 1/alpha, 1/beta scaling; orientation (CCW) is kept.
  auto to_disk = [&](double x, double y) {
    const double px = x - cx, py = y - cy;
    return Vec2((c * px + sn * py) / s.alpha, (-sn * px + c * py) / beta);
  };
  return {to_disk(0, 0), to_disk(s.sx, 0), to_disk(s.sx, s.sy), to_disk(0, s.sy)};
}

double EllipseWindowArea(const EllipseSegment& s, double hx, double hy) {
  const double beta = s.alpha * std::sqrt((1 - s.eta) * (1 + s.eta));
  const std::array<Vec2, 4> quad = EllipseWindowInDisk(s, hx, hy);
  return s.alpha * beta * DiskPolygonArea({quad.begin(), quad.end()});
}

// ---- Parameters and presets ---------------------------------------------------------------------

void Irawan2006Params::Check() const {
  BTF_CHECK_OPTION(tile_w >= 1 && tile_w <= 64, "tile_w", "tile width in units");
  BTF_CHECK_OPTION(tile_h >= 1 && tile_h <= 64, "tile_h", "tile height in units");
  BTF_CHECK_OPTION(!segments.empty(), "segments", "at least one segment");
  BTF_CHECK_OPTION(fresnel == "dielectric" || fresnel == "none", "fresnel", "'dielectric' or 'none'");
  BTF_CHECK_OPTION(std::isfinite(ior) && ior > 1 && ior < 10, "ior", "refractive index in (1, 10)");
  BTF_CHECK_OPTION(std::isfinite(tile_mm) && tile_mm > 0, "tile_mm", "positive tile size");
  for (int c = 0; c < 3; ++c) {
    BTF_CHECK_OPTION(std::isfinite(kd[c]) && kd[c] >= 0, "kd", "finite, >= 0");
    BTF_CHECK_OPTION(std::isfinite(ks[c]) && ks[c] >= 0, "ks", "finite, >= 0");
  }
  std::vector<int> cover(static_cast<std::size_t>(tile_w * tile_h), 0);
  for (const auto& s : segments) {
    BTF_CHECK_OPTION(s.alpha > 0 && std::isfinite(s.alpha), "segments.alpha", "positive semi-major axis");
    BTF_CHECK_OPTION(s.eta >= 0 && s.eta < 1, "segments.eta", "eccentricity in [0, 1)");
    BTF_CHECK_OPTION(std::isfinite(s.phi) && std::isfinite(s.kx) && std::isfinite(s.ky), "segments.phi/kx/ky",
                     "finite");
    // Windows lie on the unit grid so that a point finds its segment by one table look-up.
    const bool integral = s.x0 == std::floor(s.x0) && s.y0 == std::floor(s.y0) && s.sx == std::floor(s.sx) &&
                          s.sy == std::floor(s.sy) && s.sx >= 1 && s.sy >= 1 && s.sx <= tile_w && s.sy <= tile_h;
    BTF_CHECK_OPTION(integral, "segments.window", "integer window position and size within the tile");
    for (int j = 0; j < s.sy; ++j)
      for (int i = 0; i < s.sx; ++i) {
        const int x = ((static_cast<int>(s.x0) + i) % tile_w + tile_w) % tile_w;
        const int y = ((static_cast<int>(s.y0) + j) % tile_h + tile_h) % tile_h;
        ++cover[static_cast<std::size_t>(y * tile_w + x)];
      }
  }
  for (int v : cover) BTF_CHECK_OPTION(v == 1, "segments", "windows must cover every unit cell exactly once");
}

namespace {
EllipseSegment Seg(const char* type, double x0, double y0, double sx, double sy, double alpha, double eta,
                   double phi_deg, double kx, double ky) {
  EllipseSegment s;
  s.type = type;
  s.x0 = x0, s.y0 = y0, s.sx = sx, s.sy = sy, s.alpha = alpha, s.eta = eta, s.phi = DegToRad(phi_deg);
  s.kx = kx, s.ky = ky;
  return s;
}
}  // namespace

Irawan2006Params Irawan2006Preset(const std::string& name) {
  Irawan2006Params p;
  p.preset = name;
  p.segments.clear();
  if (name == "twill") {
    // Report section 6 parameters; 3/1 twill layout (docs/btf-synth.md, "Irawan 2006"): column c
    // has its weft window on rows 2c, 2c+1 from the top and its warp window on the other six
    // (wrapping).
    p.tile_w = 4, p.tile_h = 8;
    for (int c = 0; c < 4; ++c) {
      const int weft_y0 = p.tile_h - 2 * c - 2;
      p.segments.push_back(Seg("warp", c, (weft_y0 + 2) % p.tile_h, 1, 6, 3.0, 0.995, 95, 1.5, 3.1));
      p.segments.push_back(Seg("weft", c, weft_y0, 1, 2, 1.0, 0.9, 80, 3.7, 1.6));
    }
    p.kd = {0.12 / kPi, 0.18 / kPi, 0.35 / kPi};
  } else if (name == "plain") {
    // Ours: 1 x 1 floats in a checkerboard; ellipses along their thread.
    p.tile_w = 2, p.tile_h = 2;
    p.segments = {Seg("warp", 0, 0, 1, 1, 0.45, 0.9, 90, 1.0, 2.0), Seg("warp", 1, 1, 1, 1, 0.45, 0.9, 90, 1.0, 2.0),
                  Seg("weft", 1, 0, 1, 1, 0.45, 0.9, 0, 2.0, 1.0), Seg("weft", 0, 1, 1, 1, 0.45, 0.9, 0, 2.0, 1.0)};
    p.kd = {0.35 / kPi, 0.30 / kPi, 0.22 / kPi};
  } else if (name == "sateen") {
    // Ours: 5-end weft-faced sateen, move 2: per row one 1x1 warp point and a 4x1 weft float.
    p.tile_w = 5, p.tile_h = 5;
    for (int r = 0; r < 5; ++r) {
      p.segments.push_back(Seg("warp", (2 * r) % 5, r, 1, 1, 0.42, 0.85, 90, 1.0, 2.0));
      p.segments.push_back(Seg("weft", (2 * r + 1) % 5, r, 4, 1, 1.85, 0.99, 0, 2.2, 1.2));
    }
    p.kd = {0.45 / kPi, 0.12 / kPi, 0.10 / kPi};
  } else {
    ThrowUsage("unknown irawan2006 preset '{}': use twill, plain or sateen", name);
  }
  return p;
}

namespace {
std::array<double, 3> Rgb(const nlohmann::json& j, const char* field) {
  if (j.is_number()) return {j.get<double>(), j.get<double>(), j.get<double>()};
  if (j.is_array() && j.size() == 3 && j[0].is_number() && j[1].is_number() && j[2].is_number())
    return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
  ThrowUsage("irawan2006 parameter '{}' must be a number or [r, g, b]", field);
}
double Num(const nlohmann::json& j, const std::string& field) {
  if (!j.is_number()) ThrowUsage("irawan2006 parameter '{}' must be a number", field);
  return j.get<double>();
}
}  // namespace

std::unique_ptr<SvbrdfModel> MakeIrawan2006Model(const std::string& preset, const nlohmann::json& params) {
  Irawan2006Params p = Irawan2006Preset(preset);
  if (!params.is_null()) {
    if (!params.is_object()) ThrowUsage("irawan2006 parameters must be a JSON object");
    for (const auto& [key, val] : params.items()) {
      if (key == "kd") p.kd = Rgb(val, "kd");
      else if (key == "ks") p.ks = Rgb(val, "ks");
      else if (key == "ior") p.ior = Num(val, key);
      else if (key == "tile_mm") p.tile_mm = Num(val, key);
      else if (key == "fresnel") {
        if (!val.is_string()) ThrowUsage("irawan2006 parameter 'fresnel' must be a string");
        p.fresnel = val.get<std::string>();
      } else if (key == "warp" || key == "weft") {
        if (!val.is_object()) ThrowUsage("irawan2006 parameter '{}' must be an object", key);
        for (auto& s : p.segments) {
          if (s.type != key) continue;
          for (const auto& [k2, v2] : val.items()) {
            const std::string f = key + "." + k2;
            if (k2 == "alpha") s.alpha = Num(v2, f);
            else if (k2 == "eta") s.eta = Num(v2, f);
            else if (k2 == "phi_deg") s.phi = DegToRad(Num(v2, f));
            else if (k2 == "kx") s.kx = Num(v2, f);
            else if (k2 == "ky") s.ky = Num(v2, f);
            else ThrowUsage("unknown irawan2006 parameter '{}' (use alpha, eta, phi_deg, kx, ky)", f);
          }
        }
      } else {
        ThrowUsage("unknown irawan2006 parameter '{}' (use kd, ks, ior, fresnel, tile_mm, warp, weft)", key);
      }
    }
  }
  return std::make_unique<Irawan2006Model>(std::move(p));
}

// ---- Model ----------------------------------------------------------------------------------------

struct Irawan2006Model::Pair {
  double spec = 0;  // F G / (cos_i cos_o)
  std::vector<Vec2> f1, f2;  // foci per segment, window-local units
};

Irawan2006Model::Irawan2006Model(Irawan2006Params p) : p_(std::move(p)) {
  p_.Check();
  cell_segment_.assign(static_cast<std::size_t>(p_.tile_w * p_.tile_h), -1);
  for (std::size_t k = 0; k < p_.segments.size(); ++k) {
    const auto& s = p_.segments[k];
    for (int j = 0; j < s.sy; ++j)
      for (int i = 0; i < s.sx; ++i) {
        const int x = ((static_cast<int>(s.x0) + i) % p_.tile_w + p_.tile_w) % p_.tile_w;
        const int y = ((static_cast<int>(s.y0) + j) % p_.tile_h + p_.tile_h) % p_.tile_h;
        cell_segment_[static_cast<std::size_t>(y * p_.tile_w + x)] = static_cast<int>(k);
      }
  }
}

double Irawan2006Model::SpecularFactor(const Vec3& wi_in, const Vec3& wo_in) const {
  if (!wi_in.allFinite() || !wo_in.allFinite()) return 0;
  const double ni = wi_in.norm(), no = wo_in.norm();
  if (!(ni > 0 && no > 0)) return 0;
  const Vec3 wi = wi_in / ni, wo = wo_in / no;
  const double ci = wi.z(), co = wo.z();
  if (ci <= 0 || co <= 0) return 0;
  const Vec3 sum = wi + wo;
  const double len = sum.norm();
  if (len < 1e-12) return 0;  // wi = -wo: half vector undefined
  const Vec3 h = sum / len;
  const double cd = std::clamp(wi.dot(h), 0.0, 1.0);
  const double nh = h.z();
  if (cd <= 0) return 0;
  const double G = std::min({1.0, 2 * nh * co / cd, 2 * nh * ci / cd});
  double F = 1;
  if (p_.fresnel == "dielectric") {
    const double g2 = p_.ior * p_.ior - 1 + cd * cd;
    const double g = std::sqrt(g2);
    const double a = (g - cd) / (g + cd);
    const double b = (cd * (g + cd) - 1) / (cd * (g - cd) + 1);
    F = 0.5 * a * a * (1 + b * b);
  }
  // Clamp the cosines so that a grazing pair stays finite in float (both grazing diverges).
  constexpr double kMinCos = 1e-6;
  return F * G / (std::max(ci, kMinCos) * std::max(co, kMinCos));
}

bool Irawan2006Model::PrepareDirs(const Vec3& wi, const Vec3& wo, Pair& pr) const {
  pr.spec = SpecularFactor(wi, wo);
  if (!(wi.allFinite() && wo.allFinite()) || wi.z() <= 0 || wo.z() <= 0) return false;
  const Vec3 h = HalfVector(wi.normalized(), wo.normalized());
  pr.f1.resize(p_.segments.size());
  pr.f2.resize(p_.segments.size());
  for (std::size_t k = 0; k < p_.segments.size(); ++k) {
    const auto& s = p_.segments[k];
    const Vec2 c(0.5 * s.sx * (s.kx * h.x() + 1), 0.5 * s.sy * (s.ky * h.y() + 1));
    const Vec2 off = s.alpha * s.eta * Vec2(std::cos(s.phi), std::sin(s.phi));
    pr.f1[k] = c + off;
    pr.f2[k] = c - off;
  }
  return true;
}

int Irawan2006Model::Locate(double X, double Y, double* lx, double* ly) const {
  const int W = p_.tile_w, H = p_.tile_h;
  int cx = static_cast<int>(std::floor(X)), cy = static_cast<int>(std::floor(Y));
  cx = std::clamp(cx, 0, W - 1);
  cy = std::clamp(cy, 0, H - 1);
  const int k = cell_segment_[static_cast<std::size_t>(cy * W + cx)];
  const auto& s = p_.segments[static_cast<std::size_t>(k)];
  double x = X - s.x0, y = Y - s.y0;
  if (x < 0) x += W;
  if (x >= W) x -= W;
  if (y < 0) y += H;
  if (y >= H) y -= H;
  *lx = x;
  *ly = y;
  return k;
}

void Irawan2006Model::EvalPrepared(const Pair& pr, const Vec2& uv, float* out) const {
  double u = uv.x() - std::floor(uv.x()), v = uv.y() - std::floor(uv.y());
  if (!std::isfinite(u)) u = 0;
  if (!std::isfinite(v)) v = 0;
  double lx, ly;
  const int k = Locate(u * p_.tile_w, v * p_.tile_h, &lx, &ly);
  const Vec2 p(lx, ly);
  const auto& s = p_.segments[static_cast<std::size_t>(k)];
  const bool lit = pr.spec > 0 && (p - pr.f1[k]).norm() + (p - pr.f2[k]).norm() <= 2 * s.alpha;
  for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(p_.kd[c] + (lit ? p_.ks[c] * pr.spec : 0.0));
}

void Irawan2006Model::Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const {
  // Single point: only the covering segment's ellipse is needed (no per-pair tables).
  const double spec = SpecularFactor(wi, wo);
  if (!(wi.allFinite() && wo.allFinite()) || wi.z() <= 0 || wo.z() <= 0) {
    std::fill(out, out + 3, 0.0f);
    return;
  }
  double u = uv.x() - std::floor(uv.x()), v = uv.y() - std::floor(uv.y());
  if (!std::isfinite(u)) u = 0;
  if (!std::isfinite(v)) v = 0;
  double lx, ly;
  const int k = Locate(u * p_.tile_w, v * p_.tile_h, &lx, &ly);
  const auto& s = p_.segments[static_cast<std::size_t>(k)];
  bool lit = false;
  if (spec > 0) {
    const Vec3 h = HalfVector(wi.normalized(), wo.normalized());
    const Vec2 c(0.5 * s.sx * (s.kx * h.x() + 1), 0.5 * s.sy * (s.ky * h.y() + 1));
    const Vec2 off = s.alpha * s.eta * Vec2(std::cos(s.phi), std::sin(s.phi));
    const Vec2 p(lx, ly);
    lit = (p - c - off).norm() + (p - c + off).norm() <= 2 * s.alpha;
  }
  for (int ch = 0; ch < 3; ++ch) out[ch] = static_cast<float>(p_.kd[ch] + (lit ? p_.ks[ch] * spec : 0.0));
}

void Irawan2006Model::EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* uv, int n, float* out) const {
  Pair pr;
  if (!PrepareDirs(wi, wo, pr)) {
    std::fill(out, out + 3 * n, 0.0f);
    return;
  }
  for (int i = 0; i < n; ++i) EvalPrepared(pr, uv[i], out + 3 * i);
}

double Irawan2006Model::HighlightFraction(const Vec3& wi, const Vec3& wo) const {
  if (!(wi.allFinite() && wo.allFinite()) || wi.z() <= 0 || wo.z() <= 0) return 0;
  const Vec3 h = HalfVector(wi.normalized(), wo.normalized());
  double area = 0;
  for (const auto& s : p_.segments) area += EllipseWindowArea(s, h.x(), h.y());
  return area / (p_.tile_w * p_.tile_h);
}

void Irawan2006Model::EvalBrdf(const Vec3& wi, const Vec3& wo, float* out) const {
  const double spec = SpecularFactor(wi, wo);
  if (!(wi.allFinite() && wo.allFinite()) || wi.z() <= 0 || wo.z() <= 0) {
    std::fill(out, out + 3, 0.0f);
    return;
  }
  const double frac = spec > 0 ? HighlightFraction(wi, wo) : 0.0;
  for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(p_.kd[c] + p_.ks[c] * frac * spec);
}

nlohmann::json Irawan2006Model::Describe() const {
  nlohmann::json segs = nlohmann::json::array();
  for (const auto& s : p_.segments) {
    const double beta = s.alpha * std::sqrt((1 - s.eta) * (1 + s.eta));
    const double c = std::cos(s.phi), sn = std::sin(s.phi);
    const double ext_x = 2 * std::sqrt(s.alpha * s.alpha * c * c + beta * beta * sn * sn);
    const double ext_y = 2 * std::sqrt(s.alpha * s.alpha * sn * sn + beta * beta * c * c);
    segs.push_back({{"type", s.type},
                    {"window", {s.x0, s.y0, s.sx, s.sy}},
                    {"alpha", s.alpha},
                    {"eta", s.eta},
                    {"phi_deg", RadToDeg(s.phi)},
                    {"k", {s.kx, s.ky}},
                    {"ellipse_fits_window", ext_x <= s.sx && ext_y <= s.sy}});
  }
  return {{"model", "irawan2006"},
          {"preset", p_.preset},
          {"tile_units", {p_.tile_w, p_.tile_h}},
          {"tile_mm", p_.tile_mm},
          {"kd", p_.kd},
          {"ks", p_.ks},
          {"fresnel", p_.fresnel},
          {"ior", p_.ior},
          {"G", "V-groove: min(1, 2(n.h)(n.wo)/(wo.h), 2(n.h)(n.wi)/(wo.h))"},
          {"frame", "all segment parameters and (h_x, h_y) in the global tile frame (x = weft/u, y = warp/v)"},
          {"units", "BRDF 1/sr without cos(theta_i); kd is a BRDF value (albedo/pi)"},
          {"segments", segs}};
}

}  // namespace btf
