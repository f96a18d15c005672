#include "libbtf/web/web.h"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <csignal>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/export/neural.h"
#include "libbtf/export/neural_reference_decoder.h"
#include "libbtf/export/sattler_reference_decoder.h"
#include "libbtf/export/schneider.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/file_kind.h"

namespace btf {

const char* ViewerSourceDir();  // viewer_source_dir.cpp

namespace {

// Owns the reference decoder of one layout.
template <typename Decoder>
class ExportBtfEvaluator final : public BtfEvaluator {
 public:
  explicit ExportBtfEvaluator(const std::filesystem::path& dir) : d_(dir) {}
  int channels() const override { return d_.channels(); }
  bool cos_theta_i_included() const override { return d_.cos_theta_i_included(); }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override {
    const double u = uv.x() - std::floor(uv.x()), v = uv.y() - std::floor(uv.y());
    const int x = std::min(int(u * d_.width()), d_.width() - 1);
    const int y = std::min(int((1.0 - v) * d_.height()), d_.height() - 1);
    d_.Value(x, y, wi, wo, out);
  }

 private:
  const Decoder d_;
};

nlohmann::json Vec(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

// A scratch folder for one browser run, removed when done.
class JobDir {
 public:
  JobDir() {
    static int counter = 0;
    path_ = std::filesystem::temp_directory_path() /
            fmt::format("libbtf-web-{}-{}-{}", ::getpid(), counter++,
                        std::chrono::steady_clock::now().time_since_epoch().count());
    std::filesystem::create_directories(path_);
  }
  ~JobDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

std::string ReadText(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Runs argv with stdout and stderr to files (empty path: inherited); returns the exit status
// (128 + signal when killed). The child gets SIGTERM when this process dies (an interrupted
// btf-eval leaves no server or browser behind).
int Spawn(const std::vector<std::string>& args, const std::filesystem::path& out, const std::filesystem::path& err) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  int pipe_fd[2];  // reports an exec failure (errno) to the parent; closed on exec
  if (::pipe2(pipe_fd, O_CLOEXEC) != 0) ThrowIo("cannot create a pipe: {}", std::strerror(errno));
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) ThrowIo("cannot fork: {}", std::strerror(errno));
  if (pid == 0) {  // child: async-signal-safe calls only
    ::close(pipe_fd[0]);
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(127);
    if (!out.empty()) {
      const int fd = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 1), ::close(fd);
    }
    if (!err.empty()) {
      const int fd = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) ::dup2(fd, 2), ::close(fd);
    }
    ::execvp(argv[0], argv.data());
    const int e = errno;
    [[maybe_unused]] const auto w = ::write(pipe_fd[1], &e, sizeof e);
    ::_exit(127);
  }
  ::close(pipe_fd[1]);
  int exec_errno = 0;
  const auto n = ::read(pipe_fd[0], &exec_errno, sizeof exec_errno);
  ::close(pipe_fd[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) ThrowIo("waiting for '{}' failed: {}", args[0], std::strerror(errno));
  if (n == static_cast<ssize_t>(sizeof exec_errno))
    ThrowUsage("cannot run '{}': {} (install it, or name it with --node)", args[0], std::strerror(exec_errno));
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

// node viewer/render.mjs in `job` (scene.json already written); returns its JSON summary line.
nlohmann::json RunRender(const BrowserOptions& b, const std::filesystem::path& export_dir, const JobDir& job,
                         const std::string& mode, const std::filesystem::path& out, int frames = 10) {
  b.Check();
  if (!std::filesystem::exists(export_dir / "manifest.json"))
    ThrowBadInput("'{}' is not an export folder (no manifest.json; make one with btf-compress export)", export_dir.string());
  if (!ChromiumAvailable(b)) ThrowUsage("Chromium not found at '{}' (Debian: apt-get install chromium; or --chromium PATH)", b.chromium);
  const auto viewer = ViewerDir(b);
  const auto log_out = job.path() / "node.out", log_err = job.path() / "node.err";
  const int rc = Spawn({b.node, (viewer / "render.mjs").string(), "--export", std::filesystem::absolute(export_dir).string(),
                        "--job", job.path().string(), "--mode", mode, "--out", std::filesystem::absolute(out).string(),
                        "--chromium", b.chromium, "--timeout", std::to_string(b.timeout_s), "--frames", std::to_string(frames)},
                       log_out, log_err);
  if (rc != 0) {
    std::string e = ReadText(log_err);
    if (e.size() > 4000) e = "..." + e.substr(e.size() - 4000);
    throw Error(ExitCode::kIo, fmt::format("browser run ({} mode) failed with status {}: {}", mode, rc, e));
  }
  std::string line = ReadText(log_out);
  const auto j = nlohmann::json::parse(line, nullptr, false);
  if (j.is_discarded()) ThrowIo("browser run printed no JSON summary: '{}'", line);
  return j;
}

}  // namespace

std::vector<std::string> WebSceneNames() { return {"patch-point", "cylinder-env"}; }

RenderOptions WebSceneOptions(const std::string& scene, int width, int height) {
  RenderOptions o;
  if (scene == "patch-point") {
    o.scene = "patch", o.lighting = "point";
  } else if (scene == "cylinder-env") {
    o.scene = "cylinder", o.lighting = "environment", o.environment = "sky";
  } else {
    ThrowUsage("unknown scene '{}' (available: patch-point, cylinder-env)", scene);
  }
  o.width = width, o.height = height;
  o.Check();
  return o;
}

namespace {

// Tone mapping of both renderers: display value = sRGB(clamp(exposure * radiance, 0, 1)); this
// returns exposure * radiance clamped to [0, 1] (write it with ImageWriteOptions::srgb = true).
Image ToneMap(const Image& linear, double exposure) {
  Image out = linear;
  for (auto& v : out.pixels) v = std::clamp(float(v * exposure), 0.0f, 1.0f);
  return out;
}

}  // namespace

nlohmann::json ViewerSceneJson(const RenderOptions& o, double exposure) {
  o.Check();
  const RenderCamera cam;
  // The environment's samples whatever the starting lighting: the page switches between point
  // light and sky at any time.
  RenderOptions sky = o;
  sky.lighting = "environment";
  nlohmann::json dirs = nlohmann::json::array(), rad = nlohmann::json::array();
  for (const auto& e : EnvironmentSamples(sky)) {
    dirs.push_back(Vec(e.direction));
    rad.push_back({e.radiance_solid_angle[0], e.radiance_solid_angle[1], e.radiance_solid_angle[2]});
  }
  return {{"shape", o.scene},
          {"lighting", o.lighting},
          {"width", o.width},
          {"height", o.height},
          {"tiles", o.tiles},
          {"cylinder_radius", kCylinderRadius},
          {"camera", {{"position", Vec(cam.position)}, {"target", Vec(cam.target)}, {"up", Vec(cam.up)}, {"fov_y_deg", cam.fov_y_deg}}},
          {"light", {{"position", Vec(o.light_position)}, {"intensity", o.light_intensity}}},
          {"background", o.background},
          {"exposure", exposure},
          {"environment", {{"name", o.environment}, {"directions", dirs}, {"radiance_solid_angle", rad}}}};
}

namespace {

// An export folder (any layout) as a BtfEvaluator through its reference decoder (nearest texel
// for uv, as DatasetEvaluator).
std::unique_ptr<BtfEvaluator> OpenExportEvaluator(const std::filesystem::path& dir) {
  std::ifstream in(dir / "manifest.json");
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  const std::string layout = !j.is_discarded() && j.is_object() ? j.value("layout", "") : "";
  if (layout == kSattlerLayout) return std::make_unique<ExportBtfEvaluator<SattlerReferenceDecoder>>(dir);
  if (layout == kNeuralLayout) return std::make_unique<ExportBtfEvaluator<NeuralReferenceDecoder>>(dir);
  return std::make_unique<ExportBtfEvaluator<SchneiderReferenceDecoder>>(dir);  // its errors name what is wrong
}

}  // namespace

nlohmann::json CpuRenderSummary::ToJson() const {
  return {{"output", output}, {"source", source}, {"source_kind", source_kind}, {"scene", scene},
          {"width", width}, {"height", height}, {"exposure", exposure}, {"seconds", seconds}};
}

std::string CpuRenderSummary::Report() const {
  return fmt::format("{}: {} of {} ({}) at {} x {} on the CPU, exposure {:g}, {:.1f} s\n", output, scene, source, source_kind,
                     width, height, exposure, seconds);
}

CpuRenderSummary RenderCpu(const std::filesystem::path& source, const RenderOptions& scene, double exposure,
                           const std::filesystem::path& png, const std::string& scene_name, Image* linear) {
  if (!(std::isfinite(exposure) && exposure > 0)) ThrowUsage("invalid option 'exposure': must be > 0");
  scene.Check();
  const auto t0 = std::chrono::steady_clock::now();
  CpuRenderSummary s;
  Image img;
  if (std::filesystem::is_directory(source)) {
    img = Render(*OpenExportEvaluator(source), scene);
    s.source_kind = "export";
  } else {
    const std::string format = FileFormatOf(source);
    if (format == kCodecFormat) {
      const Codec codec = ReadCodec(source);
      img = Render(*CodecEvaluator(codec), scene);
      s.source_kind = "codec";
    } else if (format == kDatasetFormat) {
      RequireEveryImage(DatasetReader(source).header(), "rendering interpolates between all sampled directions");
      const Dataset d = ReadDataset(source);
      img = Render(*DatasetEvaluator(d), scene);
      s.source_kind = "dataset";
    } else {
      ThrowBadInput("'{}' is a '{}' file: render takes an export folder, a libbtf codec or a dataset", source.string(), format);
    }
  }
  ImageWriteOptions w;  // 8-bit sRGB, as the browser's canvas
  w.has_format = true;
  w.format = PixelFormat::kUint8;
  w.srgb = true;
  WriteImage(png, ToneMap(img, exposure), w);
  if (linear) *linear = std::move(img);
  s.output = png.string();
  s.source = source.string();
  s.scene = scene_name.empty() ? scene.scene + "-" + scene.lighting : scene_name;
  s.width = scene.width, s.height = scene.height;
  s.exposure = exposure;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return s;
}

void BrowserOptions::Check() const {
  BTF_CHECK_OPTION(!chromium.empty(), "chromium", "must name the Chromium executable");
  BTF_CHECK_OPTION(!node.empty(), "node", "must name the node executable");
  BTF_CHECK_OPTION(timeout_s >= 1 && timeout_s <= 3600, "timeout_s", "must be 1..3600");
}

std::filesystem::path ViewerDir(const BrowserOptions& b, bool need_playwright) {
  std::filesystem::path dir = b.viewer_dir;
  if (dir.empty()) {
    const char* env = std::getenv("BTF_VIEWER_DIR");
    dir = env && *env ? std::filesystem::path(env) : std::filesystem::path(ViewerSourceDir());
  }
  if (!std::filesystem::exists(dir / "index.html")) ThrowUsage("'{}' is not the libbtf viewer folder (no index.html)", dir.string());
  for (const char* m : {"three", "playwright-core"}) {
    if (!need_playwright && std::string(m) == "playwright-core") continue;
    if (!std::filesystem::exists(dir / "node_modules" / m / "package.json"))
      ThrowUsage("'{}' lacks node_modules/{} (run 'npm ci' in it; ./run does)", dir.string(), m);
  }
  return dir;
}

bool ChromiumAvailable(const BrowserOptions& b) {
  if (b.chromium.find('/') != std::string::npos) return ::access(b.chromium.c_str(), X_OK) == 0;
  const char* path = std::getenv("PATH");
  std::stringstream s(path ? path : "");
  for (std::string d; std::getline(s, d, ':');)
    if (!d.empty() && ::access((std::filesystem::path(d) / b.chromium).c_str(), X_OK) == 0) return true;
  return false;
}

nlohmann::json WebRenderSummary::ToJson() const {
  return {{"output", output}, {"scene", scene}, {"width", width},          {"height", height},
          {"renderer", renderer}, {"seconds", seconds}, {"benchmark", benchmark}};
}

std::string WebRenderSummary::Report() const {
  std::string r = fmt::format("{}: {} at {} x {} in headless Chromium ({}), {:.1f} s\n", output, scene, width, height, renderer, seconds);
  if (benchmark.is_object())
    r += fmt::format("benchmark: {:.1f} ms per frame at {} x {} (median of {} frames; min {:.1f}, max {:.1f})\n",
                     benchmark.value("median_ms", 0.0), benchmark.value("width", 0), benchmark.value("height", 0),
                     benchmark.value("frames", 0), benchmark.value("min_ms", 0.0), benchmark.value("max_ms", 0.0));
  return r;
}

WebRenderSummary RenderWeb(const BrowserOptions& b, const RenderOptions& scene, double exposure,
                           const std::filesystem::path& export_dir, const std::filesystem::path& png,
                           const std::string& scene_name, bool page) {
  if (!(std::isfinite(exposure) && exposure > 0)) ThrowUsage("invalid option 'exposure': must be > 0");
  JobDir job;
  WriteTextFileAtomic(job.path() / "scene.json", ViewerSceneJson(scene, exposure).dump());
  const auto shot = job.path() / "shot.png";
  const auto t0 = std::chrono::steady_clock::now();
  const nlohmann::json j = RunRender(b, export_dir, job, page ? "page" : "shot", shot);
  const std::string bytes = [&] {
    std::ifstream in(shot, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }();
  if (bytes.size() < 8) ThrowIo("the browser wrote no PNG");
  WriteFileAtomic(png, bytes.data(), bytes.size());
  WebRenderSummary s;
  s.output = png.string();
  s.scene = scene_name.empty() ? scene.scene + "-" + scene.lighting : scene_name;
  s.width = j.value("width", 0), s.height = j.value("height", 0);
  s.renderer = j.value("renderer", "");
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return s;
}

std::vector<float> EvaluateInBrowser(const BrowserOptions& b, const std::filesystem::path& export_dir,
                                     const std::vector<float>& queries, std::string* renderer) {
  if (queries.empty() || queries.size() % 8 != 0) ThrowUsage("queries must be [N][8] floats (u, v, wi, wo), N >= 1");
  JobDir job;
  RenderOptions o;
  o.width = o.height = 8;
  WriteTextFileAtomic(job.path() / "scene.json", ViewerSceneJson(o, 1.0).dump());
  WriteFileAtomic(job.path() / "queries.f32", queries.data(), queries.size() * sizeof(float));
  const auto out = job.path() / "values.f32";
  const nlohmann::json j = RunRender(b, export_dir, job, "eval", out);
  if (renderer) *renderer = j.value("renderer", "");
  const std::size_t n = queries.size() / 8 * 3;
  std::vector<float> v(n);
  std::ifstream in(out, std::ios::binary);
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(float)));
  if (in.gcount() != static_cast<std::streamsize>(n * sizeof(float))) ThrowIo("the browser returned fewer than {} values", n);
  return v;
}

nlohmann::json BenchmarkWeb(const BrowserOptions& b, const RenderOptions& scene, double exposure,
                            const std::filesystem::path& export_dir, int frames) {
  if (frames < 1 || frames > 10000) ThrowUsage("invalid option 'frames': must be 1..10000");
  JobDir job;
  WriteTextFileAtomic(job.path() / "scene.json", ViewerSceneJson(scene, exposure).dump());
  const auto out = job.path() / "bench.json";
  RunRender(b, export_dir, job, "bench", out, frames);
  return nlohmann::json::parse(ReadText(out));
}

std::string ViewerUrl(int port) { return fmt::format("http://127.0.0.1:{}/index.html?job=1", port); }

int ServeViewer(const BrowserOptions& b, const std::filesystem::path& export_dir, int port, const RenderOptions& scene,
                double exposure) {
  b.Check();
  if (port < 1 || port > 65535) ThrowUsage("invalid option 'port': must be 1..65535");
  if (!std::filesystem::exists(export_dir / "manifest.json"))
    ThrowBadInput("'{}' is not an export folder (no manifest.json; make one with btf-compress export)", export_dir.string());
  const auto viewer = ViewerDir(b, false);
  JobDir job;
  WriteTextFileAtomic(job.path() / "scene.json", ViewerSceneJson(scene, exposure).dump());
  // The server's own URL line goes to /dev/null: the caller prints ViewerUrl(port).
  return Spawn({b.node, (viewer / "server.mjs").string(), "--export", std::filesystem::absolute(export_dir).string(), "--job",
                job.path().string(), "--port", std::to_string(port)},
               "/dev/null", "");
}

}  // namespace btf
