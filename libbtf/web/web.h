#pragma once
// The browser side of the renderer export (docs/viewer.md): named scenes shared by the CPU
// renderer (libbtf/eval/render.h) and the WebGL2 viewer (viewer/), an evaluator of an export
// folder through its reference decoder, and runs of the viewer in headless Chromium (through node
// and playwright-core: viewer/render.mjs) or as a local server (viewer/server.mjs).
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/eval/render.h"
#include "libbtf/io/image_io.h"

namespace btf {

// The scenes of render-web and render: "patch-point" (the flat patch under the point light) and
// "cylinder-env" (the cylinder under the sampled sky), at width x height pixels.
std::vector<std::string> WebSceneNames();
RenderOptions WebSceneOptions(const std::string& scene, int width, int height);
// scene.json for the viewer: everything the page needs to draw `scene` as the CPU renderer does
// (camera, shape, tiles, light, background, exposure, size) and the environment's samples, also
// when the scene starts with the point light (the page's lighting choice switches to the sky).
nlohmann::json ViewerSceneJson(const RenderOptions& scene, double exposure);

struct CpuRenderSummary {
  std::string output, source, source_kind, scene;  // source_kind: export, codec or dataset
  int width = 0, height = 0;
  double seconds = 0, exposure = 1;
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// The CPU renderer's picture of `source` (an export folder, a codec or a dataset file) under
// `scene`, tone-mapped as in the viewer (display value = sRGB(clamp(exposure * radiance, 0, 1)))
// and written as an sRGB PNG (atomically) to `png`; `linear` (if non-null) gets the radiance
// image before tone mapping.
CpuRenderSummary RenderCpu(const std::filesystem::path& source, const RenderOptions& scene, double exposure,
                           const std::filesystem::path& png, const std::string& scene_name = "", Image* linear = nullptr);

struct BrowserOptions {
  std::string chromium = "/usr/bin/chromium";  // Debian's chromium
  std::string node = "node";                   // node >= 18 (on PATH unless a path is given)
  // The viewer folder (index.html, viewer.js, render.mjs, node_modules/ from npm ci); empty: the
  // environment variable BTF_VIEWER_DIR, else this source tree's viewer/.
  std::string viewer_dir;
  int timeout_s = 300;  // for one browser run
  void Check() const;
};

// The viewer folder the options name (see BrowserOptions::viewer_dir). Throws btf::Error (usage)
// when it lacks node_modules/three or node_modules/playwright-core ("run npm ci in it").
std::filesystem::path ViewerDir(const BrowserOptions& options, bool need_playwright = true);
// True when the Chromium executable exists.
bool ChromiumAvailable(const BrowserOptions& options);

struct WebRenderSummary {
  std::string output, renderer, scene;
  int width = 0, height = 0;
  double seconds = 0;  // node + browser, wall clock
  nlohmann::json benchmark;  // BenchmarkWeb's result when frames were timed, else null
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// Renders the export at `export_dir` in headless Chromium (software WebGL2) and writes the frame
// as an sRGB PNG (atomically) to `png`. With `page`, the PNG is a screenshot of the interactive
// page instead (its controls and ms per frame over the first frame).
WebRenderSummary RenderWeb(const BrowserOptions& browser, const RenderOptions& scene, double exposure,
                           const std::filesystem::path& export_dir, const std::filesystem::path& png,
                           const std::string& scene_name = "", bool page = false);

// btf_eval of the export's GLSL in the browser at N queries (float [N][8]: u, v, wi xyz, wo xyz);
// returns float [N][3]. `renderer` (if non-null) gets the WebGL renderer string.
std::vector<float> EvaluateInBrowser(const BrowserOptions& browser, const std::filesystem::path& export_dir,
                                     const std::vector<float>& queries, std::string* renderer = nullptr);

// ms per frame of `scene` in headless Chromium: {frames, median_ms, min_ms, max_ms, renderer, width, height}.
nlohmann::json BenchmarkWeb(const BrowserOptions& browser, const RenderOptions& scene, double exposure,
                            const std::filesystem::path& export_dir, int frames);

// Serves the viewer for `export_dir` on 127.0.0.1:port (the page at ViewerUrl(port)) until the
// server stops (Ctrl-C); returns node's exit status. The scene starts as `scene`.
int ServeViewer(const BrowserOptions& browser, const std::filesystem::path& export_dir, int port,
                const RenderOptions& scene, double exposure);
std::string ViewerUrl(int port);

}  // namespace btf
