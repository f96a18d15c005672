// The WebGL2 viewer in headless Chromium (Debian's chromium, software WebGL2 through SwiftShader)
// against the CPU renderer, the C++ reference decoders and the codec's own decoder, on a small
// twill LPCA export, a pca-view export and a neural export of the same twill. Skips only when Chromium is absent (./run installs it, so CI runs these).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/export/neural.h"
#include "libbtf/export/neural_reference_decoder.h"
#include "libbtf/export/sattler.h"
#include "libbtf/export/sattler_reference_decoder.h"
#include "libbtf/export/schneider.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "libbtf/synth/btf_generator.h"
#include "libbtf/synth/model.h"
#include "libbtf/web/web.h"
#include "tests/codec_util.h"
#include "tests/synth_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// Irawan 2006 twill, bonn81 x bonn81, 16 x 16 texels (about 5 s), LPCA k = 4, c = 4; exported
// on the default 16^2 x 16^2 grid (u8) into one atlas page, in `dir`; the codec file too when
// `codec_file` is not empty.
const Dataset& Twill() {
  static const Dataset d = [] {
    const auto model = MakeModel("irawan2006", "twill", nlohmann::json::object());
    BtfOptions bo;
    bo.resolution = 16;
    bo.samples = 1;
    return test::GenerateDataset(*model, bo);
  }();
  return d;
}

void TwillExport(const std::filesystem::path& dir, const std::filesystem::path& codec_file = {},
                 const SchneiderExportOptions& options = {}) {
  static const Codec codec = [] {
    CompressOptions co;
    co.method = CodecMethod::kLpca;
    co.clusters = 4;
    co.components = 4;
    return test::CompressDataset(Twill(), co);
  }();
  ExportSchneider(options, codec, dir);
  if (!codec_file.empty()) WriteCodec(codec_file, codec);
}

// The same twill compressed with per-view PCA, c = 4 per view, exported in the sattler-2003
// layout (u8, 81 x 5 images of 16 x 16 on two 256 x 256 layers).
void TwillPcaViewExport(const std::filesystem::path& dir, const std::filesystem::path& codec_file = {},
                        const SattlerExportOptions& options = {}) {
  static const Codec codec = [] {
    CompressOptions co;
    co.method = CodecMethod::kPcaView;
    co.components = 4;
    return test::CompressDataset(Twill(), co);
  }();
  ExportSattler(options, codec, dir);
  if (!codec_file.empty()) WriteCodec(codec_file, codec);
}

// The same twill compressed with the neural codec: 8 latents (uint8 codes), decoder 14 -> 32 ->
// 32 -> 3 (SiLU), 400 steps of 1024 samples (about 2 s); exported in the neural-mlp layout.
const Codec& TwillNeuralCodec() {
  static const Codec codec = [] {
    CompressOptions co;
    co.method = CodecMethod::kNeural;
    co.seed = 7;
    co.neural.latent = 8;
    co.neural.samples = 1 << 16;
    co.neural.batch = 1024;
    co.neural.steps = 400;
    return test::CompressDataset(Twill(), co);
  }();
  return codec;
}
void TwillNeuralExport(const std::filesystem::path& dir, const std::filesystem::path& codec_file = {}) {
  ExportNeural(TwillNeuralCodec(), dir);
  if (!codec_file.empty()) WriteCodec(codec_file, TwillNeuralCodec());
}

using Exporter = void (*)(const std::filesystem::path&, const std::filesystem::path&);
void Lpca(const std::filesystem::path& dir, const std::filesystem::path& codec) { TwillExport(dir, codec); }
void PcaView(const std::filesystem::path& dir, const std::filesystem::path& codec) { TwillPcaViewExport(dir, codec); }
void Neural(const std::filesystem::path& dir, const std::filesystem::path& codec) { TwillNeuralExport(dir, codec); }
const char* ExporterName(Exporter e) { return e == PcaView ? " pca-view" : e == Neural ? " neural" : " lpca"; }

#define SKIP_WITHOUT_CHROMIUM()                                                                       \
  do {                                                                                                \
    if (!ChromiumAvailable(BrowserOptions{}))                                                         \
      GTEST_SKIP() << "Chromium is not installed at " << BrowserOptions{}.chromium << " (./run installs it)"; \
  } while (0)

double Luminance(const Image& im, int x, int y) {
  return 0.2126 * im.at(x, y, 0) + 0.7152 * im.at(x, y, 1) + 0.0722 * im.at(x, y, 2);
}

struct Agreement {
  double level = 0, mean_abs = 0, max_abs_inside = 0;
  int inside = 0, silhouette = 0, texel_edge = 0, filtered = 0;
  double worst_edge_distance = 0;  // texel-edge distance of the worst pixel inside (diagnostics)
};

// Distance (in texels) of the pixel's texture position from the nearest texel boundary.
double TexelEdgeDistance(const Vec2& uv, int width, int height) {
  double d = 1;
  for (double t : {uv.x() * width, uv.y() * height}) {
    const double f = t - std::floor(t);
    d = std::min({d, f, 1 - f});
  }
  return d;
}

