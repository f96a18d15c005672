// Codec file "libbtf-codec" version 1.2.0, neural codecs 1.3.0 (normative description: docs/format.md).
#include <cmath>
#include <sstream>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/codec_writer.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/hdf5.h"

namespace btf {

namespace {

std::string SlotName(const char* what, int v) { return fmt::format("/codec/pca_view/{}_{:05d}", what, v); }

std::string Join(const std::vector<std::string>& names) {
  std::string s;
  for (std::size_t i = 0; i < names.size(); ++i) s += (i ? "," : "") + names[i];
  return s;
}

std::vector<float> ReadChecked(const h5::File& f, const std::string& name, const std::vector<hsize_t>& dims) {
  const auto got = f.Dims(name);
  if (got != dims) {
    std::string want, have;
    for (auto d : dims) want += fmt::format("{}x", d);
    for (auto d : got) have += fmt::format("{}x", d);
    ThrowBadInput("'{}': '{}' has shape {}, expected {}", f.path(), name, have.empty() ? "scalar" : have.substr(0, have.size() - 1),
                  want.substr(0, want.size() - 1));
  }
  std::vector<float> v = f.ReadFloats(name);
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) ThrowBadInput("'{}': '{}' holds a non-finite value at element {}", f.path(), name, i);
  return v;
}

std::vector<std::int32_t> ReadIntsChecked(const h5::File& f, const std::string& name, const std::vector<hsize_t>& dims) {
  if (f.Dims(name) != dims) ThrowBadInput("'{}': '{}' has an unexpected shape", f.path(), name);
  return f.ReadInts(name);
}

int ReadDim(const h5::File& f, const char* name, int lo, int hi) {
  const auto v = f.GetInt("/codec", name);
  if (v < lo || v > hi) ThrowBadInput("'{}': attribute '/codec@{}' = {} is outside [{}, {}]", f.path(), name, v, lo, hi);
  return static_cast<int>(v);
}

}  // namespace

void WriteCodec(const std::filesystem::path& path, const Codec& c, const std::string& creator) {
  AtomicOutput out(path);
  WriteCodec(out, c, creator);
}

void WriteCodec(AtomicOutput& out, const Codec& c, const std::string& creator) {
  CodecFileWriter w(out, c, creator);
  w.Finish(c, 0);
}

CodecFileWriter::CodecFileWriter(AtomicOutput& out, const Codec& c, const std::string& creator)
    : out_(out),
      file_(h5::File::Create(out.temp_path())),
      storage_(c.storage() == CodecStorage::kHalf ? h5::Storage::kFloat16 : h5::Storage::kFloat32),
      L_(c.num_lights()),
      H_(c.height()),
      W_(c.width()),
      C_(c.channels()) {
  h5::File& f = file_;
  f.WriteFormatHeader(kCodecFormat, c.method() == CodecMethod::kNeural ? kNeuralCodecFormatVersion : kCodecFormatVersion,
                      creator);
  f.WriteString("/provenance", c.info().provenance.dump());
  f.CreateGroup("/codec");
  f.SetAttr("/codec", "method", MethodName(c.method()));
  f.SetAttr("/codec", "color_space", c.info().color_space);
  f.SetAttr("/codec", "units", c.info().units);
  f.SetAttr("/codec", "cos_theta_i_included", std::int64_t(c.info().cos_theta_i_included ? 1 : 0));
  f.SetAttr("/codec", "channel_names", Join(c.info().channel_names));
  f.SetAttr("/codec", "texel_size_mm", c.info().texel_size_mm);
  f.SetAttr("/codec", "height", std::int64_t(c.height()));
  f.SetAttr("/codec", "width", std::int64_t(c.width()));
  f.SetAttr("/codec", "channels", std::int64_t(c.channels()));
  f.SetAttr("/codec", "transform", std::string(c.transform() == ValueTransform::kLog ? "log" : "none"));
  f.SetAttr("/codec", "log_epsilon", c.log_epsilon());
  f.SetAttr("/codec", "storage", std::string(storage_ == h5::Storage::kFloat16 ? "float16" : "float32"));
  WriteSamplingTables(f, "/codec/view", c.views());
  WriteSamplingTables(f, "/codec/light", c.lights());
  if (c.method() == CodecMethod::kPcaView) f.CreateGroup("/codec/pca_view");
}

