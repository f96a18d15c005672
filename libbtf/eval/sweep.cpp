#include "libbtf/eval/sweep.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "libbtf/compress/codec.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/compress/codec_source.h"
#include "libbtf/eval/metrics.h"
#include "libbtf/eval/plot.h"
#include "libbtf/export/sattler.h"
#include "libbtf/export/schneider.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/image_io.h"

namespace btf {

namespace {
// Methods with a cluster count k (swept over SweepOptions::clusters).
bool Clustered(const std::string& m) { return m == "lpca" || m == "lpca-tensor"; }
}  // namespace

void SweepOptions::Check() const {
  BTF_CHECK_OPTION(!methods.empty(), "methods", "name at least one method");
  for (const auto& m : methods) ParseMethod(m);  // throws (usage) for unknown names
  BTF_CHECK_OPTION(!components.empty(), "components", "give at least one component count");
  for (int c : components) BTF_CHECK_OPTION(c >= 1, "components", "every count must be >= 1");
  if (std::find(methods.begin(), methods.end(), "neural") != methods.end()) {
    for (int c : components) BTF_CHECK_OPTION(c <= 256, "components", "neural: the latent width is at most 256");
    neural.Check();
  }
  for (int k : clusters) BTF_CHECK_OPTION(k >= 1, "clusters", "every count must be >= 1");
  BTF_CHECK_OPTION(std::none_of(methods.begin(), methods.end(), Clustered) || !clusters.empty(), "clusters",
                   "lpca and lpca-tensor need at least one cluster count");
  BTF_CHECK_OPTION(runs >= 1 && runs <= 100, "runs", "must be 1..100");
  BTF_CHECK_OPTION(error_metric == "rel" || error_metric == "rmse", "error_metric", "must be rel or rmse");
  BTF_CHECK_OPTION(std::isfinite(render_max_rel_error) && render_max_rel_error >= 0, "render_max_rel_error",
                   "must be >= 0");
  render_options.Check();
  BTF_CHECK_OPTION(viewer_dir.empty() || render, "viewer_dir", "needs render (the viewer shows the rendered codecs)");
  BTF_CHECK_OPTION(viewer_dir.empty() || std::filesystem::exists(std::filesystem::path(viewer_dir) / "node_modules/three/build/three.module.js"),
                   "viewer_dir", "must be the viewer folder with node_modules/three (run 'npm ci' in it; ./run does)");
}

namespace {

// Median of a non-empty list (mean of the middle two for even sizes).
double Median(std::vector<double> v) {
  if (v.empty()) ThrowUsage("median of an empty list");
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Base64 (RFC 4648, with padding), for data URIs.
std::string Base64(const std::string& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::uint32_t b0 = static_cast<unsigned char>(bytes[i]);
    const std::uint32_t b1 = i + 1 < bytes.size() ? static_cast<unsigned char>(bytes[i + 1]) : 0;
    const std::uint32_t b2 = i + 2 < bytes.size() ? static_cast<unsigned char>(bytes[i + 2]) : 0;
    const std::uint32_t n = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[n & 63] : '=';
  }
  return out;
}

// The sweep's folder: files are written under the temporary folder (AtomicDirectory) and
// recorded by their final names.
struct OutputFolder {
  std::filesystem::path work, final;
  std::filesystem::path Work(const std::string& name) const { return work / name; }
  std::string Final(const std::string& name) const { return (final / name).string(); }
};

nlohmann::json Opt(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); }

std::string PointName(const SweepPoint& p) {
  return Clustered(p.method) ? fmt::format("{}_k{}_c{}", p.method, p.clusters, p.components)
                            : fmt::format("{}_c{}", p.method, p.components);
}

void WritePng(const std::filesystem::path& path, const Image& image) {
  ImageWriteOptions wo;
  wo.has_format = true;
  wo.format = PixelFormat::kUint8;
  wo.srgb = true;
  WriteImage(path, image, wo);
}

// ---- Phase 1: describe the dataset. ----

SweepSummary Describe(const std::filesystem::path& dataset, const std::filesystem::path& dir, const Dataset& data,
                      const SweepOptions& o) {
  SweepSummary s;
  s.dataset = dataset.string();
  s.output_dir = dir.string();
  s.error_metric = o.error_metric;
  s.views = data.num_views(), s.lights = data.num_lights(), s.height = data.height(), s.width = data.width();
  s.channels = data.channels();
  s.raw_float32_bytes = std::uint64_t(data.size()) * 4;
  return s;
}

// The settings, in a fixed order: each method, each k (lpca), each c.
std::vector<SweepPoint> Settings(const SweepOptions& o) {
  std::vector<SweepPoint> todo;
  for (const auto& m : o.methods) {
    const std::vector<int> ks = Clustered(m) ? o.clusters : std::vector<int>{0};
    for (int k : ks)
      for (int c : o.components) {
        SweepPoint p;
        p.method = m, p.components = c, p.clusters = k;
        todo.push_back(p);
      }
  }
  return todo;
}

// ---- Phase 2: compress and time one setting. ----

// Compresses `runs` times and decodes `runs` times, filling the point's times, sizes, stored
// parameters and warnings; returns the codec and sets `decoded` to its decoded BTF.
Codec CompressAndTime(const SlotSource& truth, const SweepOptions& o, SweepPoint& p, Dataset& decoded) {
  CompressOptions opt;
  opt.method = ParseMethod(p.method);
  opt.components = p.components;
  if (p.clusters) opt.clusters = p.clusters;
  opt.seed = o.seed;
  opt.log_transform = o.log_transform;
  if (opt.method == CodecMethod::kNeural) {
    opt.neural = o.neural;
    opt.neural.latent = p.components;
    const std::int64_t triples = std::int64_t(truth.views().size()) * truth.lights().size() * truth.height() * truth.width();
    opt.neural.samples = std::min(opt.neural.samples, triples);
  }
  Codec codec;
  CompressSummary cs;
  for (int r = 0; r < o.runs; ++r) {
    Timer t;
    cs = Compress(opt, truth, &codec);
    p.compress_runs.push_back(t.Seconds());
  }
  p.warnings = cs.warnings;
  p.stored_components = cs.components;
  p.stored_clusters = cs.clusters;
  p.bytes = codec.StoredBytes();
  p.ratio_float32 = p.bytes ? double(codec.RawBytes(4)) / double(p.bytes) : 0;
  p.ratio_half = p.bytes ? double(codec.RawBytes(2)) / double(p.bytes) : 0;
  // Decoding small codecs takes microseconds: each run repeats it until it has taken at least
  // 20 ms and reports the time per decode, so scheduler noise does not dominate.
  for (int r = 0; r < o.runs; ++r) {
    Timer t;
    int n = 0;
    do {
      decoded = codec.DecodeAll();
      ++n;
    } while (t.Seconds() < 0.02);
    p.decode_runs.push_back(t.Seconds() / n);
  }
  p.compress_s = Median(p.compress_runs);
  p.decode_s = Median(p.decode_runs);
  return codec;
}

// ---- Phase 3: evaluate one setting (metrics against the dataset). Returns the PSNR peak. ----

double Evaluate(const SlotSource& truth, const Dataset& decoded, const SweepOptions& o, SweepPoint& p) {
  CompareOptions co;
  co.ssim = o.ssim;
  const CompareSummary e = Compare(co, truth, *MemorySource(decoded, PointName(p)));
  p.rmse = e.rmse, p.max_abs = e.max_abs, p.rel_l2 = e.rel_l2, p.psnr_db = e.psnr_db, p.mean_ssim = e.mean_ssim;
  p.error = o.error_metric == "rel" && e.rel_l2 ? *e.rel_l2 : e.rmse;
  return e.peak;
}

void KeepCodec(const OutputFolder& out, const Codec& codec, SweepPoint& p) {
  const std::string name = "codecs/" + PointName(p) + ".h5";
  WriteCodec(out.Work(name), codec, "btf-eval sweep");
  p.codec_file = out.Final(name);
  p.file_bytes = std::filesystem::file_size(out.Work(name));
}

// The codec each method renders (see SweepOptions::render_max_rel_error), with its point index.
class RenderChoice {
 public:
  struct Chosen {
    std::size_t index;
    bool within;  // meets the error bound
    Codec codec;
  };
  explicit RenderChoice(double max_rel_error) : max_rel_error_(max_rel_error) {}
  // Offers point `index` of `points` (already measured) and its codec.
  void Offer(const std::vector<SweepPoint>& points, std::size_t index, Codec&& codec) {
    const SweepPoint& p = points[index];
    const bool within = p.rel_l2 && *p.rel_l2 <= max_rel_error_;
    auto it = chosen_.find(p.method);
    bool take = it == chosen_.end();
    if (!take) {
      const SweepPoint& q = points[it->second.index];
      take = within ? (!it->second.within || p.bytes < q.bytes) : (!it->second.within && p.error < q.error);
    }
    if (take) chosen_.insert_or_assign(p.method, Chosen{index, within, std::move(codec)});
  }
  const Chosen* Find(const std::string& method) const {
    const auto it = chosen_.find(method);
    return it == chosen_.end() ? nullptr : &it->second;
  }

