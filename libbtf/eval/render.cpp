#include "libbtf/eval/render.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <Eigen/Geometry>

#include "libbtf/core/error.h"
#include "libbtf/eval/annotate.h"

namespace btf {

namespace {

class DatasetBtfEvaluator final : public BtfEvaluator {
 public:
  explicit DatasetBtfEvaluator(const Dataset& d) : d_(d) {}
  int channels() const override { return d_.channels(); }
  bool cos_theta_i_included() const override { return d_.info().cos_theta_i_included; }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override {
    const double u = uv.x() - std::floor(uv.x()), v = uv.y() - std::floor(uv.y());
    const int x = std::min(int(u * d_.width()), d_.width() - 1);
    const int y = std::min(int((1.0 - v) * d_.height()), d_.height() - 1);
    const Interpolant iv = d_.views().Barycentric(wo), il = d_.lights().Barycentric(wi);
    const int C = d_.channels();
    // Per-thread scratch: Eval runs millions of times per render, so no allocation per call.
    thread_local std::vector<double> acc;
    acc.assign(std::size_t(C), 0.0);
    for (int a = 0; a < iv.count; ++a)
      for (int b = 0; b < il.count; ++b) {
        const double w = iv.weight[a] * il.weight[b];
        for (int c = 0; c < C; ++c) acc[c] += w * d_.at(iv.index[a], il.index[b], y, x, c);
      }
    for (int c = 0; c < C; ++c) out[c] = float(acc[c]);
  }

 private:
  const Dataset& d_;
};

class CodecBtfEvaluator final : public BtfEvaluator {
 public:
  explicit CodecBtfEvaluator(const Codec& c) : c_(c) {}
  int channels() const override { return c_.channels(); }
  bool cos_theta_i_included() const override { return c_.info().cos_theta_i_included; }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override {
    c_.Value(uv, wi, wo, out, UvFilter::kNearest);
  }