// Both PNGs decoded to linear; |difference| per channel. Silhouette pixels: those whose 3 x 3
// neighbourhood has both hits and misses of the analytic shape (TracePixel), where the browser's
// rasterised proxy and the CPU's ray disagree by construction.
// Texel-edge pixels: the texture position within kTexelEdge texels of a texel boundary, where the
// nearest-texel lookup flips between float32 (browser) and double (CPU) arithmetic.
constexpr double kTexelEdge = 1e-4;

// Filtered pixels: the footprint (|uv(x + 1) - uv(x)| or |uv(y + 1) - uv(y)| times the texture's
// side) above kFilteredFootprint texels, where the viewer may average taps over the footprint
// (its own footprint comes from ray differentials, so a margin below 1) and the CPU takes one
// nearest texel: near the cylinder's silhouette and where many tiles are far away.
constexpr double kFilteredFootprint = 0.9;

Agreement Compare(const RenderOptions& scene, const Image& cpu, const Image& web, int tex_w, int tex_h) {
  Agreement a;
  std::vector<double> lum;
  for (int y = 0; y < cpu.height; ++y)
    for (int x = 0; x < cpu.width; ++x) lum.push_back(Luminance(cpu, x, y));
  std::sort(lum.begin(), lum.end());
  a.level = lum[std::size_t(0.99 * (lum.size() - 1))];
  std::vector<char> hit(std::size_t(cpu.width) * cpu.height);
  std::vector<double> edge_distance(hit.size(), 1.0), footprint(hit.size(), 0.0);
  for (int y = 0; y < cpu.height; ++y)
    for (int x = 0; x < cpu.width; ++x) {
      const SurfacePoint sp = TracePixel(scene, x, y);
      hit[std::size_t(y) * cpu.width + x] = sp.hit;
      if (!sp.hit) continue;
      edge_distance[std::size_t(y) * cpu.width + x] = TexelEdgeDistance(sp.uv, tex_w, tex_h);
      for (const SurfacePoint& q : {TracePixel(scene, x + 1, y), TracePixel(scene, x, y + 1)})
        if (q.hit) footprint[std::size_t(y) * cpu.width + x] = std::max(footprint[std::size_t(y) * cpu.width + x], (q.uv - sp.uv).norm() * std::max(tex_w, tex_h));
    }
  double sum = 0;
  for (int y = 0; y < cpu.height; ++y)
    for (int x = 0; x < cpu.width; ++x) {
      bool any = false, all = true;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = std::clamp(x + dx, 0, cpu.width - 1), yy = std::clamp(y + dy, 0, cpu.height - 1);
          any |= bool(hit[std::size_t(yy) * cpu.width + xx]), all &= bool(hit[std::size_t(yy) * cpu.width + xx]);
        }
      const bool silhouette = any && !all, texel_edge = edge_distance[std::size_t(y) * cpu.width + x] < kTexelEdge;
      const bool filtered = !silhouette && !texel_edge && footprint[std::size_t(y) * cpu.width + x] > kFilteredFootprint;
      a.silhouette += silhouette;
      a.texel_edge += !silhouette && texel_edge;
      a.filtered += filtered;
      a.inside += !silhouette && !texel_edge && !filtered;
      for (int c = 0; c < 3; ++c) {
        const double d = std::abs(double(web.at(x, y, c)) - cpu.at(x, y, c));
        sum += d;
        if (!silhouette && !texel_edge && !filtered && d > a.max_abs_inside) {
          a.max_abs_inside = d;
          a.worst_edge_distance = edge_distance[std::size_t(y) * cpu.width + x];
        }
      }
    }
  a.mean_abs = sum / (3.0 * cpu.width * cpu.height);
  return a;
}

