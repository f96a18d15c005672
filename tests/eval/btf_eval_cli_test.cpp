// btf-eval as a user runs it: exit codes, JSON, the files a sweep writes.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/export/sattler_reference_decoder.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/image_io.h"
#include "tests/codec_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

std::string Q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

TEST(BtfEvalCli, CompareExitCodesAndJson) {
  const auto dir = test::TempDir();
  const std::string tool = test::Tool("btf-eval");
  const Dataset ref = test::MakeTestDataset(2, 3, 4, 5);
  Dataset t = ref;
  for (auto& v : t.data()) v += 0.01f;
  WriteDataset(dir / "ref.h5", ref);
  WriteDataset(dir / "t.h5", t);
  std::string out;
  // rmse = 0.01 (values shifted by 0.01; float rounding below 1e-6).
  ASSERT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "t.h5") +
                                 " --json --metric rmse --warn 0.005 --fail 0.02 2>" + Q(dir / "err.txt"),
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_NEAR(j["rmse"].get<double>(), 0.01, 1e-6);
  EXPECT_EQ(j["verdict"], "warn");
  std::ifstream err(dir / "err.txt");
  const std::string err_text((std::istreambuf_iterator<char>(err)), {});
  EXPECT_NE(err_text.find("warning threshold"), std::string::npos) << err_text;
  // Over --fail: exit 1.
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "t.h5") +
                             " --metric rmse --fail 0.005 -q >/dev/null 2>&1"),
            1);
  // PSNR thresholds fail below: PSNR here is about 20 log10(1.6 / 0.01) = 44 dB.
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "t.h5") +
                             " --metric psnr --fail 60 -q >/dev/null 2>&1"),
            1);
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "t.h5") +
                             " --metric psnr --fail 30 -q >/dev/null 2>&1"),
            0);
  // A NaN in the test input: exit 3 with the item named.
  t.at(1, 2, 3, 4, 0) = std::numeric_limits<float>::quiet_NaN();
  WriteDataset(dir / "nan.h5", t);
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "nan.h5") + " 2>&1", &out), 3);
  EXPECT_NE(out.find("holds NaN at view 1, light 2, texel (y 3, x 4), channel 0"), std::string::npos) << out;
  // Incompatible shapes: exit 3.
  WriteDataset(dir / "small.h5", test::MakeTestDataset(2, 3, 4, 4));
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "small.h5") + " 2>&1", &out), 3);
  EXPECT_NE(out.find("shapes must match"), std::string::npos) << out;
  // Usage errors: exit 2; a missing file: exit 4.
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "t.h5") + " --metric foo 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(tool + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "none.h5") + " 2>/dev/null"), 4);
}

TEST(BtfEvalCli, CompareReadsCodecs) {
  const auto dir = test::TempDir();
  const Dataset ref = test::MakeTestDataset(2, 4, 6, 6);
  CompressOptions co;
  co.method = CodecMethod::kPcaView;
  co.components = 1;
  const Codec codec = test::CompressDataset(ref, co);
  WriteDataset(dir / "ref.h5", ref);
  WriteCodec(dir / "c.h5", codec);
  // The same figure as decoding in memory and comparing (both sides use the codec's decoder).
  const Dataset decoded = codec.DecodeAll();
  double sse = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) sse += std::pow(double(decoded.data()[i]) - ref.data()[i], 2);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "c.h5") +
                                 " --json --error-maps " + Q(dir / "maps") + " --maps 2",
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_NEAR(j["rmse"].get<double>(), std::sqrt(sse / double(ref.size())), 1e-9);
  ASSERT_EQ(j["error_maps"].size(), 2u);
  for (const auto& f : j["error_maps"]) EXPECT_TRUE(std::filesystem::exists(f.get<std::string>()));
}

