#pragma once
// A small CPU renderer for looking at BTFs: a flat patch and a draped cylinder, textured with any
// BTF source, lit by a point light or by an environment (Sattler et al. 2003, section 5: the
// environment is integrated over a fixed set of sampled directions, without visibility).
#include <memory>
#include <string>
#include <vector>

#include "libbtf/compress/codec.h"
#include "libbtf/core/dataset.h"
#include "libbtf/core/directions.h"
#include "libbtf/io/image_io.h"

namespace btf {

// A BTF evaluated at any texture position and pair of directions: (uv, wi, wo) -> channels,
// directions in the local frame (z = normal, x = weft/u, y = warp/v), uv with period 1.
class BtfEvaluator {
 public:
  virtual ~BtfEvaluator() = default;
  virtual int channels() const = 0;
  // True when values already include cos(theta_i) (the renderer then does not multiply by it).
  virtual bool cos_theta_i_included() const { return false; }
  virtual void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const = 0;
};

// A dataset (which must outlive the evaluator): the nearest texel (uv wrapped to the tile, row 0 =
// v near 1 as in docs/conventions.md) and barycentric interpolation over the three nearest views x
// the three nearest lights (Sampling::Barycentric), 9 samples.
std::unique_ptr<BtfEvaluator> DatasetEvaluator(const Dataset& dataset);
// A codec's arbitrary-direction decoder (Codec::Value: barycentric over the three nearest views x
// lights, nearest texel so it matches DatasetEvaluator). The codec must outlive the evaluator.
std::unique_ptr<BtfEvaluator> CodecEvaluator(const Codec& codec);

struct RenderOptions {
  std::string scene = "patch";      // "patch" (a 2 x 2 flat square) or "cylinder" (radius 0.6, length 2)
  std::string lighting = "point";   // "point" or "environment"
  // "sky" (gradient + sun lobe), "studio" (key + fill lobes) or "uniform" (radiance 1 everywhere:
  // the white-furnace test, where a Lambertian BTF of albedo rho renders as rho).
  std::string environment = "sky";
  int width = 280, height = 224;    // pixels
  double tiles = 3;                 // texture repeats along each side of the patch / along the cylinder
  // Point light position (world: z up, camera at (0, -3.2, 2.6) looking at the origin) and its
  // radiant intensity; the default gives irradiance about 1 at normal incidence at the center.
  Vec3 light_position{1.2, -1.4, 2.6};
  double light_intensity = 10.2;
  int environment_samples = 128;    // fixed Fibonacci-sphere directions, 4 pi / N sr each
  double background = 0.02;         // radiance of pixels that miss the object
  void Check() const;
};

// The fixed camera of every scene (world: z up): position, the point it looks at, its up vector
// and vertical field of view; the cylinder's radius. A browser renderer uses the same numbers.
struct RenderCamera {
  Vec3 position{0, -3.2, 2.6}, target{0, 0, 0}, up{0, 0, 1};
  double fov_y_deg = 32;
};
inline constexpr double kCylinderRadius = 0.6;

// The environment's fixed sample set: Fibonacci-sphere directions (world) and radiance (linear
// RGB) times the solid angle 4 pi / N of each; Render sums BTF * cos * this over the samples.
struct EnvironmentSample {
  Vec3 direction;
  double radiance_solid_angle[3];
};
std::vector<EnvironmentSample> EnvironmentSamples(const RenderOptions& options);

// What pixel (px, py) sees: the surface point, its frame and texture coordinates (for tests).
struct SurfacePoint {
  bool hit = false;
  Vec3 position, normal, tangent_u, tangent_v;  // world; tangent_u x tangent_v = normal
  Vec2 uv;
  Vec3 camera;  // the camera position (world)
};
SurfacePoint TracePixel(const RenderOptions& options, int px, int py);

// Linear radiance image (3 channels; BTFs with 1 channel are shown gray, extra channels dropped).
Image Render(const BtfEvaluator& btf, const RenderOptions& options);

// Side-by-side panel: ground truth | test | difference, tone-mapped with one exposure (ground
// truth's 99th-percentile luminance -> 0.8) and labelled above each image (DrawText; without a
// font, see LabelFont, the panel has no text and `stats->labelled` is false). The difference is
// |test - truth| (luminance) relative to that same level, in the "viridis" map (FalseColorImage)
// from 0 to `diff_full_scale` (default 10 %). Returns a linear image to write with srgb = true;
// `stats` (if non-null) gets the largest and the mean relative difference over all pixels.
struct PanelStats {
  double max_rel_diff = 0, mean_rel_diff = 0;
  bool labelled = false;  // the labels were drawn
};
Image ComparisonPanel(const Image& truth, const Image& test, const std::string& truth_label,
                      const std::string& test_label, double diff_full_scale = 0.1, PanelStats* stats = nullptr);

}  // namespace btf
