// btf-compress: per-view PCA, local-PCA and full-matrix factorisation codecs, decoding, renderer
// export (docs/btf-compress.md).
//   btf-compress DATASET --method pca-view|lpca|lpca-tensor|fmf|dfmf|neural [...] -o codec.h5
//   btf-compress decode CODEC -o dataset.h5
//   btf-compress export CODEC [--format schneider|sattler|neural] -o DIR
#include <optional>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/codec_source.h"
#include "libbtf/compress/compress.h"
#include "libbtf/export/neural.h"
#include "libbtf/export/sattler.h"
#include "libbtf/export/schneider.h"
#include "libbtf/io/bonn.h"
#include "tools/common/cli.h"

namespace {

struct CompressFlags {
  std::string dataset, output, method = btf::MethodName(btf::CompressOptions().method), scene;
  std::string storage = btf::StorageName(btf::CompressOptions().storage);
  btf::CompressOptions options;
};

struct DecodeFlags {
  std::string codec, output;
};

struct ExportFlags {
  std::string codec, output, format;  // schneider, sattler or neural (CLI-checked); empty: by the codec's method
  btf::SchneiderExportOptions options;
  bool grids_given = false;  // --view-grid / --light-grid (schneider only)
  bool storage_given = false;  // --components / --storage / --atlas-side (not for neural)
};

// The export format of a codec when --format is not given: by its method.
std::string DefaultExportFormat(btf::CodecMethod method) {
  if (method == btf::CodecMethod::kPcaView) return "sattler";
  if (method == btf::CodecMethod::kNeural) return "neural";
  return "schneider";
}

int RunCompress(const CLI::App& app, const btf::cli::CommonFlags& common, CompressFlags& f) {
  if (f.dataset.empty()) btf::ThrowUsage("give a DATASET to compress, or a subcommand (decode, export); see --help");
  if (f.output.empty()) btf::ThrowUsage("-o/--output is required when compressing");
  f.options.method = btf::ParseMethod(f.method);
  f.options.storage = btf::ParseStorage(f.storage);
  btf::CheckOutput(f.output, {f.dataset, f.scene});
  if (!f.scene.empty()) f.options.scene = btf::SceneSpec::Load(f.scene);
  // pca-view, lpca, fmf, dfmf and neural split their work over MPI ranks (docs/scaling.md); rank 0
  // alone writes.
  if (f.options.method == btf::CodecMethod::kLpcaTensor) btf::cli::RequireSingleRank("btf-compress --method " + f.method);
  // Claim the output before the work: an unwritable folder fails now, not after the compression.
  std::optional<btf::AtomicOutput> target;
  if (btf::cli::PrintingRank()) target.emplace(f.output, btf::AtomicOutput::kReserve);
  // A dataset file or a Bonn .btf file (decoded one view slot at a time).
  const auto input = btf::OpenCompressInput(f.dataset, btf::cli::DatasetReadOptionsFromEnvironment());
  const btf::CompressSummary s = btf::CompressToFile(f.options, *input, target ? &*target : nullptr, "btf-compress",
                                                     btf::cli::MakeReporter(common));
  btf::cli::PrintSummary(app, common, s, {{"output", f.output}});
  if (!common.json && btf::cli::PrintingRank()) fmt::print("  output                {}\n", f.output);
  return 0;
}

int RunDecode(const CLI::App& app, const btf::cli::CommonFlags& common, const DecodeFlags& f) {
  btf::cli::RequireSingleRank("btf-compress decode");
  btf::CheckOutput(f.output, {f.codec});
  const btf::Codec codec = btf::ReadCodec(f.codec);
  const btf::DecodeSummary s = btf::DecodeToDatasetFile(codec, f.output, btf::cli::MakeReporter(common));
  btf::cli::PrintSummary(app, common, s, {{"codec", f.codec}});
  return 0;
}

int RunExport(const CLI::App& app, const btf::cli::CommonFlags& common, const ExportFlags& f) {
  btf::cli::RequireSingleRank("btf-compress export");
  btf::CheckOutput(f.output, {f.codec}, btf::OutputKind::kFolder);
  const btf::Codec codec = btf::ReadCodec(f.codec);
  const std::string format = !f.format.empty() ? f.format : DefaultExportFormat(codec.method());
  if (format == "neural") {
    if (f.grids_given || f.storage_given)
      btf::ThrowUsage("--view-grid, --light-grid, --components, --storage and --atlas-side belong to --format schneider "
                      "and sattler (a neural export keeps the codec's latents and decoder as stored)");
    const btf::NeuralExportSummary s = btf::ExportNeural(codec, f.output, btf::cli::MakeReporter(common));
    btf::cli::PrintSummary(app, common, s, {{"codec", f.codec}});
    return 0;
  }
  if (format == "schneider") {
    const btf::SchneiderExportSummary s =
        btf::ExportSchneider(f.options, codec, f.output, btf::cli::MakeReporter(common));
    btf::cli::PrintSummary(app, common, s, {{"codec", f.codec}});
    return 0;
  }
  if (f.grids_given) btf::ThrowUsage("--view-grid and --light-grid belong to --format schneider (sattler keeps the sampled directions)");
  btf::SattlerExportOptions o;
  o.components = f.options.components;
  o.storage = f.options.storage;
  o.atlas_side = f.options.atlas_side;
  const btf::SattlerExportSummary s = btf::ExportSattler(o, codec, f.output, btf::cli::MakeReporter(common));
  btf::cli::PrintSummary(app, common, s, {{"codec", f.codec}});
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Compress a BTF dataset with per-view PCA (Sattler 2003) or local PCA (Mueller 2003); decode codecs; "
               "export LPCA (Schneider 2004), pca-view (Sattler 2003) and neural codecs for real-time rendering.",
               "btf-compress"};
  btf::cli::Configure(app);
  app.require_subcommand(0, 1);
  app.fallthrough();
  btf::cli::CommonFlags common;
  btf::cli::AddCommonFlags(app, common);