TEST(BtfEvalCli, SweepWritesResultsPlotsAndReport) {
  const auto dir = test::TempDir();
  // 3 views x 4 lights x 8x8 texels: the default methods, a handful of settings, one timing run.
  WriteDataset(dir / "d.h5", test::MakeTestDataset(3, 4, 8, 8));
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " sweep " + Q(dir / "d.h5") + " -o " + Q(dir / "sweep") +
                                 " --components 1,2 --clusters 2,4 --runs 1 --render-size 40 --json -q",
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  // pca-view and neural (latent widths 1, 2): 2 settings each, lpca and lpca-tensor: 2 x 2.
  ASSERT_EQ(j["points"].size(), 2u + 2u * 2u + 2u * 2u + 2u);
  EXPECT_EQ(j["points"][10]["method"], "neural");
  EXPECT_EQ(j["points"][11]["stored"]["components"], 2);
  for (const auto& p : j["points"]) {
    EXPECT_GT(p["bytes"].get<double>(), 0);
    EXPECT_GT(p["compress_s"].get<double>(), 0);
    EXPECT_GT(p["decode_s"].get<double>(), 0);
    EXPECT_GE(p["errors"]["rmse"].get<double>(), 0);
    EXPECT_TRUE(std::filesystem::exists(p["codec_file"].get<std::string>()));
  }
  // More components never increase the error of pca-view (nested PCA subspaces).
  EXPECT_LE(j["points"][1]["errors"]["rmse"].get<double>(), j["points"][0]["errors"]["rmse"].get<double>() + 1e-9);
  // At least one point is on each Pareto front.
  for (const char* front : {"bytes", "compress_time", "decode_time"}) {
    int n = 0;
    for (const auto& p : j["points"]) n += p["pareto"][front].get<bool>();
    EXPECT_GE(n, 1) << front;
  }
  for (const char* f : {"results.json", "report.html", "error_vs_bytes.svg", "error_vs_compress_time.svg",
                        "error_vs_decode_time.svg"})
    EXPECT_TRUE(std::filesystem::exists(dir / "sweep" / f)) << f;
  // Plots are SVG only: the only PNGs are the rendered comparisons, and `files` lists what exists.
  std::set<std::string> pngs;
  for (const auto& e : std::filesystem::directory_iterator(dir / "sweep"))
    if (e.path().extension() == ".png") pngs.insert(e.path().filename().string());
  EXPECT_EQ(pngs, (std::set<std::string>{"render_lpca_cylinder_environment.png", "render_lpca_patch_point.png",
                                         "render_lpca-tensor_cylinder_environment.png", "render_lpca-tensor_patch_point.png",
                                         "render_pca-view_cylinder_environment.png", "render_pca-view_patch_point.png",
                                         "render_neural_cylinder_environment.png", "render_neural_patch_point.png"}));
  for (const auto& f : j["files"]) {
    const std::filesystem::path file = f.get<std::string>();
    EXPECT_TRUE(std::filesystem::exists(file)) << file;
    if (file.filename().string().rfind("error_vs_", 0) == 0) {
      EXPECT_EQ(file.extension(), ".svg") << file;
    }
  }
  EXPECT_EQ(j["renders"].size(), 8u);  // 4 methods x (patch + point, cylinder + environment)
  // The report is self-contained: the plots are inline SVG figures with their text in captions,
  // the renders PNG data URIs; nothing refers to other files.
  std::ifstream in(dir / "sweep" / "report.html");
  const std::string html((std::istreambuf_iterator<char>(in)), {});
  std::size_t figures = 0;
  for (std::size_t pos = 0; (pos = html.find("<figure class=\"plot\">\n<svg", pos)) != std::string::npos; ++pos) ++figures;
  EXPECT_EQ(figures, 3u);
  EXPECT_NE(html.find("<figcaption><b>relative L2 error vs stored bytes</b>"), std::string::npos);
  EXPECT_EQ(html.find("data:image/svg+xml"), std::string::npos);
  EXPECT_EQ(html.find(".svg\""), std::string::npos);
  EXPECT_NE(html.find("data:image/png;base64,"), std::string::npos);
  EXPECT_EQ(html.find("src=\"error_"), std::string::npos);
  EXPECT_EQ(html.find("src=\"render_"), std::string::npos);
  // The text table has the relative error and PSNR of each setting.
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " sweep " + Q(dir / "d.h5") + " -o " + Q(dir / "sweep2") +
                                 " --methods pca-view --components 1 --runs 1 --no-render --no-codecs -q",
                             &out),
            0);
  EXPECT_NE(out.find("PSNR dB"), std::string::npos) << out;
  EXPECT_NE(out.find(fmt::format("{:.2f}", j["points"][0]["errors"]["psnr_db"].get<double>())), std::string::npos) << out;
}

