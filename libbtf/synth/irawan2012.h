#pragma once
// Irawan & Marschner 2012 woven-cloth model, behaving as Mitsuba 0.6's `irawan` BSDF does for the
// same weave pattern and parameters (docs/btf-synth.md, "Irawan 2012"; our own code).
//
// Differences from Mitsuba, all deliberate and documented in docs/btf-synth.md:
//  - Eval returns the BRDF f (1/sr) WITHOUT cos(theta_o); Mitsuba's eval returns f * cos(theta_o).
//  - double precision; cells are found with floor (Mitsuba truncates, defined only for uv >= 0).
//  - the spine radius uses a closed form valid for every branch (ellipse/circle/parabola/hyperbola).
//  - N_spec is computed by deterministic quadrature, relative error ~1e-6 or less (Mitsuba: 1e4 SFMT
//    samples), so values agree with Mitsuba's only up to Mitsuba's own Monte Carlo noise.
//  - randomness (umax noise, intensity variation) is off by default ("noise": false); when on it
//    uses our own hash and gradient noise, not Mitsuba's random sequence.
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/synth/model.h"
#include "libbtf/synth/weave_pattern.h"

namespace btf {
namespace irawan2012 {

// Radius of curvature of the yarn spine at inclination u (|u| <= umax), closed form for all
// branches (as Mitsuba 0.6's irawan plugin computes them, rewritten without tan(u)):
//   R = C * sqrt(cot^2(umax) + q) / (cos^2 u + q sin^2 u)^(3/2),
//   C = l/2 - (w/2) sin(umax), rhat = 1 + kappa (1 + cot umax), q = rhat |rhat|.
// Returns 0 where it is undefined (umax <= 0, C <= 0, or a hyperbola evaluated past its asymptote).
double SpineRadius(double u, double umax, double kappa, double w, double l);

// von Mises density on the circle, vM(c; b) = e^{b c} / (2 pi I0(|b|)), evaluated in scaled form
// (no overflow for large |b|). VonMisesNorm(b) = 1 / (2 pi e^{-|b|} I0(|b|)) is the cached part
// (irawan2012.cpp and irawan2012_nspec.cpp both cache it).
double VonMisesNorm(double b);
double VonMises(double cos_x, double b);
// 1 / (2 pi e^{-|b|} I0(|b|)): the part of VonMises that depends on b alone (cached per kernel).
double VonMisesNorm(double b);

// The smooth cutoff 3x^2 - 2x^3 of x clamped to [0, 1]: the highlight's fade towards umax, as the
// model evaluates it and N_spec's quadrature integrates it.
inline double SmoothStep01(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3 - 2 * x);
}

// Seeliger attenuation (1/4pi) c1 c2 / (c1 + c2) with c = max(0, cos); 0 if either is 0.
double Seeliger(double cos1, double cos2);

// Orthonormal frame of the fibre at yarn coordinates (u, v) (u along the yarn, v across) for twist
// psi, in the yarn's local frame (x across, y along, z = normal). With e_x = (1, 0, 0),
// e_n = (0, sin u, cos u) and e_t = (0, cos u, -sin u):
//   n = sin v e_x + cos v e_n                                   (yarn surface normal)
//   t = -sin psi cos v e_x + sin psi sin v e_n + cos psi e_t    (fibre tangent)
//   b = cos psi cos v e_x - cos psi sin v e_n + sin psi e_t     (completes the frame).
// N_spec's quadrature writes direction pairs in this frame (docs/btf-synth.md, "Normalization").
struct FibreFrame {
  Vec3 n, t, b;
};
FibreFrame MakeFibreFrame(double u, double v, double psi);

}  // namespace irawan2012

struct Irawan2012Options {
  double repeat_u = 1, repeat_v = 1;  // weave repeats per uv tile (Mitsuba's repeatU / repeatV)
  bool noise = false;                 // umax noise + intensity variation (off = ground truth)
  // Gauss-Legendre order of the N_spec quadrature, 4..64 (docs/btf-synth.md): 16 gives a relative
  // error of 1e-8 .. 1e-6 on the presets; the cost grows with order^5. The error estimate compares
  // with a lower order.
  int nspec_order = 16;
  double tile_mm = 4.0;               // physical size of one uv tile
  void Check() const;                 // throws btf::Error (usage) naming the bad field
};

