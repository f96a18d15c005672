#include "libbtf/synth/model.h"

#include <vector>

#include "libbtf/core/error.h"

namespace btf {

void SvbrdfModel::EvalBrdf(const Vec3& wi, const Vec3& wo, float* out) const {
  // Midpoints of a 128 x 128 grid: models without an analytic answer are piecewise smooth, and a
  // regular grid over one period converges like the boundary length / 128.
  constexpr int kGrid = 128;
  const int nc = channels();
  std::vector<Vec2> uv(kGrid);
  std::vector<float> vals(static_cast<std::size_t>(kGrid * nc));
  std::vector<double> acc(static_cast<std::size_t>(nc), 0.0);
  for (int j = 0; j < kGrid; ++j) {
    for (int i = 0; i < kGrid; ++i) uv[i] = Vec2((i + 0.5) / kGrid, (j + 0.5) / kGrid);
    EvalBatch(wi, wo, uv.data(), kGrid, vals.data());
    for (int i = 0; i < kGrid; ++i)
      for (int c = 0; c < nc; ++c) acc[c] += vals[static_cast<std::size_t>(i * nc + c)];
  }
  for (int c = 0; c < nc; ++c) out[c] = static_cast<float>(acc[c] / (kGrid * kGrid));
}

void SvbrdfModel::EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* uv, int n, float* out) const {
  const int nc = channels();
  for (int i = 0; i < n; ++i) Eval(uv[i], wi, wo, out + static_cast<std::ptrdiff_t>(i) * nc);
}

std::unique_ptr<SvbrdfModel> MakeModel(const std::string& model, const std::string& preset,
                                       const nlohmann::json& params) {
  if (model == "irawan2006") return MakeIrawan2006Model(preset, params);
  if (model == "irawan2012") return MakeIrawan2012Model(preset, params);
  if (model == "sadeghi2013") return MakeSadeghi2013Model(preset, params);
  ThrowUsage("unknown model '{}': use irawan2006, irawan2012 or sadeghi2013", model);
}

}  // namespace btf