// --viewer: each method's rendered codec exported beside the report (lpca: schneider-2004,
// pca-view: sattler-2003; fmf has no renderer export and is left out with a warning), the
// viewer's page and three.js files copied byte for byte, and the report linking them. The
// exports are read back by their reference decoders; the sattler one equals the kept codec's
// Codec::Value (nearest texel) to its storage bound (+ 1e-5 for float arithmetic), at the
// sampled directions. (The viewer drawing both layouts is tested in tests/web.)
TEST(BtfEvalCli, SweepWithViewerExportsTheRenderedCodecsAndLinksTheViewer) {
  const auto dir = test::TempDir();
  WriteDataset(dir / "d.h5", test::MakeTestDataset(3, 4, 8, 8));
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " sweep " + Q(dir / "d.h5") + " -o " + Q(dir / "sweep") +
                                 " --methods pca-view,lpca,fmf --components 2 --clusters 2 --runs 1 --render-size 40"
                                 " --viewer --json 2>" + Q(dir / "err.txt"),
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  ASSERT_EQ(j["viewer_exports"].size(), 2u);
  EXPECT_EQ(j["viewer_exports"][0]["layout"], "sattler-2003");
  EXPECT_EQ(j["viewer_exports"][1]["layout"], "schneider-2004");
  std::ifstream err(dir / "err.txt");
  const std::string warnings((std::istreambuf_iterator<char>(err)), {});
  EXPECT_NE(warnings.find("viewer: fmf_c2 is not exported"), std::string::npos) << warnings;
  const auto viewer = dir / "sweep" / "viewer";
  for (const char* f : {"index.html", "viewer.js", "node_modules/three/build/three.module.js",
                        "node_modules/three/build/three.core.js", "node_modules/three/examples/jsm/controls/OrbitControls.js"})
    EXPECT_EQ(test::Slurp(viewer / f), test::Slurp(std::filesystem::path(test::SourceDir()) / "viewer" / f)) << f;
  const std::string html = test::Slurp(dir / "sweep" / "report.html");
  EXPECT_NE(html.find("<a href=\"viewer/index.html?export=exports/pca-view_c2/\">"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"viewer/index.html?export=exports/lpca_k2_c2/\">"), std::string::npos);
  EXPECT_NE(html.find("<iframe title=\"viewer: pca-view_c2\""), std::string::npos);
  EXPECT_NO_THROW(SchneiderReferenceDecoder{viewer / "exports" / "lpca_k2_c2"});
  const SattlerReferenceDecoder ref(viewer / "exports" / "pca-view_c2");
  const Codec codec = ReadCodec(dir / "sweep" / "codecs" / "pca-view_c2.h5");
  for (int v = 0; v < codec.num_views(); ++v)
    for (int l = 0; l < codec.num_lights(); ++l)
      for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x) {
          float a[3], b[3];
          ref.Value(x, y, codec.lights()[l], codec.views()[v], a);
          codec.Value(Vec2((x + 0.5) / 8, 1 - (y + 0.5) / 8), codec.lights()[l], codec.views()[v], b, UvFilter::kNearest);
          for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(a[c], b[c], ref.ErrorBound(codec.lights()[l], codec.views()[v]) + 1e-5);
        }
  // --viewer with --no-render has no rendered codecs to show: refused.
  EXPECT_EQ(test::RunCommand(test::Tool("btf-eval") + " sweep " + Q(dir / "d.h5") + " -o " + Q(dir / "s2") +
                                 " --components 2 --clusters 2 --runs 1 --no-render --viewer -q 2>&1", &out), 2);
  EXPECT_NE(out.find("viewer_dir"), std::string::npos) << out;
}