// render-web against the CPU render of the same export (SchneiderReferenceDecoder through
// ExportEvaluator): same camera, light, exposure and tone mapping, both 8-bit sRGB PNGs.
// Tolerances: mean |diff| <= 1 % of the CPU image's 99th-percentile luminance, and
// no pixel off by more than 5 % of it away from silhouettes. What may differ: float32 against
// double arithmetic (the ray, uv and the concentric map), GPU trilinear filtering, 8-bit sRGB
// rounding (half a step of 1/255 in display values: <= 0.5 % of the level at the level).
// With cpu_of_codec, the CPU renders the codec itself (Codec::Value, barycentric over the sampled
// directions) instead of the export: then the export's resampling onto the 16^2 x 16^2 grid (a
// trilinear interpolant of the barycentric one) and its 8-bit storage are inside the difference
// too. Measured on this twill: mean 0.95 % (patch-point) and 0.47 % (cylinder-env) of the level,
// largest pixel 15 % and 14 % (at highlights, where the two interpolants differ most); the
// bounds are 2x those (max_mean, max_pixel).
void ExpectSceneAgrees(const std::string& name, bool cpu_of_codec = false, double max_mean = 0.01, double max_pixel = 0.05,
                       Exporter exporter = Lpca, int width = 280, int height = 224, double tiles = 3) {
  SKIP_WITHOUT_CHROMIUM();
  const auto tmp = test::TempDir(), dir = tmp / "export", codec_file = tmp / "codec.h5";
  exporter(dir, codec_file);
  const std::filesystem::path cpu_source = cpu_of_codec ? codec_file : dir;
  RenderOptions scene = WebSceneOptions(name, width, height);
  scene.tiles = tiles;
  // Exposure: the CPU image's 99th-percentile luminance at display value 0.8 (as ComparisonPanel).
  Image linear;
  RenderCpu(cpu_source, scene, 1.0, tmp / "probe.png", name, &linear);
  std::vector<double> lum;
  for (int y = 0; y < linear.height; ++y)
    for (int x = 0; x < linear.width; ++x) lum.push_back(Luminance(linear, x, y));
  std::sort(lum.begin(), lum.end());
  const double exposure = 0.8 / lum[std::size_t(0.99 * (lum.size() - 1))];
  RenderCpu(cpu_source, scene, exposure, tmp / "cpu.png", name);
  const WebRenderSummary s = RenderWeb(BrowserOptions{}, scene, exposure, dir, tmp / "web.png", name);
  EXPECT_NE(s.renderer.find("SwiftShader"), std::string::npos) << s.renderer;
  const Image cpu = ReadImage(tmp / "cpu.png"), web = ReadImage(tmp / "web.png");
  ASSERT_EQ(web.width, width);
  ASSERT_EQ(web.height, height);
  const Agreement a = Compare(scene, cpu, web, Twill().width(), Twill().height());
  std::cout << name << ExporterName(exporter) << (tiles != 3 ? " tiles " + std::to_string(tiles) : "") << (cpu_of_codec ? " (CPU: codec)" : " (CPU: export)") << ": level " << a.level << ", mean |diff| " << 100 * a.mean_abs / a.level << " %, max inside "
            << 100 * a.max_abs_inside / a.level << " % over " << a.inside << " pixels (left out: " << a.silhouette
            << " silhouette, " << a.texel_edge << " texel-edge, " << a.filtered << " filtered pixels; worst pixel " << a.worst_edge_distance
            << " texel from an edge), " << s.seconds << " s in the browser\n";
  EXPECT_GT(a.level, 0.5);  // the picture is not black (exposure maps the level to about 0.8)
  EXPECT_LE(a.mean_abs, max_mean * a.level);
  EXPECT_LE(a.max_abs_inside, max_pixel * a.level);
  EXPECT_GT(a.inside, width * height / 2);
  EXPECT_LT(a.texel_edge, width * height / 1000);  // the texel-edge exclusion stays small (< 0.1 % of the pixels)
  EXPECT_LT(a.filtered, width * height / 20);      // and the filtered pixels' (< 5 %: 4.4 % for the cylinder at 140 x 112)
}

TEST(Browser, PatchPointAgreesWithTheCpuRender) { ExpectSceneAgrees("patch-point"); }
TEST(Browser, CylinderEnvAgreesWithTheCpuRender) { ExpectSceneAgrees("cylinder-env"); }
TEST(Browser, PatchPointOfTheExportIsCloseToTheCpuRenderOfTheCodec) { ExpectSceneAgrees("patch-point", true, 0.02, 0.30); }
TEST(Browser, CylinderEnvOfTheExportIsCloseToTheCpuRenderOfTheCodec) { ExpectSceneAgrees("cylinder-env", true, 0.01, 0.30); }
// The pca-view export (sattler-2003, btf_sattler.glsl) under the same tolerances; the sky at
// 140 x 112 (its 128 lights x 2 x 81 direction dot products per pixel take 33 s in SwiftShader
// at 280 x 224).
TEST(Browser, PcaViewPatchPointAgreesWithTheCpuRender) { ExpectSceneAgrees("patch-point", false, 0.01, 0.05, PcaView); }
TEST(Browser, PcaViewCylinderEnvAgreesWithTheCpuRender) {
  ExpectSceneAgrees("cylinder-env", false, 0.01, 0.05, PcaView, 140, 112);
}

// btf_schneider.glsl evaluated in the browser (a float render target) against the reference
// decoder. Queries: every texel at grid nodes of the view and light squares (where trilinear
// filtering is exact), and random (uv, wi, wo) anywhere on the hemispheres.
// Queries (uv, wi, wo) for EvaluateInBrowser, 8 floats each, with the texel each is meant for.
struct Queries {
  std::vector<float> q;
  std::vector<int> x, y;
  void Add(int tx, int ty, const Vec2& uv, const Vec3& wi, const Vec3& wo) {
    for (double v : {uv.x(), uv.y(), wi.x(), wi.y(), wi.z(), wo.x(), wo.y(), wo.z()}) q.push_back(float(v));
    x.push_back(tx), y.push_back(ty);
  }
  // `count` random texels, uv jittered inside the texel's central half, directions uniform over
  // the square that HemisphereFromSquare maps.
  void AddRandom(int W, int H, int count, std::mt19937& rng) {
    std::uniform_real_distribution<double> u01(0, 1);
    for (int i = 0; i < count; ++i) {
      const int tx = int(u01(rng) * W) % W, ty = int(u01(rng) * H) % H;
      Add(tx, ty, Vec2((tx + 0.25 + 0.5 * u01(rng)) / W, 1 - (ty + 0.25 + 0.5 * u01(rng)) / H),
          HemisphereFromSquare(Vec2(u01(rng), u01(rng))), HemisphereFromSquare(Vec2(u01(rng), u01(rng))));
    }
  }
  std::size_t size() const { return x.size(); }
  Vec3 wi(std::size_t i) const { return Vec3(q[i * 8 + 2], q[i * 8 + 3], q[i * 8 + 4]); }
  Vec3 wo(std::size_t i) const { return Vec3(q[i * 8 + 5], q[i * 8 + 6], q[i * 8 + 7]); }
};