 private:
  double max_rel_error_;
  std::map<std::string, Chosen> chosen_;
};

// Phases 2 and 3 for every setting, in order; codecs kept (files) and offered for rendering.
std::vector<SweepPoint> MeasureSettings(const SlotSource& truth, const SweepOptions& o,
                                        const OutputFolder& out, const Reporter& reporter,
                                        RenderChoice& choice, double* psnr_peak) {
  const std::vector<SweepPoint> todo = Settings(o);
  std::vector<SweepPoint> points;
  for (std::size_t i = 0; i < todo.size(); ++i) {
    reporter.Progress(i, todo.size(), "sweep");
    SweepPoint p = todo[i];
    Dataset decoded;
    Codec codec = CompressAndTime(truth, o, p, decoded);
    for (const auto& w : p.warnings) reporter.Warn("{}: {}", PointName(p), w);
    *psnr_peak = Evaluate(truth, decoded, o, p);
    if (o.keep_codecs) KeepCodec(out, codec, p);
    reporter.Info("{}: {} bytes (ratio {:.1f}), compress {:.4g} s, decode {:.4g} s, {} {:.5g}", PointName(p), p.bytes,
                  p.ratio_float32, p.compress_s, p.decode_s, o.error_metric, p.error);
    points.push_back(std::move(p));
    if (o.render) choice.Offer(points, points.size() - 1, std::move(codec));
  }
  reporter.Progress(todo.size(), todo.size(), "sweep");
  return points;
}

// ---- Phase 4: Pareto fronts and plots. ----

void MarkParetoFronts(std::vector<SweepPoint>& points, std::vector<int>* fb, std::vector<int>* fc,
                      std::vector<int>* fd) {
  std::vector<double> err, bytes, ct, dt;
  for (const auto& p : points)
    err.push_back(p.error), bytes.push_back(double(p.bytes)), ct.push_back(p.compress_s), dt.push_back(p.decode_s);
  *fb = ParetoFront(bytes, err), *fc = ParetoFront(ct, err), *fd = ParetoFront(dt, err);
  for (int i : *fb) points[i].pareto_bytes = true;
  for (int i : *fc) points[i].pareto_compress = true;
  for (int i : *fd) points[i].pareto_decode = true;
}

// One plot of error against a cost, one series per (method, k), Pareto front marked.
Plot CostPlot(const std::vector<SweepPoint>& points, const std::string& title, const std::string& x_label,
              const std::string& y_label, double SweepPoint::*cost_d, std::uint64_t SweepPoint::*cost_u,
              const std::vector<int>& front, bool join) {
  Plot plot;
  plot.title = title;
  plot.x_label = x_label;
  plot.y_label = y_label;
  plot.log_x = plot.log_y = true;
  std::map<std::string, int> series_of;
  auto cost = [&](const SweepPoint& p) { return cost_d ? p.*cost_d : double(p.*cost_u); };
  for (const auto& p : points) {
    const std::string key = Clustered(p.method) ? fmt::format("{} k={}", p.method, p.clusters) : p.method;
    if (!series_of.count(key)) {
      series_of[key] = int(plot.series.size());
      PlotSeries s;
      s.name = key;
      s.color = SeriesColor(int(plot.series.size()));
      s.shape = int(plot.series.size());
      s.line = join;
      plot.series.push_back(s);
    }
    auto& s = plot.series[series_of[key]];
    s.x.push_back(cost(p));
    s.y.push_back(p.error);
    s.labels.push_back(fmt::format("c{}", p.components));
  }
  PlotSeries pf;
  pf.name = "Pareto front";
  pf.color = Color{0, 0, 0};
  pf.line = true;
  pf.ring_markers = true;
  for (int i : front) pf.x.push_back(cost(points[i])), pf.y.push_back(points[i].error);
  plot.series.push_back(pf);
  return plot;
}

std::vector<std::pair<std::string, Plot>> MakePlots(std::vector<SweepPoint>& points, const std::string& metric) {
  std::vector<int> fb, fc, fd;
  MarkParetoFronts(points, &fb, &fc, &fd);
  const std::string y = metric == "rel" ? "relative L2 error" : "RMSE";
  return {{"error_vs_bytes", CostPlot(points, y + " vs stored bytes", "stored bytes", y, nullptr, &SweepPoint::bytes, fb, true)},
          {"error_vs_compress_time", CostPlot(points, y + " vs compression time", "compression time (s, median)", y,
                                              &SweepPoint::compress_s, nullptr, fc, false)},
          {"error_vs_decode_time", CostPlot(points, y + " vs decoding time", "decoding time (s, median)", y,
                                            &SweepPoint::decode_s, nullptr, fd, false)}};
}

void WritePlots(const OutputFolder& out, const std::vector<std::pair<std::string, Plot>>& plots,
                std::vector<std::string>& files) {
  for (const auto& [name, plot] : plots) {
    WriteTextFileAtomic(out.Work(name + ".svg"), PlotSvg(plot));
    files.push_back(out.Final(name + ".svg"));
  }
}

// ---- Phase 6 (viewer_dir): renderer exports of the rendered codecs and the viewer beside them. ----

// The viewer's files the page loads (index.html's import map), copied with the same relative paths.
constexpr const char* kViewerFiles[] = {"index.html", "viewer.js", "node_modules/three/LICENSE",
                                        "node_modules/three/build/three.module.js",
                                        "node_modules/three/build/three.core.js",
                                        "node_modules/three/examples/jsm/controls/OrbitControls.js"};

std::vector<SweepViewerExport> ExportForViewer(const std::vector<SweepPoint>& points, const RenderChoice& choice,
                                               const SweepOptions& o, const OutputFolder& out,
                                               const Reporter& reporter, std::vector<std::string>& files) {
  std::vector<SweepViewerExport> exports;
  for (const auto& m : o.methods) {
    const RenderChoice::Chosen* chosen = choice.Find(m);
    if (!chosen) continue;
    const Codec& codec = chosen->codec;
    if ((m != "lpca" && m != "pca-view") || codec.transform() != ValueTransform::kNone) {
      reporter.Warn("viewer: {} is not exported (renderer exports take lpca and pca-view codecs without --log)",
                    PointName(points[chosen->index]));
      continue;
    }
    SweepViewerExport e;
    e.method = m;
    e.label = PointName(points[chosen->index]);
    const std::string rel = "viewer/exports/" + e.label;
    std::filesystem::create_directories(out.Work("viewer/exports"));
    if (m == "lpca") {
      ExportSchneider({}, codec, out.Work(rel));
      e.layout = kSchneiderLayout;
    } else {
      ExportSattler({}, codec, out.Work(rel));
      e.layout = kSattlerLayout;
    }
    e.directory = out.Final(rel);
    e.page = "viewer/index.html?export=exports/" + e.label + "/";
    files.push_back(e.directory);
    exports.push_back(e);
  }
  for (const char* f : kViewerFiles) {
    const std::filesystem::path to = out.Work("viewer") / f;
    std::filesystem::create_directories(to.parent_path());
    const std::string bytes = ReadFileBytes(std::filesystem::path(o.viewer_dir) / f, "viewer file");
    WriteFileAtomic(to, bytes.data(), bytes.size());
  }
  files.push_back(out.Final("viewer/index.html"));
  return exports;
}

// ---- Phase 5: rendered comparisons, ground truth (the dataset) against each method's choice. ----

std::vector<SweepRender> RenderComparisons(const Dataset& data, const std::vector<SweepPoint>& points,
                                           const RenderChoice& choice, const SweepOptions& o,
                                           const OutputFolder& out, const Reporter& reporter,
                                           std::vector<std::string>& files) {
  std::vector<SweepRender> renders;
  const auto gt = DatasetEvaluator(data);
  bool warned = false;
  const std::pair<const char*, const char*> panels[] = {{"patch", "point"}, {"cylinder", "environment"}};
  for (const auto& [scene, lighting] : panels) {
    RenderOptions ro = o.render_options;
    ro.scene = scene;
    ro.lighting = lighting;
    const Image truth_img = Render(*gt, ro);
    for (const auto& m : o.methods) {
      const RenderChoice::Chosen* chosen = choice.Find(m);
      if (!chosen) continue;
      const std::string label = PointName(points[chosen->index]);
      const Image test_img = Render(*CodecEvaluator(chosen->codec), ro);
      SweepRender r;
      r.method = m, r.label = label, r.scene = scene, r.lighting = lighting;
      PanelStats ps;
      const Image panel = ComparisonPanel(truth_img, test_img, "ground truth", "decoded " + label, 0.1, &ps);
      if (!ps.labelled && !warned) {
        reporter.Warn("no font for the labels of the rendered comparisons (install fonts-dejavu-core or set "
                      "BTF_FONT): the PNG panels are written without text");
        warned = true;
      }
      r.max_rel_diff = ps.max_rel_diff;
      r.mean_rel_diff = ps.mean_rel_diff;
      const std::string name = fmt::format("render_{}_{}_{}.png", m, scene, lighting);
      r.file = out.Final(name);
      WritePng(out.Work(name), panel);
      files.push_back(r.file);
      renders.push_back(r);
    }
  }
  return renders;
}

// ---- Phase 6: the HTML report, one function per section. ----

std::string ReportHead(const SweepSummary& s) {
  return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>libbtf codec sweep: " +
         EscapeXml(s.dataset) +
         "</title>\n<style>body{font-family:sans-serif;margin:24px;max-width:1500px;color:#222}"
         "table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #bbb;padding:3px 7px;text-align:right}"
         "th{background:#eee}td.l{text-align:left}tr.front td{background:#fff6d5}"
         ".plots{display:flex;flex-wrap:wrap;gap:12px}"
         "figure{margin:0 0 14px 0;border:1px solid #ccc;padding:6px;background:#fff}"
         "figure.plot{flex:0 1 540px;box-sizing:border-box}figure svg{display:block;width:100%;height:auto}"
         "figure.render{width:fit-content}"
         "figure img{display:block;max-width:100%}figcaption{font-size:13px;margin-top:4px;line-height:1.5}"
         ".key{font-size:15px}code{background:#f3f3f3;padding:1px 4px}</style></head><body>\n"
         "<h1>Codec sweep: error against size and run time</h1>\n";
}

std::string ReportIntro(const SweepSummary& s, const SweepOptions& o) {
  std::string h = fmt::format(
      "<p>Dataset <code>{}</code>: {} views &times; {} lights &times; {}&times;{} texels &times; {} channels, "
      "{:.3f} MB as float32. {} settings, each timed over {} run(s) (median). Error metric on the plots: "
      "<b>{}</b>. PSNR peak: {:.6g} (the reference's maximum value).</p>\n",
      EscapeXml(s.dataset), s.views, s.lights, s.width, s.height, s.channels, s.raw_float32_bytes / 1e6,
      s.points.size(), o.runs,
      s.error_metric == "rel" ? "relative L2 error ||decoded - truth|| / ||truth||" : "RMSE", s.psnr_peak);
  if (!o.command_line.empty()) h += "<p>Made by <code>" + EscapeXml(o.command_line) + "</code></p>\n";
  return h;
}

std::string ReportPlots(const std::vector<std::pair<std::string, Plot>>& plots) {
  std::string h =
      "<h2>Plots</h2>\n<p>Labels cN next to the markers give the components c (neural: the latent width). On the size plot, lines join the "
      "settings of one method (and cluster count) in order of c; black rings and the black line mark the Pareto "
      "front (no other setting is both cheaper and more accurate).</p>\n<div class=\"plots\">\n";
  for (const auto& [name, plot] : plots) h += PlotFigureHtml(plot);
  return h + "</div>\n";
}

std::string ReportTable(const SweepSummary& s) {
  std::string h =
      "<h2>Results</h2>\n<p>bytes = stored coefficient arrays (Codec::StoredBytes); ratio = float32 raw size "
      "/ bytes; times in seconds (median); &#9733; = on the Pareto front of error against bytes (B), compression "
      "time (C) or decoding time (D).</p>\n"
      "<table><tr><th>method</th><th>k</th><th>c</th><th>stored k/c</th><th>bytes</th><th>ratio</th>"
      "<th>compress s</th><th>decode s</th><th>RMSE</th><th>rel L2</th><th>PSNR dB</th><th>SSIM</th>"
      "<th>max abs</th><th>Pareto</th></tr>\n";
  for (const auto& p : s.points) {
    const bool any = p.pareto_bytes || p.pareto_compress || p.pareto_decode;
    const std::string marks = std::string(p.pareto_bytes ? "B" : "") + (p.pareto_compress ? "C" : "") +
                              (p.pareto_decode ? "D" : "");
    h += fmt::format(
        "<tr{}><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}{}</td><td>{}</td><td>{:.1f}</td><td>{:.4g}</td>"
        "<td>{:.4g}</td><td>{:.4g}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.4g}</td><td>{}</td></tr>\n",
        any ? " class=\"front\"" : "", p.method, p.clusters ? std::to_string(p.clusters) : "-", p.components,
        p.stored_clusters ? std::to_string(p.stored_clusters) + "/" : "", p.stored_components, p.bytes, p.ratio_float32,
        p.compress_s, p.decode_s, p.rmse, p.rel_l2 ? fmt::format("{:.4g}", *p.rel_l2) : "-",
        p.psnr_db ? fmt::format("{:.2f}", *p.psnr_db) : "inf", p.mean_ssim ? fmt::format("{:.4f}", *p.mean_ssim) : "-",
        p.max_abs, any ? "&#9733; " + marks : "");
  }
  return h + "</table>\n";
}

// What lights a panel, for its caption.
std::string LightingText(const SweepRender& r, const RenderOptions& ro) {
  if (r.lighting == "environment")
    return fmt::format("the procedural &ldquo;{}&rdquo; environment ({} fixed directions, no visibility)",
                       ro.environment, ro.environment_samples);
  const Vec3& l = ro.light_position;
  const double elevation = RadToDeg(std::atan2(l.z(), std::hypot(l.x(), l.y())));
  return fmt::format("a point light at ({:g}, {:g}, {:g}), {:.0f}&deg; above the horizon seen from the centre",
                     l.x(), l.y(), l.z(), elevation);
}

std::string ReportRenders(const SweepSummary& s, const SweepOptions& o, const OutputFolder& out) {
  if (s.renders.empty()) return {};
  std::string h =
      "<h2>Rendered comparison</h2>\n<p>Each picture: ground truth | decoded | difference. Ground truth = the "
      "dataset, interpolated between its sampled directions (barycentric over the three nearest views &times; "
      "lights, nearest texel); decoded = the codec's own arbitrary-direction decoder. For each method the smallest "
      "setting with a relative error of at most " +
      fmt::format("{:g} %", 100 * o.render_max_rel_error) +
      " is shown (else the most accurate one). Both images share one exposure; the difference is |decoded &minus; "
      "truth| in luminance relative to the truth's 99th-percentile luminance, in the viridis colour map from dark "
      "blue (0) to yellow (10 % or more). The camera is at (0, &minus;3.2, 2.6) looking at the origin; the patch is "
      "a flat 2 &times; 2 square, the cylinder has radius 0.6 and length 2 (Sattler et al. 2003, section 5, for "
      "the environment integration).</p>\n<div class=\"renders\">\n";
  for (const auto& r : s.renders)
    h += fmt::format("<figure class=\"render\"><img alt=\"{0}: {1}, {2} light\" src=\"data:image/png;base64,{3}\">"
                     "<figcaption><b>{0}</b>: {1} under {4}. Largest difference {5:.3g} %, mean {6:.3g} %."
                     "</figcaption></figure>\n",
                     EscapeXml(r.label), r.scene, r.lighting, Base64(ReadFileBytes(out.Work(std::filesystem::path(r.file).filename().string()), "render")),
                     LightingText(r, o.render_options), 100 * r.max_rel_diff, 100 * r.mean_rel_diff);
  return h + "</div>\n";
}

std::string ReportMetrics() {
  return "<h2>Metrics</h2>\n<ul>"
         "<li>RMSE = sqrt(mean over all values of (decoded &minus; truth)&sup2;)</li>"
         "<li>relative L2 = ||decoded &minus; truth||<sub>2</sub> / ||truth||<sub>2</sub> over all values</li>"
         "<li>PSNR = 10 log<sub>10</sub>(peak&sup2; / MSE), peak = the truth's maximum value</li>"
         "<li>SSIM: mean over images, texels and channels of Wang et al. (2004) SSIM with a Gaussian window "
         "(&sigma; = 1.5 texels, truncated at 3&sigma;), C1 = (0.01 peak)&sup2;, C2 = (0.03 peak)&sup2;</li>"
         "<li>Times: wall clock on this machine, median of the runs; compression from an in-memory dataset, decoding "
         "of the whole BTF to memory (Codec::DecodeAll; each run repeats it for at least 20 ms and reports the time "
         "per decode). Other processes on the machine add noise.</li></ul>\n"
         "<p>Data: <code>results.json</code> next to this file. Definitions: docs/btf-eval.md.</p>\n</body></html>\n";
}

std::string ReportViewer(const SweepSummary& s) {
  if (s.viewer_exports.empty()) return {};
  std::string h =
      "<h2>Viewer</h2>\n<p>The rendered codecs exported for real-time rendering (docs/viewer.md) and drawn by the "
      "WebGL2 viewer in <code>viewer/</code> beside this report. Browsers do not load its files from "
      "<code>file://</code>: serve this folder over HTTP (any static server) to use the links and the frame below, "
      "or run <code>btf-eval view viewer/exports/SETTING</code> here.</p>\n<ul>\n";
  for (const auto& e : s.viewer_exports)
    h += fmt::format("<li><a href=\"{0}\">{1}</a> ({2} export in <code>viewer/exports/{1}/</code>)</li>\n",
                     EscapeXml(e.page), EscapeXml(e.label), e.layout);
  return h + fmt::format("</ul>\n<iframe title=\"viewer: {}\" src=\"{}\" width=\"800\" height=\"500\"></iframe>\n",
                         EscapeXml(s.viewer_exports.front().label), EscapeXml(s.viewer_exports.front().page));
}

std::string ReportHtml(const SweepSummary& s, const SweepOptions& o,
                       const std::vector<std::pair<std::string, Plot>>& plots, const OutputFolder& out) {
  return ReportHead(s) + ReportIntro(s, o) + ReportPlots(plots) + ReportTable(s) + ReportRenders(s, o, out) +
         ReportViewer(s) + ReportMetrics();
}

// results.json and report.html (last), added to the summary's files.
void WriteResultsAndReport(const OutputFolder& out, const SweepOptions& o,
                           const std::vector<std::pair<std::string, Plot>>& plots, SweepSummary& s) {
  s.report = out.Final("report.html");
  s.files.push_back(out.Final("results.json"));
  s.files.push_back(s.report);
  WriteTextFileAtomic(out.Work("results.json"), s.ToJson().dump(2));
  WriteTextFileAtomic(out.Work("report.html"), ReportHtml(s, o, plots, out));
}

}  // namespace

