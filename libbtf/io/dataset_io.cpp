#include "libbtf/io/dataset_io.h"

#include <cmath>
#include <cstdlib>
#include <memory>
#include <sstream>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"

namespace btf {

namespace {
constexpr const char* kData = "/btf/data";
constexpr const char* kMissing = "/btf/missing";

std::string JoinNames(const std::vector<std::string>& names) {
  std::string s;
  for (std::size_t i = 0; i < names.size(); ++i) s += (i ? "," : "") + names[i];
  return s;
}
std::vector<std::string> SplitNames(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  return out;
}

void WriteSampling(const h5::File& f, const std::string& prefix, const Sampling& s) {
  std::vector<double> xyz, angles;
  for (int i = 0; i < s.size(); ++i) {
    xyz.insert(xyz.end(), {s[i].x(), s[i].y(), s[i].z()});
    const Angles a = s.angles(i);
    angles.insert(angles.end(), {a.theta, a.phi});
  }
  const hsize_t n = static_cast<hsize_t>(s.size());
  f.WriteDoubles(prefix + "_directions", {n, 3}, xyz.data());
  f.WriteDoubles(prefix + "_angles", {n, 2}, angles.data());
  f.SetAttr(prefix + "_directions", "sampling", s.name());
  f.SetAttr(prefix + "_directions", "frame", std::string("z=normal,x=weft(u),y=warp(v)"));
  f.SetAttr(prefix + "_angles", "units", std::string("radians; columns theta,phi"));
}

Sampling ReadSampling(const h5::File& f, const std::string& prefix) {
  const std::string name = prefix + "_directions";
  const auto dims = f.Dims(name);
  if (dims.size() != 2 || dims[1] != 3 || dims[0] < 1)
    ThrowBadInput("'{}': '{}' must have shape [n, 3] with n >= 1", f.path(), name);
  const auto xyz = f.ReadDoubles(name);
  std::vector<Vec3> dirs;
  for (std::size_t i = 0; i < dims[0]; ++i) {
    Vec3 d(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (!d.allFinite() || std::abs(d.norm() - 1) > 1e-3)
      ThrowBadInput("'{}': '{}' row {} is not a unit vector", f.path(), name, i);
    dirs.push_back(d);
  }
  const std::string sampling = f.HasAttr(name, "sampling") ? f.GetString(name, "sampling") : "unnamed";
  return Sampling(sampling, std::move(dirs));
}

DatasetHeader ReadHeader(const h5::File& f) {
  DatasetHeader h;
  h.path = f.path();
  h.format_version = f.CheckFormatHeader(kDatasetFormat, kDatasetFormatMajor);
  h.creator = f.GetString("/", "creator");
  h.creation_time = f.GetString("/", "creation_time");
  const auto dims = f.Dims(kData);
  if (dims.size() != 5)
    ThrowBadInput("'{}': '{}' must have 5 dimensions (view, light, y, x, channel), found {}", f.path(), kData,
                  dims.size());
  for (auto d : dims)
    if (d < 1 || d > (1u << 20)) ThrowBadInput("'{}': '{}' has an invalid dimension {}", f.path(), kData, d);
  h.num_views = static_cast<int>(dims[0]);
  h.num_lights = static_cast<int>(dims[1]);
  h.height = static_cast<int>(dims[2]);
  h.width = static_cast<int>(dims[3]);
  h.channels = static_cast<int>(dims[4]);
  // Every reader holds at least one view slot; ReadDataset's Dataset checks the whole BTF.
  CheckAllocation(4.0 * h.num_lights * h.height * h.width * h.channels, fmt::format("'{}': one view slot", f.path()));
  h.storage = f.StorageOf(kData);
  h.views = ReadSampling(f, "/btf/view");
  h.lights = ReadSampling(f, "/btf/light");
  if (h.views.size() != h.num_views || h.lights.size() != h.num_lights)
    ThrowBadInput("'{}': {} view and {} light directions do not match data shape {}x{}", f.path(), h.views.size(),
                  h.lights.size(), h.num_views, h.num_lights);
  DatasetInfo& info = h.info;
  info.color_space = f.GetString("/btf", "color_space");
  info.units = f.GetString("/btf", "units");
  const auto cos_flag = f.GetInt("/btf", "cos_theta_i_included");
  if (cos_flag != 0 && cos_flag != 1) ThrowBadInput("'{}': attribute cos_theta_i_included must be 0 or 1", f.path());
  info.cos_theta_i_included = cos_flag == 1;
  info.channel_names = SplitNames(f.GetString("/btf", "channel_names"));
  if (static_cast<int>(info.channel_names.size()) != h.channels)
    ThrowBadInput("'{}': {} channel names for {} channels", f.path(), info.channel_names.size(), h.channels);
  info.texel_size_mm = f.HasAttr("/btf", "texel_size_mm") ? f.GetDouble("/btf", "texel_size_mm") : 0.0;
  if (f.Exists("/provenance")) {
    info.provenance = nlohmann::json::parse(f.ReadString("/provenance"), nullptr, false);
    if (info.provenance.is_discarded()) ThrowBadInput("'{}': '/provenance' is not valid JSON", f.path());
  }
  if (f.Exists(kMissing)) {
    const auto dims = f.Dims(kMissing);
    if (dims.size() != 2 || dims[1] != 2 || dims[0] > hsize_t(h.num_views) * hsize_t(h.num_lights))
      ThrowBadInput("'{}': '{}' must be a list of (view, light) pairs, at most one per image", f.path(), kMissing);
    const std::vector<std::int32_t> pairs = f.ReadInts(kMissing);
    for (std::size_t i = 0; i < pairs.size(); i += 2) {
      if (pairs[i] < 0 || pairs[i] >= h.num_views || pairs[i + 1] < 0 || pairs[i + 1] >= h.num_lights)
        ThrowBadInput("'{}': '{}' entry {} is (view {}, light {}), outside the {} x {} images", f.path(), kMissing, i / 2,
                      pairs[i], pairs[i + 1], h.num_views, h.num_lights);
      h.missing.emplace_back(pairs[i], pairs[i + 1]);
    }
  }
  return h;
}

std::vector<hsize_t> ImageChunk(int height, int width, int channels) {
  // One chunk per image, split along y if an image exceeds 4 MiB (keeps chunks cacheable).
  const hsize_t row_bytes = hsize_t(width) * channels * 4;
  hsize_t rows = std::max<hsize_t>(1, std::min<hsize_t>(height, (4u << 20) / std::max<hsize_t>(row_bytes, 1)));
  return {1, 1, rows, hsize_t(width), hsize_t(channels)};
}

}  // namespace

void DatasetWriteOptions::Check() const {
  BTF_CHECK_OPTION(deflate_level >= 0 && deflate_level <= 9, "deflate_level", "must be 0..9");
}

struct DatasetWriter::Impl {
  AtomicOutput out;
  h5::File file;
  int views, lights, height, width, channels;
  std::vector<std::int32_t> missing;  // (view, light) pairs
  explicit Impl(const std::filesystem::path& p) : out(p) {}
};

DatasetWriter::DatasetWriter(const std::filesystem::path& path, const Sampling& views, const Sampling& lights,
                             int height, int width, int channels, const DatasetInfo& info,
                             const DatasetWriteOptions& options) {
  options.Check();
  if (static_cast<int>(info.channel_names.size()) != channels)
    ThrowUsage("dataset info has {} channel names for {} channels", info.channel_names.size(), channels);
  impl_ = std::make_unique<Impl>(path);
  impl_->views = views.size();
  impl_->lights = lights.size();
  impl_->height = height;
  impl_->width = width;
  impl_->channels = channels;
  h5::File& f = impl_->file;
  f = h5::File::Create(impl_->out.temp_path());
  f.WriteFormatHeader(kDatasetFormat, kDatasetFormatVersion, options.creator);
  f.CreateGroup("/btf");
  f.SetAttr("/btf", "color_space", info.color_space);
  f.SetAttr("/btf", "units", info.units);
  f.SetAttr("/btf", "cos_theta_i_included", std::int64_t(info.cos_theta_i_included ? 1 : 0));
  f.SetAttr("/btf", "channel_names", JoinNames(info.channel_names));
  f.SetAttr("/btf", "texel_size_mm", info.texel_size_mm);
  WriteSampling(f, "/btf/view", views);
  WriteSampling(f, "/btf/light", lights);
  f.WriteString("/provenance", info.provenance.dump());
  f.CreateFloatArray(kData,
                     {hsize_t(views.size()), hsize_t(lights.size()), hsize_t(height), hsize_t(width), hsize_t(channels)},
                     ImageChunk(height, width, channels), options.storage, options.deflate_level);
  f.SetAttr(kData, "dimension_names", std::string("view,light,y,x,channel"));
  f.SetAttr(kData, "units", info.units);
  f.SetAttr(kData, "storage", std::string(options.storage == h5::Storage::kFloat16 ? "float16" : "float32"));
}

DatasetWriter::~DatasetWriter() = default;

void DatasetWriter::WriteImage(int view, int light, const float* data) {
  impl_->file.WriteSlab(kData, {hsize_t(view), hsize_t(light), 0, 0, 0},
                        {1, 1, hsize_t(impl_->height), hsize_t(impl_->width), hsize_t(impl_->channels)}, data);
}

void DatasetWriter::WriteViewSlot(int view, const float* data) {
  impl_->file.WriteSlab(kData, {hsize_t(view), 0, 0, 0, 0},
                        {1, hsize_t(impl_->lights), hsize_t(impl_->height), hsize_t(impl_->width),
                         hsize_t(impl_->channels)},
                        data);
}

void DatasetWriter::MarkMissing(int view, int light) {
  impl_->missing.push_back(view);
  impl_->missing.push_back(light);
}

void DatasetWriter::Commit() {
  if (!impl_->missing.empty()) {
    h5::File& f = impl_->file;
    f.WriteInts(kMissing, {hsize_t(impl_->missing.size() / 2), 2}, impl_->missing.data());
    f.SetAttr(kMissing, "meaning", std::string("(view, light) images not measured; their values are 0"));
    f.SetAttr("/", "format_version", std::string(kDatasetFormatVersionMissing));
  }
  impl_->file.Close();  // throws if the data did not all reach the file: nothing is committed
  impl_->out.Commit();
}

void RequireEveryImage(const DatasetHeader& h, const std::string& needs) {
  if (h.missing.empty()) return;
  ThrowBadInput("'{}' marks {} of {} images missing (first: view {}, light {}), and {}: import the set again with "
                "--directions present (only the directions with images), or add the missing photos",
                h.path, h.missing.size(), std::size_t(h.num_views) * h.num_lights, h.missing.front().first,
                h.missing.front().second, needs);
}

void WriteDataset(const std::filesystem::path& path, const Dataset& d, const DatasetWriteOptions& options) {
  DatasetWriter w(path, d.views(), d.lights(), d.height(), d.width(), d.channels(), d.info(), options);
  for (int v = 0; v < d.num_views(); ++v) w.WriteViewSlot(v, d.view_slot(v).data());
  w.Commit();
}

DatasetReader::DatasetReader(const std::filesystem::path& path, const DatasetReadOptions& options)
    : file_(h5::File::Open(path)) {
  header_ = ReadHeader(file_);
  raw_chunks_ = options.raw_chunks;
}

void DatasetReader::ReadImage(int view, int light, float* out) const {
  const auto& h = header_;
  file_.ReadSlab(kData, {hsize_t(view), hsize_t(light), 0, 0, 0},
                 {1, 1, hsize_t(h.height), hsize_t(h.width), hsize_t(h.channels)}, out, raw_chunks_);
}

void DatasetReader::ReadViewSlot(int view, float* out) const {
  const auto& h = header_;
  file_.ReadSlab(kData, {hsize_t(view), 0, 0, 0, 0},
                 {1, hsize_t(h.num_lights), hsize_t(h.height), hsize_t(h.width), hsize_t(h.channels)}, out,
                 raw_chunks_);
}

Dataset ReadDataset(const std::filesystem::path& path, const DatasetReadOptions& options) {
  DatasetReader r(path, options);
  const auto& h = r.header();
  Dataset d(h.views, h.lights, h.height, h.width, h.channels, h.info);
  for (int v = 0; v < h.num_views; ++v) r.ReadViewSlot(v, d.view_slot(v).data());
  return d;
}

void WriteSamplingTables(const h5::File& file, const std::string& prefix, const Sampling& sampling) {
  WriteSampling(file, prefix, sampling);
}
Sampling ReadSamplingTables(const h5::File& file, const std::string& prefix) { return ReadSampling(file, prefix); }

}  // namespace btf