void ExpectGlslMatchesTheReferenceDecoder(const SchneiderExportOptions& options, int expected_pages) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  TwillExport(dir, {}, options);
  const SchneiderReferenceDecoder ref(dir);
  std::ifstream in(dir / "manifest.json");
  ASSERT_EQ(nlohmann::json::parse(in)["atlas"]["pages"], expected_pages);
  Queries qs;
  const int W = ref.width(), H = ref.height(), n = options.view_grid, m = options.light_grid;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int i = 0; i < 4; ++i) {
        const int sv = (x * 5 + i * 3) % n, tv = (y * 3 + i * 7) % n, sl = (x + y + i * 5) % m, tl = (x * 7 + i) % m;
        qs.Add(x, y, Vec2((x + 0.5) / W, 1 - (y + 0.5) / H), HemisphereFromSquare(Vec2(GridCoordinate(sl, m), GridCoordinate(tl, m))),
               HemisphereFromSquare(Vec2(GridCoordinate(sv, n), GridCoordinate(tv, n))));
      }
  const std::size_t grid_queries = qs.size();
  std::mt19937 rng(17);
  qs.AddRandom(W, H, 2048, rng);
  std::string renderer;
  const std::vector<float> got = EvaluateInBrowser(BrowserOptions{}, dir, qs.q, &renderer);
  ASSERT_EQ(got.size(), qs.size() * 3);
  double worst_grid = 0, worst_any = 0;
  for (std::size_t i = 0; i < qs.size(); ++i) {
    float want[3];
    ref.Value(qs.x[i], qs.y[i], qs.wi(i), qs.wo(i), want);
    // Scale of a value's possible error: sum_f |terms[1 + f]| (each t_f in [0, 1]).
    double scale = 0;
    for (int f = 0; f < ref.functions(); ++f) scale += std::abs(ref.terms(qs.y[i], qs.x[i])[1 + f]);
    for (int c = 0; c < 3; ++c) {
      const double r = std::abs(double(got[i * 3 + c]) - want[c]) / scale;
      (i < grid_queries ? worst_grid : worst_any) = std::max(i < grid_queries ? worst_grid : worst_any, r);
    }
  }
  std::cout << "GLSL vs reference decoder (" << options.storage << ", " << expected_pages << " page(s); " << renderer << "): worst |diff| / sum|w| = " << worst_grid << " at grid nodes, "
            << worst_any << " at random points; the storage bound per t is " << ref.quantization_bound() << "\n";
  // At grid nodes only float32 arithmetic differs (the filter weights are 0 or 1): well below the
  // storage quantisation (1/510), so the GLSL reproduces the decoder to the quantisation bound.
  EXPECT_LE(worst_grid, 0.1 * ref.quantization_bound());
  // Anywhere: SwiftShader filters with float32 weights (measured 1.6e-6); the same bound as at
  // the grid nodes keeps the GLSL within a tenth of the quantisation bound everywhere. (Hardware
  // that rounds filter weights to 8 bits could differ by up to 3/256 for t in [0, 1].)
  EXPECT_LE(worst_any, 0.1 * ref.quantization_bound());
}

TEST(Browser, GlslMatchesTheReferenceDecoder) { ExpectGlslMatchesTheReferenceDecoder({}, 1); }

// Half floats (RGBA16F upload) and an atlas of two pages (btf_atlas1): 4 x 4 tiles of 16^2 per
// 64-texel page side, 20 functions; light grid 8 for depth 64.
TEST(Browser, GlslMatchesTheReferenceDecoderWithHalfFloatsOnTwoPages) {
  SchneiderExportOptions o;
  o.storage = "f16";
  o.atlas_side = 64;
  o.light_grid = 8;
  ExpectGlslMatchesTheReferenceDecoder(o, 2);
}