void CodecFileWriter::WritePcaViewSlot(int v, const PcaViewSlot& s) {
  file_.WriteFloats(SlotName("mean", v), {H_, W_, C_}, s.mean.data(), storage_);
  if (s.components > 0) {
    const hsize_t k = s.components;
    file_.WriteFloats(SlotName("basis", v), {k, H_, W_, C_}, s.basis.data(), storage_);
    file_.WriteFloats(SlotName("weights", v), {L_, k}, s.weights.data(), storage_);
    file_.WriteDoubles(SlotName("eigenvalues", v), {k}, s.eigenvalues.data());
  }
  file_.StartWriteback();
}

void CodecFileWriter::Finish(const Codec& c, int slots_written) {
  h5::File& f = file_;
  const hsize_t V = c.num_views(), L = L_, H = H_, W = W_, C = C_;
  const h5::Storage st = storage_;
  if (c.method() == CodecMethod::kPcaView) {
    std::vector<std::int32_t> comps;
    for (const auto& s : c.pca_view()) comps.push_back(s.components);
    f.WriteInts("/codec/pca_view/components", {V}, comps.data());
    for (int v = slots_written; v < c.num_views(); ++v) WritePcaViewSlot(v, c.pca_view()[static_cast<std::size_t>(v)]);
  } else if (IsFullMatrixFactorisation(c.method())) {
    WriteFmfModel(f, c.fmf(), c.num_views(), c.height(), c.width());
  } else if (c.method() == CodecMethod::kLpcaTensor) {
    WriteLpcaTensorModel(f, c.lpca_tensor(), c.height(), c.width());
  } else if (c.method() == CodecMethod::kNeural) {
    WriteNeuralModel(f, c.neural(), c.height(), c.width());
  } else {
    const LpcaModel& m = c.lpca();
    const hsize_t K = m.clusters, k = m.components;
    f.CreateGroup("/codec/lpca");
    f.SetAttr("/codec/lpca", "clusters", std::int64_t(K));
    f.SetAttr("/codec/lpca", "components", std::int64_t(k));
    f.WriteFloats("/codec/lpca/means", {K, V, L, C}, m.means.data(), st);
    f.WriteInts("/codec/lpca/cluster_components", {K}, m.cluster_components.data());
    f.WriteInts("/codec/lpca/cluster_index", {H, W}, m.cluster_of.data());
    if (k > 0) {
      f.WriteFloats("/codec/lpca/basis", {K, k, V, L, C}, m.basis.data(), st);
      f.WriteFloats("/codec/lpca/weights", {H, W, k}, m.weights.data(), st);
    }
  }
  f.WriteString("/codec/compression", c.provenance().dump());
  f.Close();  // throws if the data did not all reach the file: nothing is committed
  out_.Commit();
}