 private:
  const Codec& c_;
};

struct Hit {
  Vec3 p, n, tu, tv;  // position, normal, tangents along u and v (right-handed: tu x tv = n)
  Vec2 uv;
};

const Vec3 kCamera = RenderCamera{}.position;
const double kFovY = DegToRad(RenderCamera{}.fov_y_deg);

bool Intersect(const RenderOptions& o, const Vec3& origin, const Vec3& dir, Hit* hit) {
  if (o.scene == "patch") {
    if (std::abs(dir.z()) < 1e-12) return false;
    const double t = -origin.z() / dir.z();
    if (t <= 0) return false;
    const Vec3 p = origin + t * dir;
    if (std::abs(p.x()) > 1 || std::abs(p.y()) > 1) return false;
    hit->p = p;
    hit->n = Vec3(0, 0, 1);
    hit->tu = Vec3(1, 0, 0);
    hit->tv = Vec3(0, 1, 0);
    hit->uv = Vec2((p.x() + 1) / 2 * o.tiles, (p.y() + 1) / 2 * o.tiles);
    return true;
  }
  // Cylinder along the x axis, radius R: u runs along the axis, v around it (cloth draped over a bar).
  constexpr double R = kCylinderRadius;
  const double a = dir.y() * dir.y() + dir.z() * dir.z();
  const double b = 2 * (origin.y() * dir.y() + origin.z() * dir.z());
  const double c = origin.y() * origin.y() + origin.z() * origin.z() - R * R;
  const double disc = b * b - 4 * a * c;
  if (a < 1e-12 || disc < 0) return false;
  for (double t : {(-b - std::sqrt(disc)) / (2 * a), (-b + std::sqrt(disc)) / (2 * a)}) {
    if (t <= 0) continue;
    const Vec3 p = origin + t * dir;
    if (std::abs(p.x()) > 1) continue;
    const double phi = std::atan2(p.y(), p.z());  // 0 at the top, increasing towards +y
    hit->p = p;
    hit->n = Vec3(0, std::sin(phi), std::cos(phi));
    hit->tu = Vec3(1, 0, 0);
    hit->tv = Vec3(0, std::cos(phi), -std::sin(phi));
    const double circumference_tiles = o.tiles * (2 * kPi * R) / 2;  // same texel size as along the axis
    hit->uv = Vec2((p.x() + 1) / 2 * o.tiles, (phi / (2 * kPi) + 0.5) * circumference_tiles);
    return true;
  }
  return false;
}

Vec3 ToLocal(const Hit& h, const Vec3& w) { return Vec3(w.dot(h.tu), w.dot(h.tv), w.dot(h.n)); }

double Lobe(const Vec3& d, double theta_deg, double phi_deg, double power) {
  const double c = d.dot(DirectionFromAngles(DegToRad(theta_deg), DegToRad(phi_deg)));
  return c > 0 ? std::pow(c, power) : 0.0;
}

struct Camera {
  Vec3 forward, right, up;
  double tan_half, aspect;
  Camera(const RenderOptions& o)
      : forward((-kCamera).normalized()),
        right(forward.cross(Vec3(0, 0, 1)).normalized()),
        up(right.cross(forward)),
        tan_half(std::tan(kFovY / 2)),
        aspect(double(o.width) / o.height) {}
  Vec3 Ray(const RenderOptions& o, int px, int py) const {
    const double sx = (2 * (px + 0.5) / o.width - 1) * tan_half * aspect;
    const double sy = (1 - 2 * (py + 0.5) / o.height) * tan_half;
    return (forward + sx * right + sy * up).normalized();
  }
};

double Luminance(const Image& im, int x, int y) {
  return 0.2126 * im.at(x, y, 0) + 0.7152 * im.at(x, y, 1) + 0.0722 * im.at(x, y, 2);
}

}  // namespace

std::unique_ptr<BtfEvaluator> DatasetEvaluator(const Dataset& dataset) {
  if (dataset.num_views() < 1 || dataset.num_lights() < 1 || dataset.num_texels() < 1)
    ThrowBadInput("cannot render an empty dataset");
  return std::make_unique<DatasetBtfEvaluator>(dataset);
}

std::unique_ptr<BtfEvaluator> CodecEvaluator(const Codec& codec) { return std::make_unique<CodecBtfEvaluator>(codec); }

void RenderOptions::Check() const {
  BTF_CHECK_OPTION(scene == "patch" || scene == "cylinder", "scene", "must be patch or cylinder");
  BTF_CHECK_OPTION(lighting == "point" || lighting == "environment", "lighting", "must be point or environment");
  BTF_CHECK_OPTION(environment == "sky" || environment == "studio" || environment == "uniform", "environment",
                   "must be sky, studio or uniform");
  BTF_CHECK_OPTION(width >= 8 && height >= 8 && width <= 8192 && height <= 8192, "width/height", "must be 8..8192");
  BTF_CHECK_OPTION(std::isfinite(tiles) && tiles > 0 && tiles <= 1000, "tiles", "must be in (0, 1000]");
  BTF_CHECK_OPTION(light_position.allFinite(), "light_position", "must be finite");
  BTF_CHECK_OPTION(std::isfinite(light_intensity) && light_intensity >= 0, "light_intensity", "must be >= 0");
  BTF_CHECK_OPTION(environment_samples >= 8 && environment_samples <= 100000, "environment_samples", "must be 8..100000");
  BTF_CHECK_OPTION(std::isfinite(background) && background >= 0, "background", "must be >= 0");
}

namespace {

// Environment radiance (linear RGB) in world direction d (z up).
void EnvironmentRadiance(const std::string& environment, const Vec3& d, double* rgb) {
  if (environment == "uniform") {
    rgb[0] = rgb[1] = rgb[2] = 1.0;
    return;
  }
  if (environment == "studio") {
    // Dim gray room, a strong key light front-left and a weaker fill behind-right.
    const double key = 6.0 * Lobe(d, 40, -120, 24), fill = 2.0 * Lobe(d, 60, 60, 12);
    for (int k = 0; k < 3; ++k) rgb[k] = 0.05 + key + fill;
    return;
  }
  if (d.z() < 0) {  // ground
    rgb[0] = 0.12, rgb[1] = 0.10, rgb[2] = 0.08;
    return;
  }
  // Sky: warm horizon to blue zenith, plus a broad sun lobe.
  const double t = std::sqrt(d.z());
  const double horizon[3] = {1.0, 0.95, 0.85}, zenith[3] = {0.30, 0.50, 1.0};
  const double sun = 8.0 * Lobe(d, 50, -110, 16);
  for (int k = 0; k < 3; ++k) rgb[k] = horizon[k] + (zenith[k] - horizon[k]) * t + sun;
}

}  // namespace

std::vector<EnvironmentSample> EnvironmentSamples(const RenderOptions& o) {
  // Fibonacci sphere, equal solid angle each.
  std::vector<EnvironmentSample> samples;
  const double golden = kPi * (3 - std::sqrt(5.0)), d_omega = 4 * kPi / std::max(1, o.environment_samples);
  for (int i = 0; i < o.environment_samples; ++i) {
    const double z = 1 - (2 * i + 1.0) / o.environment_samples;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    EnvironmentSample e;
    e.direction = Vec3(r * std::cos(golden * i), r * std::sin(golden * i), z);
    EnvironmentRadiance(o.environment, e.direction, e.radiance_solid_angle);
    for (double& v : e.radiance_solid_angle) v *= d_omega;
    samples.push_back(e);
  }
  return samples;
}

SurfacePoint TracePixel(const RenderOptions& o, int px, int py) {
  o.Check();
  SurfacePoint sp;
  sp.camera = kCamera;
  Hit h;
  if (!Intersect(o, kCamera, Camera(o).Ray(o, px, py), &h)) return sp;
  sp.hit = true;
  sp.position = h.p, sp.normal = h.n, sp.tangent_u = h.tu, sp.tangent_v = h.tv, sp.uv = h.uv;
  return sp;
}

Image Render(const BtfEvaluator& btf, const RenderOptions& o) {
  o.Check();
  const std::vector<EnvironmentSample> env = o.lighting == "environment" ? EnvironmentSamples(o) : std::vector<EnvironmentSample>{};
  const Camera camera(o);
  const int C = btf.channels();
  Image img(o.width, o.height, 3);
#pragma omp parallel for schedule(dynamic)
  for (int py = 0; py < o.height; ++py) {
    std::vector<float> f(std::max(C, 3));
    for (int px = 0; px < o.width; ++px) {
      const Vec3 dir = camera.Ray(o, px, py);
      Hit h;
      double L[3] = {o.background, o.background, o.background};
      if (Intersect(o, kCamera, dir, &h)) {
        L[0] = L[1] = L[2] = 0;
        const Vec3 wo = ToLocal(h, (kCamera - h.p).normalized());
        auto add = [&](const Vec3& wi, const double* radiance, double scale) {
          if (wi.z() <= 0 || wo.z() <= 0) return;  // below the horizon: no light, no visibility test
          btf.Eval(h.uv, wi, wo, f.data());
          const double cosine = btf.cos_theta_i_included() ? 1.0 : wi.z();
          for (int k = 0; k < 3; ++k) L[k] += double(f[C >= 3 ? k : 0]) * cosine * radiance[k] * scale;
        };
        if (o.lighting == "point") {
          const Vec3 to_light = o.light_position - h.p;
          const double r2 = to_light.squaredNorm();
          const double radiance[3] = {o.light_intensity, o.light_intensity, o.light_intensity};
          if (r2 > 1e-12) add(ToLocal(h, to_light / std::sqrt(r2)), radiance, 1.0 / r2);
        } else {
          for (const EnvironmentSample& e : env) add(ToLocal(h, e.direction), e.radiance_solid_angle, 1.0);
        }
      }
      for (int k = 0; k < 3; ++k) img.at(px, py, k) = float(L[k]);
    }
  }
  return img;
}

Image ComparisonPanel(const Image& truth, const Image& test, const std::string& truth_label,
                      const std::string& test_label, double diff_full_scale, PanelStats* stats) {
  if (truth.width != test.width || truth.height != test.height || truth.channels < 3 || test.channels < 3)
    ThrowUsage("comparison panel: images must have the same size and 3 channels");
  const int W = truth.width, H = truth.height;
  std::vector<double> lum;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) lum.push_back(Luminance(truth, x, y));
  std::sort(lum.begin(), lum.end());
  const double level = std::max(lum[std::size_t(0.99 * (lum.size() - 1))], 1e-12);
  const double exposure = 0.8 / level;
  Image a(W, H, 3), b(W, H, 3);
  std::vector<float> rel(std::size_t(W) * H);
  double worst = 0, sum = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      for (int k = 0; k < 3; ++k) {
        a.at(x, y, k) = float(std::min(1.0, truth.at(x, y, k) * exposure));
        b.at(x, y, k) = float(std::min(1.0, test.at(x, y, k) * exposure));
      }
      const double r = std::abs(Luminance(test, x, y) - Luminance(truth, x, y)) / level;
      worst = std::max(worst, r);
      sum += r;
      rel[std::size_t(y) * W + x] = float(r);
    }
  const Image d = FalseColorImage(rel.data(), W, H, diff_full_scale);
  const int gap = 8, label_h = 22, text_size = 14;
  Image panel = Filled(3 * W + 4 * gap, H + label_h + gap, {1, 1, 1});
  const std::string labels[3] = {truth_label, test_label,
                                 fmt::format("|diff| 0..{:g}% (max {:.2g}%)", 100 * diff_full_scale, 100 * worst)};
  const Image* images[3] = {&a, &b, &d};
  for (int i = 0; i < 3; ++i) Paste(panel, *images[i], gap + i * (W + gap), label_h);
  // Labels on display values (anti-aliased as the font intends); none without a font.
  panel = ToDisplay(panel);
  bool labelled = true;
  for (int i = 0; i < 3; ++i) labelled &= DrawText(panel, gap + i * (W + gap), 4, labels[i], text_size, {0, 0, 0});
  if (stats) *stats = {worst, sum / (double(W) * H), labelled};
  return ToLinear(panel);
}

}  // namespace btf
