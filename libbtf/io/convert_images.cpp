// Image sets (UBO2003, ATRIUM, any folder by a name pattern) imported into a dataset file.
#include <algorithm>
#include <cmath>
#include <regex>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/image_io.h"

namespace btf {

namespace {

struct Found {
  std::filesystem::path path;
  std::string rel;  // relative to the folder, for messages
  double tv = 0, pv = 0, tl = 0, pl = 0;
  long index = -1;  // ubo2003 / atrium: NNNNN
};

// Angles in degrees, canonical: phi in [0, 360), 0 at the pole; rounded to 1e-6 degrees.
std::pair<double, double> Canonical(double theta, double phi) {
  phi = std::fmod(phi, 360.0);
  if (phi < 0) phi += 360.0;
  if (theta == 0) phi = 0;
  return {std::round(theta * 1e6) / 1e6, std::round(phi * 1e6) / 1e6};
}

// Index of (theta, phi) degrees in `s`, or -1 (within 0.01 degrees).
int IndexIn(const Sampling& s, double theta, double phi) {
  const Vec3 d = DirectionFromAngles(theta * kPi / 180, phi * kPi / 180);
  for (int i = 0; i < s.size(); ++i)
    if ((s[i] - d).norm() < 0.01 * kPi / 180) return i;
  return -1;
}

// The regular expression of a --pattern: fields {tv} {pv} {tl} {pl} (each exactly once) become
// number groups; everything else matches literally. Group order in *fields.
std::regex PatternRegex(const std::string& pattern, std::vector<std::string>* fields) {
  std::string re;
  static const std::string kSpecial = R"(\^$.|?*+()[]{})";
  for (std::size_t i = 0; i < pattern.size();) {
    bool field = false;
    for (const char* f : {"{tv}", "{pv}", "{tl}", "{pl}"}) {
      if (pattern.compare(i, 4, f) != 0) continue;
      const std::string name(f + 1, 2);
      if (std::find(fields->begin(), fields->end(), name) != fields->end())
        ThrowUsage("--pattern '{}' has the field {{{}}} twice", pattern, name);
      fields->push_back(name);
      re += "([-+]?[0-9]+(?:\\.[0-9]+)?)";
      i += 4;
      field = true;
      break;
    }
    if (field) continue;
    if (kSpecial.find(pattern[i]) != std::string::npos) re += '\\';
    re += pattern[i++];
  }
  if (fields->size() != 4)
    ThrowUsage("--pattern '{}' must hold each of the fields {{tv}} {{pv}} {{tl}} {{pl}} once", pattern);
  return std::regex(re);
}

std::vector<Found> Scan(const ConvertOptions& o, const std::filesystem::path& folder) {
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec))
    ThrowBadInput("'{}' is not a folder: --layout {} imports a folder of images (zip files are not read: unpack it)",
                  folder.string(), o.layout);
  std::vector<std::string> fields;
  const bool pattern = o.layout == "pattern";
  const std::regex re = pattern ? PatternRegex(o.pattern, &fields)
                                : std::regex(o.layout == "ubo2003" ? R"((\d+) tl(\d+) pl(\d+) tv(\d+) pv(\d+)\.(jpg|jpeg|JPG|JPEG))"
                                                                   : R"((\d+) tl(\d+) pl(\d+) tv(\d+) pv(\d+)\.(hdr|HDR))");
  if (!pattern) fields = {"tl", "pl", "tv", "pv"};
  std::vector<Found> found;
  for (auto it = std::filesystem::recursive_directory_iterator(folder, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    if (!it->is_regular_file()) continue;
    const std::string rel = std::filesystem::relative(it->path(), folder).generic_string();
    const std::string name = pattern ? rel : it->path().filename().string();
    std::smatch m;
    if (!std::regex_match(name, m, re)) continue;
    Found f{it->path(), rel};
    const int first = pattern ? 1 : 2;
    if (!pattern) f.index = std::stol(m[1].str());
    for (std::size_t i = 0; i < 4; ++i) {
      const double x = std::stod(m[first + int(i)].str());
      if (fields[i] == "tv") f.tv = x;
      if (fields[i] == "pv") f.pv = x;
      if (fields[i] == "tl") f.tl = x;
      if (fields[i] == "pl") f.pl = x;
    }
    for (double theta : {f.tv, f.tl})
      if (!(theta >= 0 && theta < 90))
        ThrowBadInput("'{}': theta {} degrees is outside [0, 90): not a direction above the surface", it->path().string(),
                      theta);
    found.push_back(std::move(f));
  }
  if (ec) ThrowIo("cannot list '{}': {}", folder.string(), ec.message());
  if (found.empty())
    ThrowBadInput("no file in '{}' is named as --layout {} expects ({}): check the folder and the layout", folder.string(),
                  o.layout,
                  pattern ? o.pattern
                          : std::string(o.layout == "ubo2003" ? "'NNNNN tlTTT plPPP tvTTT pvPPP.jpg'"
                                                              : "'NNNNN tlTTT plPPP tvTTT pvPPP.hdr'"));
  // A fixed order, whatever the file system lists first.
  std::sort(found.begin(), found.end(), [](const Found& a, const Found& b) { return a.rel < b.rel; });
  return found;
}

// The distinct directions of a pattern's names, sorted by theta then phi; the Bonn 81 or UBO2014
// sampling if they are exactly its directions.
Sampling DirectionsOf(const std::vector<std::pair<double, double>>& angles, const std::string& name) {
  std::vector<std::pair<double, double>> keys;
  for (const auto& [t, p] : angles) keys.push_back(Canonical(t, p));
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  for (const Sampling& known : {Sampling::Bonn81(), Sampling::Ubo151()}) {
    if (int(keys.size()) != known.size()) continue;
    bool all = true;
    for (const auto& [t, p] : keys) all = all && IndexIn(known, t, p) >= 0;
    if (all) return known;
  }
  std::vector<Vec3> dirs;
  for (const auto& [t, p] : keys) dirs.push_back(DirectionFromAngles(t * kPi / 180, p * kPi / 180));
  return Sampling(name, std::move(dirs));
}

std::string Describe(const Sampling& s, int i) {
  const Angles a = s.angles(i);
  return fmt::format("(theta {:.6g}, phi {:.6g})", a.theta * 180 / kPi, a.phi * 180 / kPi);
}

}  // namespace

