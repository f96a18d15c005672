// Image sets (UBO2003, ATRIUM, UBO2014 Dome 1, any folder by a name pattern; a folder or a zip
// archive) imported into a dataset file.
#include <algorithm>
#include <cmath>
#include <regex>
#include <vector>

#include <zip.h>

#include "libbtf/core/error.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/image_io.h"

namespace btf {

namespace {

// The files of an image set: a folder (recursively) or a zip archive (libzip; entries are decoded
// from memory, nothing is unpacked). Names are relative paths with '/' separators.
class ImageSetFiles {
 public:
  explicit ImageSetFiles(const std::filesystem::path& input) : input_(input) {
    std::error_code ec;
    if (std::filesystem::is_directory(input, ec)) {
      for (auto it = std::filesystem::recursive_directory_iterator(input, ec);
           !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec))
        if (it->is_regular_file()) names_.push_back(std::filesystem::relative(it->path(), input).generic_string());
      if (ec) ThrowIo("cannot list '{}': {}", input.string(), ec.message());
      return;
    }
    if (!std::filesystem::is_regular_file(input, ec))
      ThrowIo("'{}' does not exist: give a folder of images or a zip archive of them", input.string());
    int err = 0;
    zip_ = zip_open(input.c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &err);
    if (!zip_) {
      zip_error_t e;
      zip_error_init_with_code(&e, err);
      const std::string why = zip_error_strerror(&e);
      zip_error_fini(&e);
      ThrowBadInput("'{}' is neither a folder nor a readable zip archive ({}): give a folder of images or a zip of them",
                    input.string(), why);
    }
    const zip_int64_t n = zip_get_num_entries(zip_, 0);
    for (zip_int64_t i = 0; i < n; ++i) {
      const char* name = zip_get_name(zip_, zip_uint64_t(i), ZIP_FL_ENC_GUESS);
      if (!name) ThrowBadInput("'{}': entry {} of the zip archive has no readable name: {}", input.string(), i, zip_strerror(zip_));
      std::string rel = name;
      if (rel.empty() || rel.back() == '/') continue;  // a folder entry
      names_.push_back(std::move(rel));
      index_.push_back(zip_uint64_t(i));
    }
  }
  ~ImageSetFiles() {
    if (zip_) zip_discard(zip_);
  }
  ImageSetFiles(const ImageSetFiles&) = delete;
  ImageSetFiles& operator=(const ImageSetFiles&) = delete;

  const std::filesystem::path& input() const { return input_; }
  bool is_zip() const { return zip_ != nullptr; }
  const std::vector<std::string>& names() const { return names_; }
  // For messages: the file's path, or "archive.zip:entry".
  std::string Display(std::size_t i) const {
    return zip_ ? input_.string() + ":" + names_[i] : (input_ / names_[i]).string();
  }
  Image Read(std::size_t i, const ImageReadOptions& options) const {
    if (!zip_) return ReadImage(input_ / names_[i], options);
    zip_stat_t st;
    zip_stat_init(&st);
    if (zip_stat_index(zip_, index_[i], 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE))
      ThrowBadInput("'{}': cannot read the size of the zip entry: {}", Display(i), zip_strerror(zip_));
    CheckAllocation(double(st.size), fmt::format("zip entry '{}'", Display(i)));
    std::string bytes(static_cast<std::size_t>(st.size), '\0');
    zip_file_t* f = zip_fopen_index(zip_, index_[i], 0);
    if (!f) ThrowBadInput("'{}': cannot open the zip entry: {}; re-create the archive", Display(i), zip_strerror(zip_));
    std::size_t got = 0;
    zip_int64_t r = 0;
    while (got < bytes.size() && (r = zip_fread(f, bytes.data() + got, bytes.size() - got)) > 0) got += std::size_t(r);
    // Reading to the end makes libzip check the entry's CRC.
    char extra = 0;
    if (r >= 0) r = zip_fread(f, &extra, 1);
    const std::string why = r < 0 ? zip_file_strerror(f) : "";
    zip_fclose(f);
    if (r != 0 || got != bytes.size())
      ThrowBadInput("'{}': the zip entry is corrupt ({}); re-download or re-create the archive", Display(i),
                    r < 0 ? why : fmt::format("{} bytes where its header says {}", got + std::size_t(r > 0), st.size));
    return DecodeImage(Display(i), bytes, options);
  }