  CompressFlags cf;
  btf::CompressOptions& co = cf.options;
  app.add_option("DATASET", cf.dataset, "Input dataset (.h5, libbtf-dataset) or Bonn .btf file");
  app.add_option("--method", cf.method, "pca-view | lpca | lpca-tensor (LPCA with factorised, quantised Eigen-ABRDFs) | fmf | dfmf (Bonn "
                 "full-matrix factorisation, per YUV channel for dfmf) | neural (per-texel latents and a decoder MLP, log domain)");
  app.add_option("--components,-c", co.components,
                 "Components per view slot (pca-view), per cluster (lpca) or of the SVD (fmf; per YUV channel for "
                 "dfmf); the maximum with --error/--energy");
  app.add_option("--clusters,-k", co.clusters, "LPCA clusters");
  app.add_option("--error", co.target_error, "Target relative RMS error per slot/cluster; lpca-tensor: of the whole codec (0 = use --components)");
  app.add_option("--energy", co.retained_energy, "Retained fraction of centred energy per slot/cluster (0 = off)");
  app.add_option("--bytes", co.max_bytes,
                 "Byte budget of the stored codec (0 = off): the smallest error within it (lpca-tensor: factor terms; "
                 "others: the largest -c that fits)");
  app.add_option("--quant-bits", co.tensor.quant_bits, "lpca-tensor: bits of the quantised factors and weights (8 or 16)");
  app.add_option("--tensor-growth", co.tensor.growth,
                 "lpca-tensor without --error/--bytes: allowed growth of the LPCA stage's squared error by dropped "
                 "factor terms");
  btf::NeuralOptions& no = co.neural;
  app.add_option("--neural-latent", no.latent, "neural: latent values per texel (the maximum with --bytes)");
  app.add_option("--neural-hidden", no.hidden, "neural: decoder hidden widths, a comma list")->delimiter(',');
  app.add_option("--neural-fourier", no.fourier, "neural: Fourier octaves of the direction encoding (0..8)");
  app.add_option("--neural-latent-storage", no.latent_storage,
                 "neural: uint8 (codes with a scale and bias per latent channel) or half");
  app.add_option("--neural-samples", no.samples, "neural: training samples drawn from the input");
  app.add_option("--neural-steps", no.steps, "neural: training steps (0: from --neural-epochs)");
  app.add_option("--neural-epochs", no.epochs, "neural: passes over the samples when --neural-steps is 0");
  app.add_option("--neural-batch", no.batch, "neural: samples per training step");
  app.add_option("--neural-lr", no.learning_rate, "neural: learning rate at step 0 (cosine decay to 5 %)");
  app.add_option("--neural-linear-loss", no.linear_loss,
                 "neural: weight (0..1) of the linear-domain squared error in the loss, beside the log domain's");
  app.add_option("--seed", co.seed, "Seed of k-means++, the randomised SVD and the neural codec's samples and training");
  app.add_flag("--log", co.log_transform, "Compress log(x + epsilon) (HDR data); recorded in the codec");
  app.add_option("--log-epsilon", co.log_epsilon, "Epsilon of --log, in data units");
  app.add_option("--max-iterations", co.lpca.max_iterations, "LPCA: PCA/reassignment rounds at most");
  app.add_option("--lpca-memory", co.lpca.memory,
                 "LPCA: auto (out of core above the memory limit), in-core or out-of-core (stream the view slots)");
  app.add_option("--lpca-matrix", co.lpca.matrix,
                 "LPCA: storage of the texel-major matrix, half (2 bytes a value, |x| <= 65504) or float");
  app.add_option("--min-improvement", co.lpca.min_improvement, "LPCA: stop when a round improves the error by less");
  app.add_option("--lpca-sample", co.lpca.sample,
                 "LPCA: texels of the k-means sample; smaller than the texels: local-PCA rounds on it first");
  app.add_option("--lpca-splits", co.lpca.splits,
                 "LPCA: split/merge trials on the sample after its rounds, at most (0: none)");
  app.add_option("--lpca-subspace", co.lpca.subspace,
                 "LPCA: dimensions of the sample's principal subspace that k-means and the sample rounds work in "
                 "(0: the full dimension)");
  app.add_option("--storage", cf.storage, "Coefficient storage: float (float32) or half (float16, half the size)");
  app.add_option("--scene", cf.scene, "scene.json: keep only the directions, mip level and channels a scene uses");
  app.add_option("-o,--output", cf.output, "Output codec file (.h5)");