class Irawan2012Model : public SvbrdfModel {
 public:
  Irawan2012Model(std::string preset_name, WeavePattern pattern, const Irawan2012Options& options);

  std::string name() const override { return "irawan2012/" + preset_; }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override;
  void EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* uv, int n, float* out) const override;
  nlohmann::json Describe() const override;
  double tile_size_mm() const override { return options_.tile_mm; }

  // Double-precision RGB value of Eval.
  void EvalRgb(const Vec2& uv, const Vec3& wi, const Vec3& wo, double out[3]) const;
  // g = iv * S_spec * (warpArea + weftArea) / area_type: the specular value before k_s and N_spec
  // (what Mitsuba accumulates for its normalization). 0 below the horizon.
  double SpecularIntegrand(const Vec2& uv, const Vec3& wi, const Vec3& wo) const;
  // S_spec alone: the band value of Mitsuba 0.6's irawan plugin (no iv, no area factor).
  double BandValue(const Vec2& uv, const Vec3& wi, const Vec3& wo) const;

  // N_spec = 1 / (pi E[g]) (docs/btf-synth.md), by deterministic quadrature of order
  // options().nspec_order; 0 when no yarn has a specular term.
  double specular_normalization() const { return nspec_; }
  // Error estimate of N_spec, relative: |N_spec(order) - N_spec(lower order)| / N_spec, the lower
  // order being order - max(2, order / 4). Conservative (the lower order's own error).
  double specular_normalization_rel_error() const { return nspec_rel_err_; }
  // E[g] by the quadrature at Gauss-Legendre order `order` (2..64): N_spec = 1 / (pi E[g]) at
  // order options().nspec_order; public so that tests can compare orders. Deterministic (the
  // same bits on any thread count).
  double SpecularMean(int order) const;
  // 1-based indices of the yarns whose specular term the reference guard w sin(umax) >= l zeroes.
  const std::vector<int>& disabled_yarns() const { return disabled_; }
  const WeavePattern& pattern() const { return pattern_; }
  const Irawan2012Options& options() const { return options_; }

  // 1-based yarn index at uv (after the repeat and the v flip).
  int YarnIndexAt(const Vec2& uv) const;

 private:
  struct YarnCache {
    double alpha, beta, ss, vm_norm, area_factor;
    bool disabled, staple;
  };
  struct Local {
    int yarn;            // 0-based
    double x, y;         // position relative to the segment center (cells), weft rotated
    double center_x, center_y;  // segment center (cells, Mitsuba's flipped-Y frame)
    double cell_x, cell_y;      // unrotated position X, Y (cells)
  };
  Local Locate(const Vec2& uv) const;
  Local LocateCell(double cell_x, double cell_y) const;  // from unrotated cell coordinates X, Y
  double Band(const Local& loc, Vec3 wi, Vec3 wo) const;
  // EvalRgb for unit directions above the surface.
  void EvalUnit(const Vec2& uv, const Vec3& wi, const Vec3& wo, double out[3]) const;
  double IntensityVariation(const Local& loc) const;
  double NoisyUmax(const Local& loc, const WeaveYarn& y) const;
  void ComputeNormalization();
  double SpecularMean(int order, long long* node_count) const;

  std::string preset_;
  WeavePattern pattern_;
  Irawan2012Options options_;
  std::vector<YarnCache> cache_;
  std::vector<int> disabled_;
  double nspec_ = 0, nspec_rel_err_ = 0;
  long long nspec_nodes_ = 0;  // outer quadrature nodes (u, v) of the order-nspec_order estimate
};

// Builds the model from a preset name (WeavePresetNames()) or a path to a `.wv` file, with
// overrides from `params` (docs/btf-synth.md). Throws btf::Error naming the bad field.
std::unique_ptr<Irawan2012Model> MakeIrawan2012(const std::string& preset, const nlohmann::json& params = {});

}  // namespace btf