nlohmann::json SweepPoint::ToJson() const {
  nlohmann::json j;
  j["method"] = method;
  j["params"] = {{"components", components}, {"clusters", Clustered(method) ? nlohmann::json(clusters) : nlohmann::json(nullptr)}};
  j["stored"] = {{"components", stored_components}, {"clusters", Clustered(method) ? nlohmann::json(stored_clusters) : nlohmann::json(nullptr)}};
  j["bytes"] = bytes;
  j["file_bytes"] = file_bytes;
  j["ratio"] = ratio_float32;
  j["ratio_half"] = ratio_half;
  j["compress_s"] = compress_s;
  j["decode_s"] = decode_s;
  j["compress_runs_s"] = compress_runs;
  j["decode_runs_s"] = decode_runs;
  j["errors"] = {{"rmse", rmse}, {"rel_l2", Opt(rel_l2)}, {"psnr_db", Opt(psnr_db)}, {"mean_ssim", Opt(mean_ssim)},
                 {"max_abs", max_abs}};
  j["error"] = error;
  j["pareto"] = {{"bytes", pareto_bytes}, {"compress_time", pareto_compress}, {"decode_time", pareto_decode}};
  j["warnings"] = warnings;
  j["codec_file"] = codec_file;
  return j;
}

std::string SweepSummary::Report() const {
  std::string r = fmt::format("{:<22} {:>10} {:>7} {:>11} {:>11} {:>11} {:>8} {:>9}\n", "setting", "bytes", "ratio",
                              "compress s", "decode s", error_metric, "PSNR dB", "Pareto");
  for (const auto& p : points)
    r += fmt::format("{:<22} {:>10} {:>7.1f} {:>11.4g} {:>11.4g} {:>11.4g} {:>8} {:>9}\n",
                     Clustered(p.method) ? fmt::format("{} k={} c={}", p.method, p.clusters, p.components)
                                        : fmt::format("{} c={}", p.method, p.components),
                     p.bytes, p.ratio_float32, p.compress_s, p.decode_s, p.error,
                     p.psnr_db ? fmt::format("{:.2f}", *p.psnr_db) : "inf",
                     std::string(p.pareto_bytes ? "B" : "") + (p.pareto_compress ? "C" : "") + (p.pareto_decode ? "D" : ""));
  return r + fmt::format("report: {}\n", report);
}