TEST(BtfEvalCli, SweepPlotsEveryCodecMethodOnOneSetOfAxes) {
  const auto dir = test::TempDir();
  WriteDataset(dir / "d.h5", test::MakeTestDataset(3, 4, 8, 8));
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " sweep " + Q(dir / "d.h5") + " -o " + Q(dir / "sweep") +
                                 " --methods pca-view,lpca,lpca-tensor,fmf --components 2 --clusters 2 --runs 1"
                                 " --no-render --json -q",
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  ASSERT_EQ(j["points"].size(), 4u);
  EXPECT_EQ(j["points"][2]["method"], "lpca-tensor");
  EXPECT_EQ(j["points"][2]["params"]["clusters"], 2);
  EXPECT_TRUE(std::filesystem::exists(dir / "sweep" / "codecs" / "lpca-tensor_k2_c2.h5"));
  // Every method is a series of each plot, and one Pareto front runs over all of them.
  for (const char* plot : {"error_vs_bytes.svg", "error_vs_compress_time.svg", "error_vs_decode_time.svg"}) {
    std::ifstream in(dir / "sweep" / plot);
    const std::string svg((std::istreambuf_iterator<char>(in)), {});
    for (const char* series : {"pca-view", "lpca k=2", "lpca-tensor k=2", "fmf", "Pareto front"})
      EXPECT_NE(svg.find(series), std::string::npos) << plot << " " << series;
  }
}

TEST(BtfEvalCli, SweepRefusesBadInputAndOptions) {
  const auto dir = test::TempDir();
  const std::string tool = test::Tool("btf-eval");
  Dataset d = test::MakeTestDataset(2, 3, 4, 4);
  WriteDataset(dir / "ok.h5", d);
  d.at(0, 1, 2, 3, 2) = std::numeric_limits<float>::quiet_NaN();
  WriteDataset(dir / "nan.h5", d);
  std::string out;
  EXPECT_EQ(test::RunCommand(tool + " sweep " + Q(dir / "nan.h5") + " -o " + Q(dir / "s") + " -q 2>&1", &out), 3);
  EXPECT_NE(out.find("holds NaN at view 0, light 1, texel (y 2, x 3), channel 2"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "s" / "report.html"));
  EXPECT_EQ(test::RunCommand(tool + " sweep " + Q(dir / "ok.h5") + " -o " + Q(dir / "s") + " --methods svd -q 2>&1", &out), 2);
  EXPECT_NE(out.find("svd"), std::string::npos) << out;
  EXPECT_EQ(test::RunCommand(tool + " sweep " + Q(dir / "ok.h5") + " -o " + Q(dir / "s") + " --runs 0 -q 2>/dev/null"), 2);
  EXPECT_EQ(test::RunCommand(tool + " sweep " + Q(dir / "ok.h5") + " -o " + Q(dir / "s") + " --components 0 -q 2>/dev/null"), 2);
}

TEST(BtfEvalCli, StabilityJson) {
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " stability --only input/ directions/ --json -q", &out), 0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["failed"], 0);
  EXPECT_EQ(j["passed"], 3);
}