Codec ReadCodec(const std::filesystem::path& path) {
  const h5::File f = h5::File::Open(path);
  f.CheckFormatHeader(kCodecFormat, kCodecFormatMajor);
  if (!f.Exists("/codec")) ThrowBadInput("'{}': required group '/codec' is missing", path.string());
  const CodecMethod method = [&] {
    const std::string m = f.GetString("/codec", "method");
    if (m != "pca-view" && m != "lpca" && m != "fmf" && m != "dfmf" && m != "lpca-tensor" && m != "neural")
      ThrowBadInput("'{}': unknown codec method '{}'", path.string(), m);
    return ParseMethod(m);
  }();
  DatasetInfo info;
  info.color_space = f.GetString("/codec", "color_space");
  info.units = f.GetString("/codec", "units");
  info.cos_theta_i_included = f.GetInt("/codec", "cos_theta_i_included") == 1;
  {
    std::stringstream ss(f.GetString("/codec", "channel_names"));
    info.channel_names.clear();
    std::string item;
    while (std::getline(ss, item, ',')) info.channel_names.push_back(item);
  }
  info.texel_size_mm = f.HasAttr("/codec", "texel_size_mm") ? f.GetDouble("/codec", "texel_size_mm") : 0.0;
  if (f.Exists("/provenance")) {
    info.provenance = nlohmann::json::parse(f.ReadString("/provenance"), nullptr, false);
    if (info.provenance.is_discarded()) ThrowBadInput("'{}': '/provenance' is not valid JSON", path.string());
  }
  const int H = ReadDim(f, "height", 1, 1 << 16), W = ReadDim(f, "width", 1, 1 << 16),
            C = ReadDim(f, "channels", 1, 64);
  if (static_cast<int>(info.channel_names.size()) != C)
    ThrowBadInput("'{}': {} channel names for {} channels", path.string(), info.channel_names.size(), C);
  const std::string tr = f.GetString("/codec", "transform");
  if (tr != "none" && tr != "log") ThrowBadInput("'{}': unknown transform '{}' (none or log)", path.string(), tr);
  const double eps = f.GetDouble("/codec", "log_epsilon");
  // Optional since 1.1.0; float16 arrays are converted to float on reading.
  const std::string storage = f.HasAttr("/codec", "storage") ? f.GetString("/codec", "storage") : "float32";
  if (storage != "float32" && storage != "float16")
    ThrowBadInput("'{}': unknown '/codec@storage' '{}' (float32 or float16)", path.string(), storage);
  if (tr == "log" && !(eps > 0 && std::isfinite(eps)))
    ThrowBadInput("'{}': log transform with invalid epsilon {}", path.string(), eps);
  Sampling views = ReadSamplingTables(f, "/codec/view"), lights = ReadSamplingTables(f, "/codec/light");
  const hsize_t V = views.size(), L = lights.size(), D = hsize_t(H) * W * C;
  Codec c = CodecBuilder::Make(method, views, lights, H, W, C, info, ValueMap{tr == "log" ? ValueTransform::kLog : ValueTransform::kNone, eps});
  CodecBuilder::storage(c) = storage == "float16" ? CodecStorage::kHalf : CodecStorage::kFloat;
  if (f.Exists("/codec/compression")) {
    auto j = nlohmann::json::parse(f.ReadString("/codec/compression"), nullptr, false);
    if (!j.is_discarded()) CodecBuilder::provenance(c) = j;
  }
  if (method == CodecMethod::kPcaView) {
    const auto comps = ReadIntsChecked(f, "/codec/pca_view/components", {V});
    auto& slots = CodecBuilder::slots(c);
    slots.resize(V);
    for (int v = 0; v < int(V); ++v) {
      PcaViewSlot& s = slots[static_cast<std::size_t>(v)];
      const int k = comps[static_cast<std::size_t>(v)];
      if (k < 0 || hsize_t(k) > L)
        ThrowBadInput("'{}': view slot {} claims {} components (at most {} lights)", path.string(), v, k, L);
      CheckAllocation(4.0 * (double(D) * (k + 1) + double(L) * k), fmt::format("'{}' view slot {}", path.string(), v));
      s.components = k;
      s.mean = ReadChecked(f, SlotName("mean", v), {hsize_t(H), hsize_t(W), hsize_t(C)});
      if (k == 0) continue;
      s.basis = ReadChecked(f, SlotName("basis", v), {hsize_t(k), hsize_t(H), hsize_t(W), hsize_t(C)});
      s.weights = ReadChecked(f, SlotName("weights", v), {L, hsize_t(k)});
      s.eigenvalues = f.Exists(SlotName("eigenvalues", v)) ? f.ReadDoubles(SlotName("eigenvalues", v))
                                                            : std::vector<double>(static_cast<std::size_t>(k), 0.0);
    }
  } else if (IsFullMatrixFactorisation(method)) {
    CodecBuilder::fmf(c) = ReadFmfModel(f, method == CodecMethod::kDfmf, int(V), int(L), H, W, C);
  } else if (method == CodecMethod::kLpcaTensor) {
    CodecBuilder::lpca_tensor(c) = ReadLpcaTensorModel(f, int(V), int(L), H, W, C);
  } else if (method == CodecMethod::kNeural) {
    CodecBuilder::neural(c) = ReadNeuralModel(f, H, W, C);
  } else {
    LpcaModel& m = CodecBuilder::lpca(c);
    const auto K = f.GetInt("/codec/lpca", "clusters"), k = f.GetInt("/codec/lpca", "components");
    if (K < 1 || K > std::int64_t(H) * W) ThrowBadInput("'{}': invalid cluster count {}", path.string(), K);
    if (k < 0 || k > 4096) ThrowBadInput("'{}': invalid component count {}", path.string(), k);
    m.clusters = static_cast<int>(K);
    m.components = static_cast<int>(k);
    const hsize_t d = V * L * C;
    CheckAllocation(4.0 * double(k + 1) * (double(d) * double(K) + double(H) * W),
                    fmt::format("'{}' LPCA model", path.string()));
    m.means = ReadChecked(f, "/codec/lpca/means", {hsize_t(K), V, L, hsize_t(C)});
    m.cluster_components = ReadIntsChecked(f, "/codec/lpca/cluster_components", {hsize_t(K)});
    for (std::size_t i = 0; i < m.cluster_components.size(); ++i)
      if (m.cluster_components[i] < 0 || m.cluster_components[i] > k)
        ThrowBadInput("'{}': cluster {} claims {} components (stride {})", path.string(), i, m.cluster_components[i], k);
    m.cluster_of = ReadIntsChecked(f, "/codec/lpca/cluster_index", {hsize_t(H), hsize_t(W)});
    for (std::size_t i = 0; i < m.cluster_of.size(); ++i)
      if (m.cluster_of[i] < 0 || m.cluster_of[i] >= K)
        ThrowBadInput("'{}': cluster_index of texel {} is {} (clusters: {})", path.string(), i, m.cluster_of[i], K);
    if (k > 0) {
      m.basis = ReadChecked(f, "/codec/lpca/basis", {hsize_t(K), hsize_t(k), V, L, hsize_t(C)});
      m.weights = ReadChecked(f, "/codec/lpca/weights", {hsize_t(H), hsize_t(W), hsize_t(k)});
    }
  }
  return c;
}