nlohmann::json SweepSummary::ToJson() const {
  nlohmann::json j;
  j["dataset"] = dataset;
  j["output_dir"] = output_dir;
  j["shape"] = {{"views", views}, {"lights", lights}, {"height", height}, {"width", width}, {"channels", channels}};
  j["raw_float32_bytes"] = raw_float32_bytes;
  j["error_metric"] = error_metric;
  j["psnr_peak"] = psnr_peak;
  j["psnr_peak_definition"] = "max reference value";
  j["points"] = nlohmann::json::array();
  for (const auto& p : points) j["points"].push_back(p.ToJson());
  j["renders"] = nlohmann::json::array();
  for (const auto& r : renders)
    j["renders"].push_back({{"method", r.method}, {"label", r.label}, {"scene", r.scene}, {"lighting", r.lighting},
                            {"file", r.file}, {"max_rel_diff", r.max_rel_diff}, {"mean_rel_diff", r.mean_rel_diff}});
  j["viewer_exports"] = nlohmann::json::array();
  for (const auto& e : viewer_exports)
    j["viewer_exports"].push_back({{"method", e.method}, {"label", e.label}, {"layout", e.layout},
                                   {"directory", e.directory}, {"page", e.page}});
  j["files"] = files;
  j["report"] = report;
  j["seconds"] = times.ToJson();
  return j;
}