ConvertSummary ImportImageSet(const ConvertOptions& options, const std::filesystem::path& folder,
                              const std::filesystem::path& output, const Reporter& reporter) {
  options.Check();
  if (options.layout.empty()) ThrowUsage("ImportImageSet needs a --layout (ubo2003, atrium or pattern)");
  const std::string target = ConvertTarget(options, output);
  if (target != "dataset")
    ThrowUsage("image sets are imported into a dataset (.h5), not {}: convert the dataset afterwards", target);
  Timer timer;
  const std::vector<Found> found = Scan(options, folder);
  Sampling views, lights;
  if (options.layout == "pattern") {
    std::vector<std::pair<double, double>> v, l;
    for (const Found& f : found) v.emplace_back(f.tv, f.pv), l.emplace_back(f.tl, f.pl);
    views = DirectionsOf(v, "image-set:views");
    lights = DirectionsOf(l, "image-set:lights");
  } else {
    views = lights = Sampling::Bonn81();
  }
  const int V = views.size(), L = lights.size();
  std::vector<const Found*> grid(std::size_t(V) * L, nullptr);
  for (const Found& f : found) {
    const int v = IndexIn(views, f.tv, f.pv), l = IndexIn(lights, f.tl, f.pl);
    if (v < 0 || l < 0)
      ThrowBadInput("'{}': {} direction (theta {}, phi {}) is not one of the Bonn 81 directions {} names", f.path.string(),
                    v < 0 ? "view" : "light", v < 0 ? f.tv : f.tl, v < 0 ? f.pv : f.pl, options.layout);
    if (f.index >= 0 && f.index != 81L * l + v)
      ThrowBadInput("'{}': image number {} disagrees with its directions (light {}, view {}: 81 x light + view = {})",
                    f.path.string(), f.index, l, v, 81L * l + v);
    const Found*& slot = grid[std::size_t(v) * L + l];
    if (slot)
      ThrowBadInput("'{}' and '{}' are both view {} light {}: remove one", slot->path.string(), f.path.string(),
                    Describe(views, v), Describe(lights, l));
    slot = &f;
  }
  std::vector<std::string> missing;
  for (int v = 0; v < V; ++v)
    for (int l = 0; l < L; ++l)
      if (!grid[std::size_t(v) * L + l])
        missing.push_back(options.layout == "pattern"
                              ? fmt::format("view {} light {}", Describe(views, v), Describe(lights, l))
                              : fmt::format("'{:05d} tl{:03.0f} pl{:03.0f} tv{:03.0f} pv{:03.0f}.{}'", 81 * l + v,
                                            lights.angles(l).theta * 180 / kPi, lights.angles(l).phi * 180 / kPi,
                                            views.angles(v).theta * 180 / kPi, views.angles(v).phi * 180 / kPi,
                                            options.layout == "ubo2003" ? "jpg" : "hdr"));
  if (!missing.empty() && !options.allow_missing) {
    const std::size_t shown = std::min<std::size_t>(missing.size(), 3);
    ThrowBadInput("'{}': {} of {} images are missing ({}{}); add them, or give --allow-missing to write them as 0",
                  folder.string(), missing.size(), std::size_t(V) * L,
                  fmt::join(missing.begin(), missing.begin() + std::ptrdiff_t(shown), ", "),
                  missing.size() > shown ? ", ..." : "");
  }
  ImageReadOptions read;
  if (options.layout == "ubo2003") read.colorspace = "srgb";  // 8-bit sRGB by definition, tagged or not
  const Found* first = nullptr;
  for (const Found* f : grid) first = first ? first : f;
  const Image ref = ReadImage(first->path, read);
  DatasetInfo info;
  info.units = "relative";
  info.channel_names.clear();
  for (int c = 0; c < ref.channels; ++c)
    info.channel_names.push_back(ref.channels == 3 ? std::string(1, "RGB"[c]) : fmt::format("C{}", c));
  if (ref.channels != 3) info.color_space = "multispectral";
  info.provenance = {{"source", "image-set"},
                     {"layout", options.layout},
                     {"pattern", options.pattern},
                     {"folder", folder.string()},
                     {"missing_images", missing.size()}};
  DatasetWriteOptions wo;
  wo.storage = options.storage == "float16" ? h5::Storage::kFloat16 : h5::Storage::kFloat32;
  wo.deflate_level = options.deflate_level;
  wo.creator = "btf-convert";
  DatasetWriter w(output, views, lights, ref.height, ref.width, ref.channels, info, wo);
  const std::vector<float> zero(ref.pixels.size(), 0.0f);
  for (int v = 0; v < V; ++v) {
    for (int l = 0; l < L; ++l) {
      const Found* f = grid[std::size_t(v) * L + l];
      if (!f) {
        w.WriteImage(v, l, zero.data());
        continue;
      }
      const Image img = ReadImage(f->path, read);
      if (img.width != ref.width || img.height != ref.height || img.channels != ref.channels)
        ThrowBadInput("'{}' is {} x {} with {} channels, but '{}' is {} x {} with {}: every image of a set must have "
                      "one size",
                      f->path.string(), img.width, img.height, img.channels, first->path.string(), ref.width,
                      ref.height, ref.channels);
      for (std::size_t i = 0; i < img.pixels.size(); ++i)
        if (!std::isfinite(img.pixels[i]))
          ThrowBadInput("'{}': pixel ({}, {}) channel {} is {}", f->path.string(), i / img.channels % img.width,
                        i / img.channels / img.width, i % img.channels, img.pixels[i]);
      w.WriteImage(v, l, img.pixels.data());
    }
    reporter.Progress(std::size_t(v + 1), std::size_t(V), "importing");
  }
  w.Commit();
  ConvertSummary s;
  s.input = folder.string();
  s.input_kind = "image-set:" + options.layout;
  s.output = output.string();
  s.output_format = "dataset";
  s.views = V;
  s.lights = L;
  s.height = ref.height;
  s.width = ref.width;
  s.channels = ref.channels;
  s.missing_images = missing.size();
  std::error_code ec;
  s.bytes_written = std::filesystem::file_size(output, ec);
  s.times.Add("convert", timer.Seconds());
  return s;
}

}  // namespace btf