// btf_sattler.glsl in the browser against SattlerReferenceDecoder at random (uv, wi, wo) and at
// the sampled directions themselves (where one view and one light carry all the weight).
// Error scale of a query: sum_a bv_a sum_f |sum_b bl_b terms[1 + f]| (ErrorBound / per_t). The
// two differ by float32 against double arithmetic only, except where float32 and double pick
// different "three nearest" directions (dot products tied to within float precision); those
// queries are counted and asserted rare.
void ExpectSattlerGlslMatchesTheReferenceDecoder(const SattlerExportOptions& options) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  TwillPcaViewExport(dir, {}, options);
  const SattlerReferenceDecoder ref(dir);
  const Dataset& d = Twill();
  Queries qs;
  const int W = ref.width(), H = ref.height();
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u01(0, 1);
  for (int i = 0; i < 1024; ++i) {
    const int x = int(u01(rng) * W) % W, y = int(u01(rng) * H) % H;
    qs.Add(x, y, Vec2((x + 0.5) / W, 1 - (y + 0.5) / H), d.lights()[int(u01(rng) * d.num_lights()) % d.num_lights()],
           d.views()[int(u01(rng) * d.num_views()) % d.num_views()]);
  }
  const std::size_t sampled_queries = qs.size();
  qs.AddRandom(W, H, 2048, rng);
  std::string renderer;
  const std::vector<float> got = EvaluateInBrowser(BrowserOptions{}, dir, qs.q, &renderer);
  ASSERT_EQ(got.size(), qs.size() * 3);
  double worst_sampled = 0, worst_any = 0;
  int off = 0;
  for (std::size_t i = 0; i < qs.size(); ++i) {
    float want[3];
    ref.Value(qs.x[i], qs.y[i], qs.wi(i), qs.wo(i), want);
    const double scale = ref.ErrorBound(qs.wi(i), qs.wo(i)) / ref.quantization_bound();
    double r = 0;
    for (int c = 0; c < 3; ++c) r = std::max(r, std::abs(double(got[i * 3 + c]) - want[c]) / scale);
    if (r > 0.1 * ref.quantization_bound()) {
      ++off;
      continue;
    }
    (i < sampled_queries ? worst_sampled : worst_any) = std::max(i < sampled_queries ? worst_sampled : worst_any, r);
  }
  std::cout << "sattler GLSL vs reference decoder (" << options.storage << "; " << renderer
            << "): worst |diff| / scale = " << worst_sampled << " at sampled directions, " << worst_any
            << " at random points; " << off << " of " << qs.size()
            << " queries beyond a tenth of the storage bound per t " << ref.quantization_bound() << "\n";
  EXPECT_LE(worst_sampled, 0.1 * ref.quantization_bound());
  EXPECT_LE(worst_any, 0.1 * ref.quantization_bound());
  EXPECT_LE(off, int(qs.size() / 200));  // nearest-three ties: at most 0.5 % of the queries
}

TEST(Browser, SattlerGlslMatchesTheReferenceDecoder) { ExpectSattlerGlslMatchesTheReferenceDecoder({}); }

// Half floats (RGBA16F upload) on a 128-texel layer side: 64 images per layer, 7 layers.
TEST(Browser, SattlerGlslMatchesTheReferenceDecoderWithHalfFloats) {
  SattlerExportOptions o;
  o.storage = "f16";
  o.atlas_side = 128;
  ExpectSattlerGlslMatchesTheReferenceDecoder(o);
}

// btf_neural.glsl in the browser (float32, SwiftShader) against NeuralReferenceDecoder (double)
// and against the codec's own CPU decoder (Codec::Value with nearest texel, float32 Eigen), at
// 1024 queries at sampled (view, light) pairs and 2048 random (uv, wi, wo) over the whole
// hemispheres. Error measure: |got - want| / (|want| + epsilon), the size of the difference of
// the decoder outputs y = log(value + epsilon) (value = exp(y) - epsilon, so dv = (v + eps) dy).
// Both sides evaluate the same latents and weights; what differs is float32 against double (or
// against Eigen's float32 summation order): dot products of up to 33 terms, the activations' exp,
// the Fourier features (btf_sincos_pi's polynomials: SwiftShader's own sin and cos had moved y by
// 4e-4), the final exp. Each contributes O(2^-24) relative to the terms' sizes (|y| and the
// summed |w a| are O(10) here): measured at most 2.5e-6 (printed). Tolerance: 2e-5, 8x that,
// far below what a wrong weight, a wrong encoding element or a swapped texel gives (O(0.1)).
void ExpectNeuralGlslMatchesTheDecoders(const Codec& codec, const std::string& what) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  ExportNeural(codec, dir);
  const NeuralReferenceDecoder ref(dir);
  const Dataset& d = Twill();
  Queries qs;
  const int W = ref.width(), H = ref.height();
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u01(0, 1);
  for (int i = 0; i < 1024; ++i) {
    const int x = int(u01(rng) * W) % W, y = int(u01(rng) * H) % H;
    qs.Add(x, y, Vec2((x + 0.5) / W, 1 - (y + 0.5) / H), d.lights()[int(u01(rng) * d.num_lights()) % d.num_lights()],
           d.views()[int(u01(rng) * d.num_views()) % d.num_views()]);
  }
  qs.AddRandom(W, H, 2048, rng);
  std::string renderer;
  const std::vector<float> got = EvaluateInBrowser(BrowserOptions{}, dir, qs.q, &renderer);
  ASSERT_EQ(got.size(), qs.size() * 3);
  const double eps = ref.log_epsilon();
  double worst_ref = 0, worst_codec = 0, worst_cpu = 0, lo = 1e30, hi = -1e30;
  for (std::size_t i = 0; i < qs.size(); ++i) {
    float want[3], cpu[3];
    ref.Value(qs.x[i], qs.y[i], qs.wi(i), qs.wo(i), want);
    codec.Value(Vec2((qs.x[i] + 0.5) / W, 1 - (qs.y[i] + 0.5) / H), qs.wi(i), qs.wo(i), cpu, UvFilter::kNearest);
    for (int c = 0; c < 3; ++c) {
      const double g = got[i * 3 + c];
      worst_ref = std::max(worst_ref, std::abs(g - want[c]) / (std::abs(want[c]) + eps));
      worst_codec = std::max(worst_codec, std::abs(g - cpu[c]) / (std::abs(cpu[c]) + eps));
      worst_cpu = std::max(worst_cpu, std::abs(double(want[c]) - cpu[c]) / (std::abs(cpu[c]) + eps));
      lo = std::min(lo, std::log(cpu[c] + eps)), hi = std::max(hi, std::log(cpu[c] + eps));
    }
  }
  std::cout << "neural GLSL (" << what << "; " << renderer << "): worst |diff| / (|value| + eps) against the reference "
            << "decoder " << worst_ref << ", against Codec::Value " << worst_codec << " (reference vs Codec::Value "
            << worst_cpu << "; log(value + eps) from " << lo << " to " << hi << ")\n";
  EXPECT_GT(hi - lo, 0.5);  // the decoder's output varies over the queries
  EXPECT_LE(worst_ref, 2e-5);
  EXPECT_LE(worst_codec, 2e-5);
}

