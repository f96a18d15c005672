#pragma once
// Irawan & Marschner 2012 woven-cloth model, behaving as Mitsuba 0.6's `irawan` BSDF does for the
// same weave pattern and parameters (reference/irawan-models.md section 2; our own code).
//
// Differences from Mitsuba, all deliberate and documented in docs/btf-synth.md:
//  - Eval returns the BRDF f (1/sr) WITHOUT cos(theta_o); Mitsuba's eval returns f * cos(theta_o).
//  - double precision; cells are found with floor (Mitsuba truncates, defined only for uv >= 0).
//  - the spine radius uses a closed form valid for every branch (ellipse/circle/parabola/hyperbola).
//  - N_spec is computed with >= 1e6 padded-stratified samples of our own generator (Mitsuba: 1e4
//    SFMT samples), so values agree with Mitsuba's only up to Mitsuba's own Monte Carlo noise.
//  - randomness (umax noise, intensity variation) is off by default ("noise": false); when on it
//    uses our own hash and gradient noise, not Mitsuba's random sequence.
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/synth/model.h"
#include "libbtf/synth/weave_pattern.h"

namespace btf {
namespace irawan2012 {

// Radius of curvature of the yarn spine at inclination u (|u| <= umax), closed form for all
// branches (irawan-models.md 2.4, rewritten without tan(u)):
//   R = C * sqrt(cot^2(umax) + q) / (cos^2 u + q sin^2 u)^(3/2),
//   C = l/2 - (w/2) sin(umax), rhat = 1 + kappa (1 + cot umax), q = rhat |rhat|.
// Returns 0 where it is undefined (umax <= 0, C <= 0, or a hyperbola evaluated past its asymptote).
double SpineRadius(double u, double umax, double kappa, double w, double l);

// von Mises density on the circle, vM(c; b) = e^{b c} / (2 pi I0(|b|)), evaluated in scaled form
// (no overflow for large |b|). VonMisesNorm(b) = 1 / (2 pi e^{-|b|} I0(|b|)) is the cached part.
double VonMisesNorm(double b);
double VonMises(double cos_x, double b);

// Seeliger attenuation (1/4pi) c1 c2 / (c1 + c2) with c = max(0, cos); 0 if either is 0.
double Seeliger(double cos1, double cos2);

}  // namespace irawan2012

struct Irawan2012Options {
  double repeat_u = 1, repeat_v = 1;  // weave repeats per uv tile (Mitsuba's repeatU / repeatV)
  bool noise = false;                 // umax noise + intensity variation (off = ground truth)
  long long nspec_samples = 1 << 20;  // samples for N_spec (rounded up to a square n x n)
  double tile_mm = 4.0;               // physical size of one uv tile
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
  // (what Mitsuba accumulates for its normalisation). 0 below the horizon.
  double SpecularIntegrand(const Vec2& uv, const Vec3& wi, const Vec3& wo) const;
  // S_spec alone: the band value of irawan-models.md 2.3 (no iv, no area factor).
  double BandValue(const Vec2& uv, const Vec3& wi, const Vec3& wo) const;

  double specular_normalization() const { return nspec_; }
  double specular_normalization_rel_stderr() const { return nspec_rel_err_; }
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
    double x, y;         // position relative to the segment centre (cells), weft rotated
    double center_x, center_y;  // segment centre (cells, Mitsuba's flipped-Y frame)
    double cell_x, cell_y;      // unrotated position X, Y (cells)
  };
  Local Locate(const Vec2& uv) const;
  double Band(const Local& loc, Vec3 wi, Vec3 wo) const;
  // EvalRgb for unit directions above the surface.
  void EvalUnit(const Vec2& uv, const Vec3& wi, const Vec3& wo, double out[3]) const;
  double IntensityVariation(const Local& loc) const;
  double NoisyUmax(const Local& loc, const WeaveYarn& y) const;
  void ComputeNormalization();

  std::string preset_;
  WeavePattern pattern_;
  Irawan2012Options options_;
  std::vector<YarnCache> cache_;
  std::vector<int> disabled_;
  double nspec_ = 0, nspec_rel_err_ = 0;
  long long nspec_used_ = 0;
};

// Builds the model from a preset name (WeavePresetNames()) or a path to a `.wv` file, with
// overrides from `params` (docs/btf-synth.md). Throws btf::Error naming the bad field.
std::unique_ptr<Irawan2012Model> MakeIrawan2012(const std::string& preset, const nlohmann::json& params = {});

}  // namespace btf
