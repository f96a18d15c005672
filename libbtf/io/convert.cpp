#include "libbtf/io/convert.h"

#include <cmath>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/io/image_io.h"

namespace btf {

void ConvertOptions::Check() const {
  BTF_CHECK_OPTION(to.empty() || to == "dataset" || to == "bdi" || to == "dfmf" || to == "fmf" || to == "pvf" ||
                       to == "png" || to == "exr",
                   "to", "must be dataset, bdi, dfmf, fmf, pvf, png or exr");
  BTF_CHECK_OPTION(view >= 0 && light >= 0, "view", "view and light are indices >= 0");
  BTF_CHECK_OPTION(std::isfinite(exposure) && exposure > 0, "exposure", "must be > 0");
  BTF_CHECK_OPTION(storage == "float32" || storage == "float16", "storage", "must be float32 or float16");
  BTF_CHECK_OPTION(deflate_level >= 0 && deflate_level <= 9, "deflate_level", "must be 0 to 9");
  BTF_CHECK_OPTION(scan_lines_per_chunk >= 1, "scan_lines_per_chunk", "must be at least 1");
  BTF_CHECK_OPTION(layout.empty() || layout == "ubo2003" || layout == "atrium" || layout == "ubo2014-images" ||
                       layout == "pattern",
                   "layout", "must be ubo2003, atrium, ubo2014-images or pattern");
  BTF_CHECK_OPTION(pattern.empty() == (layout != "pattern"), "pattern", "given with --layout pattern, and only then");
  BTF_CHECK_OPTION(directions == "all" || directions == "present", "directions", "must be all or present");
}

nlohmann::json ConvertOptions::ToJson() const {
  return {{"to", to},
          {"storage", storage},
          {"deflate_level", deflate_level},
          {"scan_lines_per_chunk", scan_lines_per_chunk},
          {"layout", layout},
          {"pattern", pattern},
          {"allow_missing", allow_missing},
          {"directions", directions},
          {"view", view},
          {"light", light},
          {"exposure", exposure}};
}

std::string ConvertTarget(const ConvertOptions& options, const std::filesystem::path& output) {
  options.Check();
  std::string to = options.to;
  if (to.empty()) {
    const std::string ext = output.extension().string();
    if (ext == ".h5" || ext == ".hdf5")
      to = "dataset";
    else if (ext == ".btf")
      to = "bdi";
    else if (ext == ".png" || ext == ".exr")
      to = ext.substr(1);
    else
      ThrowUsage("cannot tell the output format from '{}': name it .h5 (dataset), .btf (bdi), .png or .exr (one "
                 "image: --view, --light), or give --to",
                 output.string());
  }
  return to;
}

nlohmann::json ConvertSummary::ToJson() const {
  nlohmann::json j = {
      {"input", input},
      {"input_kind", input_kind},
      {"output", output},
      {"output_format", output_format},
      {"shape", {{"views", views}, {"lights", lights}, {"height", height}, {"width", width}, {"channels", channels}}},
      {"bytes_written", bytes_written},
      {"seconds", times.ToJson()}};
  if (input_kind.rfind("image-set", 0) == 0) j["missing_images"] = missing_images;
  return j;
}

std::string ConvertSummary::Report() const {
  return fmt::format("{} ({}) -> {} ({}): {} views x {} lights x {}x{} texels x {} channels, {} bytes in {:.2f} s\n",
                     input, input_kind, output, output_format, views, lights, width, height, channels, bytes_written,
                     times.Total());
}

void WriteSampleImage(const SlotSource& input, int view, int light, double exposure, const std::filesystem::path& path) {
  const int V = input.views().size(), L = input.lights().size();
  if (view < 0 || view >= V || light < 0 || light >= L)
    ThrowUsage("'{}' has {} views and {} lights: --view {} --light {} is not one of its images (0..{}, 0..{})",
               input.name(), V, L, view, light, V - 1, L - 1);
  Image img(input.width(), input.height(), input.channels());
  input.ReadImage(view, light, img.pixels.data());
  for (float& v : img.pixels) v = float(v * exposure);
  ImageWriteOptions o;
  if (path.extension() == ".png") o.has_format = true, o.format = PixelFormat::kUint8, o.srgb = true;
  WriteImage(path, img, o);
}

ConvertSummary Convert(const ConvertOptions& options, const SlotSource& input, const std::filesystem::path& output,
                       const Reporter& reporter) {
  const std::string target = ConvertTarget(options, output);
  if (target == "fmf" || target == "dfmf")
    ThrowUsage("{} is written by WriteFmf (libbtf/compress/bonn_fmf.h), not by Convert", target);
  if (target == "pvf")
    ThrowUsage("PVF is written from a pca-view codec file ('{}' is a {}): btf-convert CODEC -o OUT.btf --to pvf",
               input.name(), input.kind());
  Timer timer;
  ConvertSummary s;
  s.input = input.name();
  s.input_kind = input.kind();
  s.output = output.string();
  s.output_format = target;
  s.views = input.views().size();
  s.lights = input.lights().size();
  s.height = input.height();
  s.width = input.width();
  s.channels = input.channels();
  if (target == "png" || target == "exr") {
    if (output.extension() != "." + target)
      ThrowUsage("--to {} writes a .{} file: name the output '{}'", target, target,
                 std::filesystem::path(output).replace_extension(target).string());
    WriteSampleImage(input, options.view, options.light, options.exposure, output);
    s.views = s.lights = 1;
    std::error_code ec;
    s.bytes_written = std::filesystem::file_size(output, ec);
  } else if (target == "bdi") {
    BdiWriteOptions o;
    o.scan_lines_per_chunk = options.scan_lines_per_chunk;
    s.bytes_written = WriteBdi(output, input, o, reporter);
  } else {
    DatasetWriteOptions o;
    o.storage = options.storage == "float16" ? h5::Storage::kFloat16 : h5::Storage::kFloat32;
    o.deflate_level = options.deflate_level;
    o.creator = "btf-convert";
    DatasetInfo info = input.info();
    info.provenance["converted_from"] = {{"kind", input.kind()}, {"file", input.name()}};
    DatasetWriter w(output, input.views(), input.lights(), input.height(), input.width(), input.channels(), info, o);
    std::vector<float> slot(input.slot_size());
    for (int v = 0; v < s.views; ++v) {
      input.ReadViewSlot(v, slot.data());
      w.WriteViewSlot(v, slot.data());
      reporter.Progress(std::size_t(v + 1), std::size_t(s.views), "converting");
    }
    w.Commit();
    std::error_code ec;
    s.bytes_written = std::filesystem::file_size(output, ec);
  }
  s.times.Add("convert", timer.Seconds());
  return s;
}

}  // namespace btf