TEST(Browser, NeuralGlslMatchesTheReferenceDecoderAndTheCodec) {
  ExpectNeuralGlslMatchesTheDecoders(TwillNeuralCodec(), "uint8 latents, SiLU");
}

// Half latents, 5 of them (a partly filled second layer), 2 Fourier octaves and softplus (the
// decoder's parameters reused with that activation: btf-compress trains SiLU only).
TEST(Browser, NeuralGlslMatchesWithHalfLatentsFourierFeaturesAndSoftplus) {
  CompressOptions co;
  co.method = CodecMethod::kNeural;
  co.seed = 7;
  co.neural.latent = 5;
  co.neural.latent_storage = "half";
  co.neural.fourier = 2;
  co.neural.samples = 1 << 15;
  co.neural.batch = 1024;
  co.neural.steps = 100;
  Codec codec = test::CompressDataset(Twill(), co);
  NeuralCodecModel& m = CodecBuilder::neural(codec);
  NeuralNetShape shape = m.net.shape();
  shape.activation = Activation::kSoftplus;
  NeuralNet net(shape, 0);
  net.parameters() = m.net.parameters();
  m.net = net;
  ExpectNeuralGlslMatchesTheDecoders(codec, "half latents, 2 Fourier octaves, softplus");
}

// The neural export drawn by the viewer against the CPU render of the same export
// (NeuralReferenceDecoder), under the tolerances of the first rows; the decoder runs per pixel
// and light, so the patch under the point light only.
TEST(Browser, NeuralPatchPointAgreesWithTheCpuRender) { ExpectSceneAgrees("patch-point", false, 0.01, 0.05, Neural); }

// ---- The page's controls: tiling, its footprint filter, exposure, the angle readout ----------

struct PageRun {
  Image image;           // the canvas, decoded to linear
  nlohmann::json panel;  // the panel's texts by element id
};

// The interactive page (mode=view) of `export_dir` in headless Chromium with `scene_json` as its
// start scene and the controls in `ui` ([[id, value], ...]) set as a user sets them (input and
// change events; JSON text); the frame they ask for is read from the canvas (viewer/render.mjs --mode canvas).
PageRun RunPage(const std::filesystem::path& export_dir, const nlohmann::json& scene_json, const std::string& ui) {
  const BrowserOptions b;
  static int runs = 0;  // a job folder per run beside the export (test::TempDir would empty the test's folder)
  const auto job = export_dir.parent_path() / ("page" + std::to_string(++runs)), png = job / "canvas.png";
  std::filesystem::create_directories(job);
  std::ofstream(job / "scene.json") << scene_json.dump();
  std::string out;
  const int rc = test::RunCommand(b.node + " '" + (ViewerDir(b) / "render.mjs").string() + "' --export '" + std::filesystem::absolute(export_dir).string() +
                                      "' --job '" + std::filesystem::absolute(job).string() + "' --mode canvas --out '" + png.string() + "' --ui '" + ui + "' 2>&1",
                                  &out);
  std::istringstream lines(out);
  std::string line, last;
  while (std::getline(lines, line))
    if (!line.empty()) last = line;
  if (rc != 0) throw std::runtime_error("render.mjs --mode canvas failed: " + out);
  return {ReadImage(png), nlohmann::json::parse(last).at("panel")};
}

// A view straight down on the plane (camera at height 32, up = y: nearly orthographic), `pixels`
// square, spanning 2.048 units: a pixel is 2.048 / pixels units wide and the plane parallel to the
// image, so a texture period is the same number of pixels everywhere. The point light far away (irradiance about
// cos theta_i everywhere).
nlohmann::json TopDownScene(int pixels, double tiles) {
  RenderOptions o = WebSceneOptions("patch-point", pixels, pixels);
  o.tiles = tiles;
  o.light_position = Vec3(20, -25, 40);
  o.light_intensity = o.light_position.squaredNorm();
  nlohmann::json j = ViewerSceneJson(o, 1.0);
  j["camera"] = {{"position", {0, 0, 32}}, {"target", {0, 0, 0}}, {"up", {0, 1, 0}},
                 {"fov_y_deg", 2 * std::atan(1.024 / 32) * 180 / kPi}};
  return j;
}