SweepSummary RunSweep(const SweepOptions& o, const std::filesystem::path& dataset_path, const std::filesystem::path& dir,
                      const Reporter& reporter) {
  o.Check();
  Timer timer;
  RequireEveryImage(DatasetReader(dataset_path).header(), "a sweep compresses and renders every image");
  const Dataset data = ReadDataset(dataset_path);
  const auto truth = MemorySource(data, dataset_path.string());
  // NaN/Inf refused up front with the item named (Compress would too, but only for the first method).
  for (int v = 0; v < data.num_views(); ++v) CheckFiniteSlot(*truth, v, data.view_slot(v).data());
  AtomicDirectory folder(dir, "results.json");
  const OutputFolder out{folder.temp_path(), dir};
  if (o.keep_codecs) std::filesystem::create_directories(out.Work("codecs"));
  SweepSummary s = Describe(dataset_path, dir, data, o);
  s.times.Add("read", timer.Seconds());

  timer.Restart();
  RenderChoice choice(o.render_max_rel_error);
  s.points = MeasureSettings(*truth, o, out, reporter, choice, &s.psnr_peak);
  s.times.Add("sweep", timer.Seconds());

  timer.Restart();
  const auto plots = MakePlots(s.points, o.error_metric);
  WritePlots(out, plots, s.files);
  s.times.Add("plots", timer.Seconds());

  if (o.render) {
    timer.Restart();
    s.renders = RenderComparisons(data, s.points, choice, o, out, reporter, s.files);
    s.times.Add("render", timer.Seconds());
  }
  if (!o.viewer_dir.empty()) {
    timer.Restart();
    s.viewer_exports = ExportForViewer(s.points, choice, o, out, reporter, s.files);
    s.times.Add("viewer", timer.Seconds());
  }

  timer.Restart();
  WriteResultsAndReport(out, o, plots, s);
  folder.Commit();
  s.times.Add("report", timer.Seconds());
  return s;
}

}  // namespace btf