 private:
  std::filesystem::path input_;
  zip_t* zip_ = nullptr;
  std::vector<std::string> names_;
  std::vector<zip_uint64_t> index_;  // zip entry of each name
};

// The named layouts: UBO2003 and ATRIUM (Bonn 81, NNNNN = 81 light + view, integer degrees) and
// ubo2014-images (UBO2014 Dome 1, NNNNN = 151 light + view, degrees with optional decimals, matched
// to the Dome 1 table within 0.5 degrees, the precision of the angles Bonn stores).
struct Layout {
  std::regex names;
  std::string example;  // for messages
  Sampling sampling;
  long index_base = 0;
  double tolerance_deg = 0.01;
};

Layout NamedLayout(const std::string& layout) {
  constexpr const char* kAngle = R"(([0-9]+(?:\.[0-9]+)?))";
  if (layout == "ubo2003" || layout == "atrium") {
    const std::string ext = layout == "ubo2003" ? "jpg|jpeg|JPG|JPEG" : "hdr|HDR";
    return {std::regex(R"((\d+) tl(\d+) pl(\d+) tv(\d+) pv(\d+)\.()" + ext + ")"),
            layout == "ubo2003" ? "'NNNNN tlTTT plPPP tvTTT pvPPP.jpg'" : "'NNNNN tlTTT plPPP tvTTT pvPPP.hdr'",
            Sampling::Bonn81(), 81, 0.01};
  }
  return {std::regex(fmt::format(R"((\d+) tl{0} pl{0} tv{0} pv{0}\.(exr|hdr|png|jpg|jpeg|tif|tiff|EXR|HDR|PNG|JPG|JPEG|TIF|TIFF))",
                                 kAngle)),
          "'NNNNN tlT plP tvT pvP.exr' (or .hdr, .png, .jpg, .tif)", Sampling::Ubo151(), 151, 0.5};
}

struct Found {
  std::size_t file = 0;  // in ImageSetFiles::names()
  std::string name;      // for messages
  double tv = 0, pv = 0, tl = 0, pl = 0;
  long index = -1;  // named layouts: NNNNN
};

// Angles in degrees, canonical: phi in [0, 360), 0 at the pole; rounded to 1e-6 degrees.
std::pair<double, double> Canonical(double theta, double phi) {
  phi = std::fmod(phi, 360.0);
  if (phi < 0) phi += 360.0;
  if (theta == 0) phi = 0;
  return {std::round(theta * 1e6) / 1e6, std::round(phi * 1e6) / 1e6};
}

// Index of (theta, phi) degrees in `s` (the nearest direction within tolerance_deg), or -1.
int IndexIn(const Sampling& s, double theta, double phi, double tolerance_deg = 0.01) {
  const Vec3 d = DirectionFromAngles(theta * kPi / 180, phi * kPi / 180);
  int best = -1;
  double best_dist = tolerance_deg * kPi / 180;
  for (int i = 0; i < s.size(); ++i)
    if (const double e = (s[i] - d).norm(); e < best_dist) best = i, best_dist = e;
  return best;
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

std::vector<Found> Scan(const ConvertOptions& o, const ImageSetFiles& files) {
  std::vector<std::string> fields;
  const bool pattern = o.layout == "pattern";
  const Layout named = pattern ? Layout{} : NamedLayout(o.layout);
  const std::regex re = pattern ? PatternRegex(o.pattern, &fields) : named.names;
  if (!pattern) fields = {"tl", "pl", "tv", "pv"};
  std::vector<Found> found;
  for (std::size_t i = 0; i < files.names().size(); ++i) {
    const std::string& rel = files.names()[i];
    const std::string name = pattern ? rel : std::filesystem::path(rel).filename().string();
    std::smatch m;
    if (!std::regex_match(name, m, re)) continue;
    Found f{i, files.Display(i)};
    const int first = pattern ? 1 : 2;
    if (!pattern) f.index = std::stol(m[1].str());
    for (std::size_t k = 0; k < 4; ++k) {
      const double x = std::stod(m[first + int(k)].str());
      if (fields[k] == "tv") f.tv = x;
      if (fields[k] == "pv") f.pv = x;
      if (fields[k] == "tl") f.tl = x;
      if (fields[k] == "pl") f.pl = x;
    }
    for (double theta : {f.tv, f.tl})
      if (!(theta >= 0 && theta < 90))
        ThrowBadInput("'{}': theta {} degrees is outside [0, 90): not a direction above the surface", f.name, theta);
    found.push_back(std::move(f));
  }
  if (found.empty())
    ThrowBadInput("no file in '{}' is named as --layout {} expects ({}): check the {} and the layout",
                  files.input().string(), o.layout, pattern ? o.pattern : named.example, files.is_zip() ? "archive" : "folder");
  // A fixed order, whatever the file system or archive lists first.
  std::sort(found.begin(), found.end(), [&](const Found& a, const Found& b) {
    return files.names()[a.file] < files.names()[b.file];
  });
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

// The file name a named layout expects for (light l, view v).
std::string MissingName(const std::string& layout, const Layout& named, const Sampling& lights, int l,
                        const Sampling& views, int v) {
  const Angles li = lights.angles(l), vi = views.angles(v);
  const auto deg = [](double rad) { return rad * 180 / kPi; };
  if (layout == "ubo2014-images")  // phi as Bonn's table has it, in [0, 360)
    return fmt::format("'{:05d} tl{:g} pl{:g} tv{:g} pv{:g}.*'", named.index_base * l + v, std::round(deg(li.theta) * 10) / 10,
                       std::round(Canonical(deg(li.theta), deg(li.phi)).second * 10) / 10, std::round(deg(vi.theta) * 10) / 10,
                       std::round(Canonical(deg(vi.theta), deg(vi.phi)).second * 10) / 10);
  return fmt::format("'{:05d} tl{:03.0f} pl{:03.0f} tv{:03.0f} pv{:03.0f}.{}'", named.index_base * l + v, deg(li.theta),
                     deg(li.phi), deg(vi.theta), deg(vi.phi), layout == "ubo2003" ? "jpg" : "hdr");
}

// --directions present: keeps the views and the lights that have at least one image (their order
// kept), so that a partial set imports as the smaller set it is instead of zeros for the rest.
void KeepPresentDirections(Sampling& views, Sampling& lights, std::vector<const Found*>& grid) {
  const int V = views.size(), L = lights.size();
  std::vector<int> vs, ls;
  for (int v = 0; v < V; ++v)
    for (int l = 0; l < L; ++l)
      if (grid[std::size_t(v) * L + l]) {
        vs.push_back(v);
        break;
      }
  for (int l = 0; l < L; ++l)
    for (int v = 0; v < V; ++v)
      if (grid[std::size_t(v) * L + l]) {
        ls.push_back(l);
        break;
      }
  std::vector<const Found*> kept;
  for (int v : vs)
    for (int l : ls) kept.push_back(grid[std::size_t(v) * L + l]);
  views = views.Subset(vs);
  lights = lights.Subset(ls);
  grid = std::move(kept);
}

}  // namespace

ConvertSummary ImportImageSet(const ConvertOptions& options, const std::filesystem::path& folder,
                              const std::filesystem::path& output, const Reporter& reporter) {
  options.Check();
  if (options.layout.empty()) ThrowUsage("ImportImageSet needs a --layout (ubo2003, atrium, ubo2014-images or pattern)");
  const std::string target = ConvertTarget(options, output);
  if (target != "dataset")
    ThrowUsage("image sets are imported into a dataset (.h5), not {}: convert the dataset afterwards", target);
  Timer timer;
  const ImageSetFiles files(folder);
  const std::vector<Found> found = Scan(options, files);
  const bool pattern = options.layout == "pattern";
  const Layout named = pattern ? Layout{} : NamedLayout(options.layout);
  Sampling views, lights;
  if (pattern) {
    std::vector<std::pair<double, double>> v, l;
    for (const Found& f : found) v.emplace_back(f.tv, f.pv), l.emplace_back(f.tl, f.pl);
    views = DirectionsOf(v, "image-set:views");
    lights = DirectionsOf(l, "image-set:lights");
  } else {
    views = lights = named.sampling;
  }
  std::vector<const Found*> grid(std::size_t(views.size()) * lights.size(), nullptr);
  for (const Found& f : found) {
    const int L = lights.size();
    const int v = IndexIn(views, f.tv, f.pv, named.tolerance_deg), l = IndexIn(lights, f.tl, f.pl, named.tolerance_deg);
    if (v < 0 || l < 0)
      ThrowBadInput("'{}': {} direction (theta {}, phi {}) is not one of the {} directions {} names", f.name,
                    v < 0 ? "view" : "light", v < 0 ? f.tv : f.tl, v < 0 ? f.pv : f.pl, views.size(), options.layout);
    if (f.index >= 0 && f.index != named.index_base * l + v)
      ThrowBadInput("'{}': image number {} disagrees with its directions (light {}, view {}: {} x light + view = {})",
                    f.name, f.index, l, v, named.index_base, named.index_base * l + v);
    const Found*& slot = grid[std::size_t(v) * L + l];
    if (slot)
      ThrowBadInput("'{}' and '{}' are both view {} light {}: remove one", slot->name, f.name, Describe(views, v),
                    Describe(lights, l));
    slot = &f;
  }
  if (options.directions == "present") KeepPresentDirections(views, lights, grid);
  const int V = views.size(), L = lights.size();
  std::vector<std::string> missing;
  for (int v = 0; v < V; ++v)
    for (int l = 0; l < L; ++l)
      if (!grid[std::size_t(v) * L + l])
        missing.push_back(pattern ? fmt::format("view {} light {}", Describe(views, v), Describe(lights, l))
                                  : MissingName(options.layout, named, lights, l, views, v));
  if (!missing.empty() && !options.allow_missing) {
    const std::size_t shown = std::min<std::size_t>(missing.size(), 3);
    ThrowBadInput("'{}': {} of {} images are missing ({}{}); add them, give --directions present to keep only the "
                  "views and lights with images, or --allow-missing to mark them missing (written as 0)",
                  folder.string(), missing.size(), std::size_t(V) * L,
                  fmt::join(missing.begin(), missing.begin() + std::ptrdiff_t(shown), ", "),
                  missing.size() > shown ? ", ..." : "");
  }
  ImageReadOptions read;
  read.max_pixels = options.max_pixels;
  if (options.layout == "ubo2003") read.colorspace = "srgb";  // 8-bit sRGB by definition, tagged or not
  const Found* first = nullptr;
  for (const Found* f : grid) first = first ? first : f;
  const Image ref = files.Read(first->file, read);
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
        w.MarkMissing(v, l);
        continue;
      }
      const Image img = files.Read(f->file, read);
      if (img.width != ref.width || img.height != ref.height || img.channels != ref.channels)
        ThrowBadInput("'{}' is {} x {} with {} channels, but '{}' is {} x {} with {}: every image of a set must have "
                      "one size",
                      f->name, img.width, img.height, img.channels, first->name, ref.width,
                      ref.height, ref.channels);
      for (std::size_t i = 0; i < img.pixels.size(); ++i)
        if (!std::isfinite(img.pixels[i]))
          ThrowBadInput("'{}': pixel ({}, {}) channel {} is {}", f->name, i / img.channels % img.width,
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
