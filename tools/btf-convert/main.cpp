// btf-convert INPUT -o OUTPUT [--to dataset|bdi|fmf|dfmf|pvf]: any readable BTF (libbtf dataset or codec, Bonn
// .btf) to a libbtf dataset or a Bonn BDI, FMF, DFMF or PVF file, one view slot at a time; a folder of images
// (--layout) to a dataset (docs/btf-convert.md).
#include "libbtf/compress/bonn_fmf.h"
#include "libbtf/compress/bonn_pvf.h"
#include "libbtf/compress/codec_source.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/file_kind.h"
#include "tools/common/cli.h"

namespace {

struct ConvertFlags {
  std::string input, output;
  btf::ConvertOptions options;
  btf::FmfWriteOptions fmf;
};

int RunConvert(const CLI::App& app, const btf::cli::CommonFlags& common, const ConvertFlags& f) {
  // Options and the output format are checked before the input is read.
  const std::string target = btf::ConvertTarget(f.options, f.output);
  btf::CheckOutput(f.output, {f.input});
  // Only the factorisation to FMF / DFMF splits its work over MPI ranks (docs/scaling.md); every
  // other conversion refuses more than one rank.
  if (!f.options.layout.empty()) {
    btf::cli::RequireSingleRank("btf-convert --layout");
    btf::cli::PrintSummary(app, common,
                           btf::ImportImageSet(f.options, f.input, f.output, btf::cli::MakeReporter(common)));
    return 0;
  }
  if (target == "fmf" || target == "dfmf") {
    btf::FmfWriteOptions o = f.fmf;
    o.decorrelate = target == "dfmf";
    o.Check();
    if (btf::FileFormatOf(f.input) == btf::kCodecFormat) {
      // An fmf / dfmf codec already holds the factors: written as they are.
      const btf::Codec codec = btf::ReadCodec(f.input);
      if (btf::MethodName(codec.method()) == target) {
        btf::cli::RequireSingleRank("btf-convert --to " + target + " of an " + target + " codec");
        btf::cli::PrintSummary(app, common, btf::WriteFmf(codec, f.input, f.output, btf::cli::MakeReporter(common)));
        return 0;
      }
    }
    // Distributed: each rank reads and multiplies its view slots, rank 0 writes the file.
    const auto input = btf::OpenSource(f.input, btf::cli::DatasetReadOptionsFromEnvironment());
    btf::cli::PrintSummary(app, common, btf::WriteFmf(o, *input, f.output, btf::cli::MakeReporter(common)));
    return 0;
  }
  btf::cli::RequireSingleRank("btf-convert --to " + target);
  if (target == "pvf") {
    // PVF stores a per-view PCA: written from a pca-view codec's factors, not re-factorised.
    const btf::Codec codec = btf::ReadCodec(f.input);
    btf::cli::PrintSummary(app, common, btf::WritePvf(codec, f.input, f.output, btf::cli::MakeReporter(common)));
    return 0;
  }
  const auto input = btf::OpenSource(f.input, btf::cli::DatasetReadOptionsFromEnvironment());
  const btf::ConvertSummary s = btf::Convert(f.options, *input, f.output, btf::cli::MakeReporter(common));
  btf::cli::PrintSummary(app, common, s);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Convert a BTF between formats: libbtf dataset or codec, or Bonn .btf (BDI, DFMF, FMF, PVF) in; libbtf "
               "dataset or Bonn BDI out. Reads and writes one view slot at a time.",
               "btf-convert"};
  btf::cli::Configure(app);
  btf::cli::CommonFlags common;
  ConvertFlags f;
  btf::ConvertOptions& o = f.options;
  app.add_option("INPUT", f.input, "Input: dataset (.h5), codec (.h5) or Bonn .btf file; with --layout a folder or zip archive of images")->required();
  app.add_option("-o,--output", f.output,
                 "Output file (.h5 = dataset, .btf = BDI, .png / .exr = the image --view, --light, unless --to)")
      ->required();
  app.add_option("--to", o.to,
                 "Output format: dataset | bdi | fmf | dfmf | pvf | png | exr (pvf from a pca-view codec; png / exr: one "
                 "image; default: from the output's extension)");
  app.add_option("--view", o.view, "Image output (.png / .exr): the view index of the image");
  app.add_option("--light", o.light, "Image output (.png / .exr): the light index of the image");
  app.add_option("--exposure", o.exposure,
                 "Image output: values are multiplied by this (.png: then clamped to [0, 1], sRGB, as the renders)");
  app.add_option("--storage", o.storage, "Dataset output: float32 | float16");
  app.add_option("--deflate-level", o.deflate_level, "Dataset output: deflate level 0-9 (0 = none)");
  app.add_option("--scan-lines", o.scan_lines_per_chunk, "BDI output: texture rows per chunk");
  app.add_option("--layout", o.layout,
                 "INPUT is a folder or zip of images: ubo2003 (NNNNN tlTTT plPPP tvTTT pvPPP.jpg, sRGB), atrium (the "
                 "same names, .hdr), ubo2014-images (UBO2014 Dome 1: NNNNN tlT plP tvT pvP.exr|hdr|png|jpg|tif, "
                 "NNNNN = 151 light + view) or pattern (--pattern); the output is a dataset");
  app.add_option("--pattern", o.pattern,
                 "--layout pattern: image path relative to the folder (or zip) with fields {tv} {pv} {tl} {pl} (degrees), e.g. "
                 "'tv{tv}_pv{pv}/tl{tl}_pl{pl}.exr'");
  app.add_flag("--allow-missing", o.allow_missing,
               "Image sets: mark missing (view, light) images missing in the dataset (values 0) instead of failing");
  app.add_option("--directions", o.directions,
                 "Image sets: all (the layout's whole sampling) or present (only the views and lights with images)");
  app.add_option("--max-pixels", o.max_pixels,
                 "Image sets: refuse an image whose header claims more pixels (width x height), before reading it (0 = "
                 "no limit)");
  app.add_option("--components,-c", f.fmf.components,
                 "FMF/DFMF output: components of the truncated SVD (per YUV channel for DFMF); clamped to the rank");
  app.add_option("--power-iterations", f.fmf.power_iterations, "FMF/DFMF output: power iterations of the randomised SVD");
  app.add_option("--seed", f.fmf.seed, "FMF/DFMF output: seed of the randomised SVD");
  btf::cli::AddCommonFlags(app, common);
  btf::cli::MarkDistributed(&app);  // --to fmf | dfmf (factorised); the other conversions refuse
  return btf::cli::Main(argc, argv, app, [&] { return RunConvert(app, common, f); });
}