// render (CPU) of a codec; the usage and bad-input errors of render, render-web and view, which
// all come before any browser starts (so these run without Chromium).
TEST(BtfEvalCli, RenderWritesAnSrgbPngAndTheSceneCommandsRefuseBadInput) {
  const auto dir = test::TempDir();
  const std::string tool = test::Tool("btf-eval");
  CompressOptions o;
  o.components = 2;
  WriteCodec(dir / "c.h5", test::CompressDataset(test::MakeTestDataset(5, 5, 4, 4), o));
  std::string out;
  ASSERT_EQ(test::RunCommand(tool + " render " + Q(dir / "c.h5") + " -o " + Q(dir / "cpu.png") +
                                 " --scene cylinder-env --size 40x30 --exposure 2 --json",
                             &out),
            0)
      << out;
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["source_kind"], "codec");
  EXPECT_EQ(j["scene"], "cylinder-env");
  EXPECT_EQ(j["exposure"], 2.0);
  const Image img = ReadImage(dir / "cpu.png");
  EXPECT_EQ(img.width, 40);
  EXPECT_EQ(img.height, 30);
  const auto run = [&](const std::string& args) { return test::RunCommand(tool + " " + args + " 2>&1", &out); };
  EXPECT_EQ(run("render " + Q(dir / "c.h5") + " -o " + Q(dir / "x.png") + " --size 40by30"), 2) << out;
  EXPECT_NE(out.find("WIDTHxHEIGHT"), std::string::npos) << out;
  EXPECT_EQ(run("render " + Q(dir / "c.h5") + " -o " + Q(dir / "x.png") + " --scene teapot"), 2) << out;
  EXPECT_EQ(run("render " + Q(dir / "c.h5") + " -o " + Q(dir / "x.png") + " --exposure 0"), 2) << out;
  EXPECT_EQ(run("render " + Q(dir / "cpu.png") + " -o " + Q(dir / "x.png")), 3) << out;  // not a BTF file
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
  // render-web and view: a folder without manifest.json is bad input; a missing Chromium or node is usage.
  std::filesystem::create_directories(dir / "not_export");
  EXPECT_EQ(run("render-web " + Q(dir / "not_export") + " -o " + Q(dir / "x.png")), 3) << out;
  EXPECT_NE(out.find("no manifest.json"), std::string::npos) << out;
  std::filesystem::create_directories(dir / "fake_export");
  std::ofstream(dir / "fake_export" / "manifest.json") << "{}";
  EXPECT_EQ(run("render-web " + Q(dir / "fake_export") + " -o " + Q(dir / "x.png") + " --chromium /nonexistent/chromium"), 2) << out;
  EXPECT_NE(out.find("Chromium not found"), std::string::npos) << out;
  EXPECT_EQ(run("view " + Q(dir / "fake_export") + " --port 0"), 2) << out;
  EXPECT_EQ(run("view " + Q(dir / "fake_export") + " --node /nonexistent/node --port 8999"), 2) << out;
  EXPECT_NE(out.find("cannot run '/nonexistent/node'"), std::string::npos) << out;
}

// OpenImageIO loads only with the image plugin, on the first image read or written: without the
// plugin a command writing an image fails with btf::Error (I/O, exit 4) saying what to do and
// writes nothing, while a command that touches no image runs as before.
TEST(BtfEvalCli, WithoutTheImagePluginOnlyImageCommandsFailAndSayWhatToDo) {
  const auto dir = test::TempDir();
  const std::string tool = test::Tool("btf-eval");
  CompressOptions o;
  o.components = 2;
  const Dataset ref = test::MakeTestDataset(5, 5, 4, 4);
  WriteDataset(dir / "ref.h5", ref);
  WriteCodec(dir / "c.h5", test::CompressDataset(ref, o));
  std::filesystem::create_directories(dir / "empty");
  const std::string no_plugin = "BTF_PLUGIN_DIR=" + Q(dir / "empty") + " " + tool;
  std::string out;
  EXPECT_EQ(test::RunCommand(no_plugin + " render " + Q(dir / "c.h5") + " -o " + Q(dir / "x.png") + " --size 16x12 2>&1", &out),
            4)
      << out;
  for (const std::string& part : {std::string("libbtf_oiio.so"), (dir / "empty").string(), std::string("BTF_PLUGIN_DIR")})
    EXPECT_NE(out.find(part), std::string::npos) << out << " / " << part;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
  EXPECT_EQ(test::RunCommand(no_plugin + " compare " + Q(dir / "ref.h5") + " " + Q(dir / "c.h5") + " -q 2>&1", &out), 0)
      << out;
  // The build tree's plugin, found from the tool's folder.
  EXPECT_EQ(test::RunCommand(tool + " render " + Q(dir / "c.h5") + " -o " + Q(dir / "x.png") + " --size 16x12 -q 2>&1", &out), 0)
      << out;
  EXPECT_EQ(ReadImage(dir / "x.png").width, 16);
}

}  // namespace
}  // namespace btf
