// btf-info's summary of a Bonn file (DescribeBonnFile, libbtf/io/bonn.h): the header as the
// reader validated it, and optionally the value statistics of every decoded slot.
#include "libbtf/io/bonn.h"
#include "libbtf/io/dataset_stats.h"

namespace btf {

nlohmann::json DescribeBonnFile(const std::filesystem::path& path, bool with_stats, const Reporter& reporter) {
  nlohmann::json j;
  {
    const BonnReader r(path, /*header_only=*/true);
    const BonnHeader& h = r.header();
    j["path"] = path.string();
    j["format"] = std::string("bonn-") + BonnFormatName(h.format);
    j["signature"] = h.signature;
    j["shape"] = {{"views", h.views.size()},
                  {"lights", h.lights.size()},
                  {"height", h.height},
                  {"width", h.width},
                  {"channels", h.channels()}};
    j["view_sampling"] = DescribeSampling(h.views);
    j["light_sampling"] = DescribeSampling(h.lights);
    j["channel_names"] = h.channel_names;
    j["components"] = h.components;
    j["scalar_sizes"] = h.scalar_sizes;
    if (h.format == BonnFormat::kDfmf) {
      j["color_model"] = {{"id", h.color_model}, {"name", BonnColorModelName(h.color_model)}};
      j["header_components"] = h.header_components;
    }
    if (h.format == BonnFormat::kDfmf || h.format == BonnFormat::kFmf)
      j["layout"] = h.transposed ? "transposed (U over texels, SxV over directions)" : "U over directions, SxV over texels";
    if (h.format == BonnFormat::kFmf) {
      j["fmf_header_version"] = h.fmf_header_version;
      j["dynamic_range_reduction"] = h.dynamic_range_reduction == 0 ? "none" : "log";
      j["height_map"] = {h.height_map_width, h.height_map_height};
    }
    if (h.format == BonnFormat::kPvf) {
      j["pvf_header"] = h.pvf_legacy ? "legacy (301074)" : "current";
      j["pvf_layout"] = h.pvf_images ? "stacked images" : "light fields";
    }
    if (h.format == BonnFormat::kBdi) {
      j["compression"] = h.compression == 0 ? "full" : "sparse";
      j["scan_lines_per_chunk"] = h.scan_lines_per_chunk;
      j["stored_texels"] = h.stored_texels;
      if (h.padding_abrdfs > 0) j["last_chunk_padding_abrdfs"] = h.padding_abrdfs;
    }
    j["rotations"] = h.rotations.size();
    j["cos_theta_i_included"] = h.cosine_flag;
    j["stored_conventions"] = {
        {"cosine_flag", h.cosine_flag},
        {"values", h.cosine_flag ? "BRDF x cos(theta_i) as stored (not divided out)" : "as stored"},
        {"texture_rows", "file row y = dataset row y (y = 0 first, not flipped)"},
        {"epsilon", kBonnEpsilon},
        {"clamping", "none"},
        {"units", "relative (rgb_scale_factor and ppmm not applied)"}};
    if (h.has_meta)
      j["meta"] = {{"version", h.meta_version},
                   {"measurement_setup", h.measurement_setup},
                   {"image_sensor", h.image_sensor},
                   {"light_source", h.light_source},
                   {"ppmm", h.ppmm},
                   {"rgb_scale_factor", h.rgb_scale_factor},
                   {"xml_bytes", h.xml.size()}};
    j["color_space"] = h.Info().color_space;
    j["units"] = "relative";
    j["file_bytes"] = h.file_bytes;
  }
  if (with_stats) j["values"] = ComputeValueStats(*OpenBonnSource(path), reporter).ToJson();
  return j;
}

}  // namespace btf
