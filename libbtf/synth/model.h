#pragma once
// Ground-truth material models: a spatially varying BRDF over one periodic tile.
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "libbtf/core/directions.h"

namespace btf {

class SvbrdfModel {
 public:
  virtual ~SvbrdfModel() = default;
  virtual std::string name() const = 0;  // e.g. "irawan2006/twill"
  virtual int channels() const { return 3; }
  // BRDF value in 1/sr, WITHOUT the cos(theta_i) factor, at tile position uv (period 1 in u and
  // v; u along +x = weft, v along +y = warp), directions in the local frame (z = normal).
  // Must return finite values >= 0 for every input, 0 below the horizon.
  virtual void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const = 0;
  // Far-field BRDF (the tile average). Models with an analytic answer override this; the
  // default averages Eval over a stratified n x n grid of the tile.
  virtual void EvalBrdf(const Vec3& wi, const Vec3& wo, float* out) const;
  // Eval at n tile positions for one direction pair (out: n x channels). Models override this to
  // hoist per-pair work out of the loop; the default calls Eval n times.
  virtual void EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* uv, int n, float* out) const;
  // All parameters, for provenance and docs.
  virtual nlohmann::json Describe() const = 0;
  // Physical size of one tile in mm (photo synthesis places tiles on the plate with this).
  virtual double tile_size_mm() const { return 4.0; }
};

// Factories. `params` overrides preset fields (documented per model in docs/btf-synth.md);
// unknown preset names or bad parameters throw btf::Error (usage) naming the field.
std::unique_ptr<SvbrdfModel> MakeIrawan2006Model(const std::string& preset, const nlohmann::json& params = {});
std::unique_ptr<SvbrdfModel> MakeIrawan2012Model(const std::string& preset, const nlohmann::json& params = {});
std::unique_ptr<SvbrdfModel> MakeSadeghi2013Model(const std::string& preset, const nlohmann::json& params = {});
// model = "irawan2006" | "irawan2012" | "sadeghi2013".
std::unique_ptr<SvbrdfModel> MakeModel(const std::string& model, const std::string& preset,
                                       const nlohmann::json& params = {});

}  // namespace btf