// Tiling: with R = 3.90625 repeats across the plane, a tile is 0.512 units = 64 pixels of the
// top-down view (a texel 4 pixels, its edges on pixel edges). The mean |difference| of the image
// and itself shifted by s pixels (x and y), over a 120 x 120 region on the plane, for s = 16..112:
// smallest at s = 64, the period, and there far below the difference half a period away. What is
// left at s = 64 is the change of view and light directions over one period (and 8-bit rounding).
TEST(Browser, TiledPlaneRepeatsWithTheTilePeriodOnScreen) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  TwillExport(dir);
  const PageRun r = RunPage(dir, TopDownScene(256, 2.0 / 0.512), "[]");
  ASSERT_EQ(r.image.width, 256);
  auto diff = [&](int s) {
    double sum = 0;
    for (int y = 8; y < 128; ++y)
      for (int x = 8; x < 128; ++x)
        sum += std::abs(Luminance(r.image, x, y) - Luminance(r.image, x + s, y)) +
               std::abs(Luminance(r.image, x, y) - Luminance(r.image, x, y + s));
    return sum / (2 * 120 * 120);
  };
  int best = 0;
  double best_d = 1e30, level = 0;
  for (int s = 16; s <= 112; ++s)
    if (const double d = diff(s); d < best_d) best = s, best_d = d;
  for (int y = 8; y < 248; ++y)
    for (int x = 8; x < 248; ++x) level += Luminance(r.image, x, y) / (240 * 240);
  std::cout << "tiled plane (" << r.panel["tile-value"] << "): mean |I(p) - I(p + s)| smallest at s = " << best << " px ("
            << best_d << "), at s = 32: " << diff(32) << ", at s = 63: " << diff(63) << "; mean luminance " << level << "\n";
  EXPECT_EQ(best, 64);
  EXPECT_LT(best_d, 0.1 * diff(32));
  EXPECT_LT(best_d, 0.02 * level);
}

// The CPU renderer tiles the same way (RenderOptions::tiles; btf-eval render --tiles): with 5
// repeats the patch-point pictures agree under the tolerances of the first row (the footprint
// stays below 0.95 texels, so the viewer takes the nearest texel everywhere).
TEST(Browser, TiledPatchPointAgreesWithTheCpuRender) { ExpectSceneAgrees("patch-point", false, 0.01, 0.05, Lpca, 280, 224, 5); }

// The footprint filter: at R = 31 repeats a texel is 0.52 pixels of the 256-pixel top-down view
// (footprint 1.94 texels: 2 x 2 taps, at the centres of the pixel's four quarters). The reference
// is the box filter done by hand: the 512-pixel view (footprint 0.97: one tap, the nearest texel
// at each pixel centre, which are the 256-pixel view's tap positions) averaged over 2 x 2 pixels.
// Filtered against it: the same up to 8-bit rounding and the taps' shared view and light
// directions; the nearest texel alone (filter "1 tap") is far from it (aliasing).
TEST(Browser, FootprintFilterAveragesTheTexelsUnderAPixel) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  TwillExport(dir);
  const double tiles = 31;
  const PageRun filtered = RunPage(dir, TopDownScene(256, tiles), "[]");
  const PageRun nearest = RunPage(dir, TopDownScene(256, tiles), R"([["taps", "1"]])");
  const PageRun fine = RunPage(dir, TopDownScene(512, tiles), R"([["taps", "1"]])");
  std::vector<double> box, f;
  double sum_f = 0, sum_n = 0;
  for (int y = 8; y < 248; ++y)
    for (int x = 8; x < 248; ++x) {
      double b = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) b += Luminance(fine.image, 2 * x + dx, 2 * y + dy) / 4;
      box.push_back(b), f.push_back(std::abs(Luminance(filtered.image, x, y) - b));
      sum_f += f.back(), sum_n += std::abs(Luminance(nearest.image, x, y) - b);
    }
  const int n = int(box.size());
  std::sort(box.begin(), box.end());
  const double level = box[std::size_t(0.99 * (n - 1))];  // the 99th-percentile luminance, as in Compare
  const int off = int(std::count_if(f.begin(), f.end(), [&](double d) { return d > 0.05 * level; }));
  std::cout << "footprint filter at " << tiles << " tiles (level " << level << "): mean |filtered - box of the 2x view| "
            << 100 * sum_f / n / level << " % of the level (max " << 100 * *std::max_element(f.begin(), f.end()) / level << " %, "
            << off << " of " << n << " pixels beyond 5 %), nearest texel alone " << 100 * sum_n / n / level << " %\n";
  EXPECT_LE(sum_f / n, 0.01 * level);
  EXPECT_LE(off, n / 200);
  EXPECT_GE(sum_n, 4 * sum_f);
}

// Display value v = sRGB(clamp(exposure * L, 0, 1)): one stop more on the exposure slider doubles
// every linear value that stays below 1. Per pixel and channel (decoded from the 8-bit canvas) the
// difference |v_2 - 2 v_1| may be half an 8-bit step of v_2 plus twice half a step of v_1.
double SrgbToLinear(double s) { return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4); }
double HalfStep(double v) {  // half the linear width of v's 8-bit sRGB step
  const double s = std::round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055));
  return 0.5 * (SrgbToLinear(std::min(255.0, s + 0.5) / 255) - SrgbToLinear(std::max(0.0, s - 0.5) / 255));
}