  DecodeFlags df;
  auto* cd = app.add_subcommand("decode", "Decode a codec into a dataset file");
  cd->add_option("CODEC", df.codec, "Codec file")->required();
  cd->add_option("-o,--output", df.output, "Output dataset (.h5)")->required();

  ExportFlags ef;
  auto* ce = app.add_subcommand("export", "Export an LPCA, pca-view or neural codec for a renderer");
  ce->add_option("CODEC", ef.codec, "Codec file (lpca, pca-view or neural)")->required();
  ce->add_option("--format", ef.format,
                 "Export format: schneider (lpca), sattler (pca-view) or neural (neural); default: by the codec's method")
      ->check(CLI::IsMember({"schneider", "sattler", "neural"}));
  auto* vg = ce->add_option("--view-grid", ef.options.view_grid, "schneider: samples per side of the (s_v, t_v) square");
  auto* lg = ce->add_option("--light-grid", ef.options.light_grid, "schneider: samples per side of the (s_l, t_l) square");
  auto* ec = ce->add_option("--components", ef.options.components,
                 "Eigen-ABRDFs per cluster (schneider) or eigen-textures per view (sattler) to export (-1 = all)");
  auto* es = ce->add_option("--storage", ef.options.storage, "Atlas values: u8 (8-bit unsigned normalised) or f16 (half floats)")
      ->check(CLI::IsMember({"u8", "f16"}));
  auto* ea = ce->add_option("--atlas-side", ef.options.atlas_side,
                 "Largest atlas side in texels (schneider: 3D texture width, height and depth, WebGL2 guarantees 256; "
                 "sattler: texture-array layer width and height, WebGL2 guarantees 2048)");
  ce->add_option("-o,--output", ef.output, "Output folder")->required();
  btf::cli::MarkDistributed(&app);  // compressing (not lpca-tensor); decode and export refuse

  return btf::cli::Main(argc, argv, app, [&] {
    if (cd->parsed()) return RunDecode(app, common, df);
    if (ce->parsed()) {
      ef.grids_given = vg->count() + lg->count() > 0;
      ef.storage_given = ec->count() + es->count() + ea->count() > 0;
      return RunExport(app, common, ef);
    }
    return RunCompress(app, common, cf);
  });
}
