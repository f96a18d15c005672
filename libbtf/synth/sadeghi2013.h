#pragma once
// Sadeghi, Bisker, De Deken, Jensen 2013, "A Practical Microcylinder Appearance Model for Cloth
// Rendering" (ACM TOG 32(2)): thread scattering (section 4.3, Eqs. 2-4) over the tangent curves
// of two thread directions with masking and reweighting (section 5, Eqs. 5-15). A BRDF; as a
// BTF it is constant over the tile. Choices the paper leaves open are listed in docs/btf-synth.md.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/synth/model.h"

namespace btf {

struct SadeghiThread {
  std::string label;                // e.g. "flat", "twisted", "dir 1"
  bool along_v = true;              // true: runs along +y (warp, texture v); false: along +x (weft)
  std::array<double, 3> albedo{};   // A (linear RGB)
  double kd = 0;                    // isotropic volume-scattering fraction
  double gamma_s = 0, gamma_v = 0;  // surface / volume Gaussian widths (radians, standard deviation)
  double coverage = 0;              // a: area fraction of the smallest patch
  std::vector<double> offsets;      // tangent-curve control points (radians, tilt out of the plane)
  std::vector<double> lengths;      // lengths between consecutive control points (0 = a jump)
};

struct SadeghiParams {
  std::string name;
  double eta = 1.5;                 // refractive index of the fibres
  std::vector<SadeghiThread> threads;
  double masking_sigma = 0.3490658503988659;  // std of the unit-height Gaussian u in Eqs. 9, 13 (20 deg)
  double tangent_step = 0.008726646259971648;  // max tangent-angle step when sampling a curve (0.5 deg)
  double tile_mm = 4.0;
};

namespace sadeghi2013 {
// Unpolarised dielectric Fresnel reflectance for external incidence, cos_i in [0, 1].
double FresnelDielectric(double cos_i, double eta);
// Unit-area Gaussian of standard deviation `width` (radians), evaluated at x (radians).
double UnitGaussian(double width, double x);
// A sample of a tangent curve: tilt angle and weight (weights of one curve sum to 1).
struct TangentSample {
  double angle, weight;
};
std::vector<TangentSample> SampleTangentCurve(const std::vector<double>& offsets, const std::vector<double>& lengths,
                                              double max_step);
}  // namespace sadeghi2013

class Sadeghi2013Model : public SvbrdfModel {
 public:
  Sadeghi2013Model(std::string preset, SadeghiParams params);

  std::string name() const override { return "sadeghi2013/" + preset_; }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override;
  void EvalBrdf(const Vec3& wi, const Vec3& wo, float* out) const override;
  void EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* uv, int n, float* out) const override;
  nlohmann::json Describe() const override;
  double tile_size_mm() const override { return params_.tile_mm; }

  // Double-precision BRDF (1/sr, without cos theta_i); 0 below the horizon.
  void EvalRgb(const Vec3& wi, const Vec3& wo, double out[3]) const;
  const SadeghiParams& params() const { return params_; }

 private:
  struct TangentFrame {
    Vec3 t, n, b;  // tangent, its local normal, t x n
    double weight;
  };
  struct Sampled {
    std::vector<TangentFrame> frames;
  };
  static TangentFrame MakeFrame(bool along_v, double tilt, double weight);
  void Terms(const SadeghiThread& th, const TangentFrame& f, const Vec3& wi, const Vec3& wo, double* surface,
             double* volume, double* masking) const;
  std::string preset_;
  SadeghiParams params_;
  std::vector<Sampled> curves_;
  unsigned long long id_;  // distinguishes instances in Eval's per-thread cache
};

// Presets: Table II fabrics linen_plain, crepe_de_chine, charmeuse_front, charmeuse_back,
// silk_shot, velvet. Overrides in `params`: eta, masking_sigma_deg, tangent_step_deg, tile_mm.
std::unique_ptr<Sadeghi2013Model> MakeSadeghi2013(const std::string& preset, const nlohmann::json& params = {});
std::vector<std::string> Sadeghi2013PresetNames();

}  // namespace btf