nlohmann::json DecodeSummary::ToJson() const {
  return {{"output", output}, {"method", method}, {"bytes_decoded", bytes_decoded}, {"seconds", times.ToJson()}};
}

std::string DecodeSummary::Report() const {
  return fmt::format("-> {} ({} decoded in {:.2f} s)\n", output, FormatBytes(bytes_decoded), times.Total());
}

std::string FormatBytes(std::uint64_t b) {
  if (b >= (1ull << 30)) return fmt::format("{:.2f} GiB", double(b) / (1ull << 30));
  if (b >= (1ull << 20)) return fmt::format("{:.2f} MiB", double(b) / (1ull << 20));
  if (b >= (1ull << 10)) return fmt::format("{:.1f} KiB", double(b) / (1ull << 10));
  return fmt::format("{} B", b);
}

DecodeSummary DecodeToDatasetFile(const Codec& codec, const std::filesystem::path& path, const Reporter& reporter) {
  Timer timer;
  DatasetInfo info = codec.info();
  info.provenance["decoded_from"] = {{"format", kCodecFormat}, {"method", MethodName(codec.method())}};
  DatasetWriter w(path, codec.views(), codec.lights(), codec.height(), codec.width(), codec.channels(), info,
                  DatasetWriteOptions{.creator = "btf-compress decode"});
  std::vector<float> slot(codec.image_size() * std::size_t(codec.num_lights()));
  for (int v = 0; v < codec.num_views(); ++v) {
    reporter.Progress(std::size_t(v), std::size_t(codec.num_views()), "decode");
    codec.DecodeViewSlot(v, slot.data());
    w.WriteViewSlot(v, slot.data());
  }
  reporter.Progress(std::size_t(codec.num_views()), std::size_t(codec.num_views()), "decode");
  w.Commit();
  DecodeSummary s;
  s.output = path.string();
  s.method = MethodName(codec.method());
  s.bytes_decoded = codec.RawBytes(4);
  s.times.Add("decode", timer.Seconds());
  return s;
}

}  // namespace btf