TEST(Browser, ExposureSliderDoublesTheLinearValuesPerStop) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  TwillExport(dir);
  const nlohmann::json scene = ViewerSceneJson(WebSceneOptions("patch-point", 280, 224), 1.0);
  const PageRun one = RunPage(dir, scene, "[]"), two = RunPage(dir, scene, R"([["exposure", "1"]])");
  EXPECT_EQ(one.panel["exposure-value"], "x1.00 (+0.0 stops from 1.00)");
  EXPECT_EQ(two.panel["exposure-value"], "x2.00 (+1.0 stops from 1.00)");
  int compared = 0, beyond = 0, beyond_5_percent_off = 0;
  for (int y = 0; y < 224; ++y)
    for (int x = 0; x < 280; ++x)
      for (int c = 0; c < 3; ++c) {
        const double v1 = one.image.at(x, y, c), v2 = two.image.at(x, y, c);
        if (v1 < 0.01 || v1 > 0.45) continue;
        ++compared;
        beyond += std::abs(v2 - 2 * v1) > HalfStep(v2) + 2 * HalfStep(v1) + 1e-7;
        // The same bound for a factor 2.1: a slider 5 % off would show.
        beyond_5_percent_off += std::abs(v2 - 2.1 * v1) > HalfStep(v2) + 2.1 * HalfStep(v1) + 1e-7;
      }
  std::cout << "exposure +1 stop: " << beyond << " of " << compared << " values beyond 8-bit rounding of v2 = 2 v1 ("
            << beyond_5_percent_off << " of v2 = 2.1 v1)\n";
  EXPECT_GT(compared, 280 * 224);  // most of the picture (the shape and the background) is compared
  EXPECT_EQ(beyond, 0);
  EXPECT_GT(beyond_5_percent_off, compared / 2);
}

// The panel's angles: theta (from the normal) and phi (from u) of the light and the camera at the
// object's reference point, for the start scene (patch-point: the plane's centre) and after the
// shape selector switched to the cylinder (its top, 0.6 above the axis), against the scene's
// numbers (RenderOptions's light, RenderCamera) computed here; printed with one decimal.
void ExpectAngles(const std::string& text, const Vec3& at) {
  const RenderOptions o;
  const RenderCamera cam;
  auto angles = [&](const Vec3& q) {
    const Vec3 v = (q - at).normalized();
    return std::pair(std::acos(v.z()) * 180 / kPi, std::atan2(v.y(), v.x()) * 180 / kPi);
  };
  const auto [lt, lp] = angles(o.light_position);
  const auto [ct, cp] = angles(cam.position);
  double got[4];
  ASSERT_EQ(std::sscanf(text.c_str(), "light theta %lf\u00b0 phi %lf\u00b0; camera theta %lf\u00b0 phi %lf\u00b0", &got[0], &got[1],
                        &got[2], &got[3]),
            4)
      << text;
  const double want[4] = {lt, lp, ct, cp};
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(got[i], want[i], 0.05 + 1e-9) << text << " (angle " << i << ")";
}

TEST(Browser, AngleReadoutMatchesTheScene) {
  SKIP_WITHOUT_CHROMIUM();
  const auto dir = test::TempDir() / "export";
  TwillExport(dir);
  const nlohmann::json scene = ViewerSceneJson(WebSceneOptions("patch-point", 140, 112), 1.0);
  const PageRun plane = RunPage(dir, scene, "[]"), cylinder = RunPage(dir, scene, R"([["scene", "cylinder"]])");
  std::cout << "angles: " << plane.panel["angles"] << "; " << cylinder.panel["angles"] << "\n";
  ExpectAngles(plane.panel["angles"], Vec3(0, 0, 0));
  ExpectAngles(cylinder.panel["angles"], Vec3(0, 0, kCylinderRadius));
  EXPECT_NE(plane.panel["angles"], cylinder.panel["angles"]);
}

// Every layout's btf_eval wraps uv (period 1): the same queries shifted by whole periods give the
// same values (texel positions in the texels' central halves, so float32 rounding of uv + k
// cannot move a query to another texel).
TEST(Browser, EveryLayoutsGlslWrapsUv) {
  SKIP_WITHOUT_CHROMIUM();
  for (Exporter exporter : {Lpca, PcaView, Neural}) {
    const auto dir = test::TempDir() / "export";
    exporter(dir, {});
    Queries qs;
    std::mt19937 rng(5);
    qs.AddRandom(Twill().width(), Twill().height(), 512, rng);
    const std::size_t n = qs.size();
    for (const auto& [du, dv] : {std::pair(3, -2), std::pair(-1, 5)})
      for (std::size_t i = 0; i < n; ++i) {
        qs.q.insert(qs.q.end(), qs.q.begin() + i * 8, qs.q.begin() + i * 8 + 8);
        qs.q[qs.q.size() - 8] += du, qs.q[qs.q.size() - 7] += dv;
      }
    const std::vector<float> got = EvaluateInBrowser(BrowserOptions{}, dir, qs.q);
    ASSERT_EQ(got.size(), 3 * n * 3);
    double worst = 0, largest = 0;
    for (std::size_t k = 1; k < 3; ++k)
      for (std::size_t i = 0; i < n * 3; ++i) {
        worst = std::max(worst, double(std::abs(got[k * n * 3 + i] - got[i])));
        largest = std::max(largest, double(std::abs(got[i])));
      }
    std::cout << ExporterName(exporter) << ": largest |btf_eval(uv + k) - btf_eval(uv)| " << worst << " (values up to " << largest
              << ")\n";
    EXPECT_GT(largest, 0);
    EXPECT_LE(worst, 1e-6 * largest);
  }
}

}  // namespace
}  // namespace btf
