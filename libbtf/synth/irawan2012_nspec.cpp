// Irawan2012Model's specular normalization N_spec by deterministic quadrature (SpecularMean,
// ComputeNormalization); the model itself is in irawan2012.cpp.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/synth/irawan2012.h"

namespace btf {

using irawan2012::SmoothStep01;
using irawan2012::SpineRadius;

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

// An outer quadrature node (u, v) of class `cls`, with its weight (quadrature * C * K * geometry).
struct OuterNode {
  double u, v, weight;
  std::size_t cls;
};

// The outer nodes of filament class k (index ci; hw the band's half width fraction): u = u*,
// v = pi x / w; K(u, v) = sum_pieces weight * |band(u) ^ [y0, y1]| * [x in [x0, x1]].
void FilamentNodes(const NormClass& k, std::size_t ci, double hw, OuterRule& outer, std::vector<OuterNode>* nodes) {
  std::vector<std::pair<double, double>> un, vn;
  const double w = k.w, l = k.l, a = 0.5 * w, umax = k.umax;
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
      if (weight != 0) nodes->push_back({u, v, weight, ci});
    }
  }
}

// The outer nodes of staple class k: u = 2 umax y / l, v = v*; K(u, v) = sum_pieces weight *
// [y in [y0, y1]] * |band(v) ^ [x0, x1]|.
void StapleNodes(const NormClass& k, std::size_t ci, double hw, OuterRule& outer, std::vector<OuterNode>* nodes) {
  std::vector<std::pair<double, double>> un, vn;
  const double w = k.w, l = k.l, a = 0.5 * w, umax = k.umax;
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
      if (weight != 0) nodes->push_back({u, v, weight, ci});
    }
  }
}

// sum_nodes weight * Phi(u, v): Phi at every node in parallel (one DirectionIntegral of this
// order per thread), summed in a fixed order: the same result on any thread count.
double WeightedPhiSum(const std::vector<OuterNode>& nodes, const std::vector<PhiParams>& phi_params, int order) {
  std::vector<double> phi(nodes.size());
  const auto count = static_cast<std::ptrdiff_t>(nodes.size());
#pragma omp parallel
  {
    DirectionIntegral inner(order);
#pragma omp for schedule(dynamic, 8)
    for (std::ptrdiff_t i = 0; i < count; ++i) {
      const OuterNode& nd = nodes[static_cast<std::size_t>(i)];
      phi[static_cast<std::size_t>(i)] = inner(nd.u, nd.v, phi_params[nd.cls]);
    }
  }
  double mean = 0;
  for (std::size_t i = 0; i < nodes.size(); ++i) mean += nodes[i].weight * phi[i];
  return mean;
}

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

  // 2. Outer nodes (u, v) of every class with their weights.
  std::vector<OuterNode> nodes;
  std::vector<PhiParams> phi_params;
  OuterRule outer((3 * order + 1) / 2, std::max(3, order / 4));
  for (std::size_t ci = 0; ci < classes.size(); ++ci) {
    const NormClass& k = classes[ci];
    phi_params.push_back({k.alpha, k.beta, irawan2012::VonMisesNorm(k.beta), k.psi, k.psi != 0});
    if (k.psi == 0)
      FilamentNodes(k, ci, p.h_width, outer, &nodes);
    else
      StapleNodes(k, ci, p.h_width, outer, &nodes);
  }

  // 3. Phi at every node.
  const double mean = WeightedPhiSum(nodes, phi_params, order);
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

}  // namespace btf
