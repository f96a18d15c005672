// The Python module `libbtf` (docs/python.md): open a dataset, codec or Bonn .btf file, read it as
// NumPy arrays, decode codecs at arbitrary (uv, wi, wo), compress and compare. A thin layer over
// the library's public API: every number comes from the same code the tools run, every error is
// the tools' message in a libbtf.Error carrying the tool's exit code.
//
// The GIL is held throughout: HDF5 is used from one thread at a time (libbtf/io/hdf5.h).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/compress/codec_source.h"
#include "libbtf/core/eigen_setup.h"
#include "libbtf/core/error.h"
#include "libbtf/core/version.h"
#include "libbtf/eval/metrics.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/hdf5.h"

namespace py = pybind11;

namespace {

using F32Array = py::array_t<float, py::array::c_style>;

py::object ToPython(const nlohmann::json& j) { return py::module_::import("json").attr("loads")(j.dump()); }

// The category names of docs/errors.md's exit codes, as libbtf.Error.category.
const char* Category(btf::ExitCode code) {
  switch (code) {
    case btf::ExitCode::kOk: return "ok";
    case btf::ExitCode::kFailedCheck: return "failed_check";
    case btf::ExitCode::kUsage: return "usage";
    case btf::ExitCode::kBadInput: return "bad_input";
    case btf::ExitCode::kIo: return "io";
    case btf::ExitCode::kInternal: return "internal";
    case btf::ExitCode::kInterrupted: return "interrupted";
  }
  return "internal";
}

// libbtf.Source: one open file.
class Source {
 public:
  // Any libbtf file, as btf-info and btf-eval compare open it; other formats are refused naming the file.
  explicit Source(const std::filesystem::path& path)
      : path_(path), source_(btf::OpenSource(path)), format_(source_->kind()),
        codec_(dynamic_cast<const btf::CodecSource*>(source_.get())) {}

  const btf::SlotSource& source() const { return *source_; }
  const btf::Codec* codec() const { return codec_ ? &codec_->codec() : nullptr; }
  const std::filesystem::path& path() const { return path_; }
  const std::string& format() const { return format_; }
  bool is_codec() const { return codec_ != nullptr; }

  py::tuple shape() const {
    const auto& s = *source_;
    return py::make_tuple(s.views().size(), s.lights().size(), s.height(), s.width(), s.channels());
  }

  py::dict conventions() const {
    const btf::DatasetInfo info = source_->info();
    py::dict d;
    d["color_space"] = info.color_space;
    d["units"] = info.units;
    d["cos_theta_i_included"] = info.cos_theta_i_included;
    d["channel_names"] = info.channel_names;
    d["texel_size_mm"] = info.texel_size_mm;
    d["provenance"] = ToPython(info.provenance);
    return d;
  }

  F32Array view_slot(int view) const {
    CheckIndex("view", view, source_->views().size());
    const auto& s = *source_;
    F32Array out({s.lights().size(), s.height(), s.width(), s.channels()});
    s.ReadViewSlot(view, out.mutable_data());
    return out;
  }

  F32Array image(int view, int light) const {
    CheckIndex("view", view, source_->views().size());
    CheckIndex("light", light, source_->lights().size());
    const auto& s = *source_;
    F32Array out({s.height(), s.width(), s.channels()});
    s.ReadImage(view, light, out.mutable_data());
    return out;
  }

  F32Array read_all() const {
    const auto& s = *source_;
    btf::CheckAllocation(double(s.slot_size()) * s.views().size() * sizeof(float), "'" + s.name() + "' read whole");
    F32Array out({s.views().size(), s.lights().size(), s.height(), s.width(), s.channels()});
    for (int v = 0; v < s.views().size(); ++v) s.ReadViewSlot(v, out.mutable_data() + v * s.slot_size());
    return out;
  }

  // views x lights x channels. A codec decodes the texel alone; other files read every view slot.
  F32Array abrdf(int y, int x) const {
    const auto& s = *source_;
    CheckIndex("y", y, s.height());
    CheckIndex("x", x, s.width());
    F32Array out({s.views().size(), s.lights().size(), s.channels()});
    float* o = out.mutable_data();
    if (codec_) {
      const std::vector<float> a = codec_->codec().DecodeAbrdf(y, x);
      std::copy(a.begin(), a.end(), o);
      return out;
    }
    std::vector<float> slot(s.slot_size());
    const std::size_t texel = (std::size_t(y) * s.width() + x) * s.channels();
    for (int v = 0; v < s.views().size(); ++v) {
      s.ReadViewSlot(v, slot.data());
      for (int l = 0; l < s.lights().size(); ++l)
        for (int c = 0; c < s.channels(); ++c)
          o[(std::size_t(v) * s.lights().size() + l) * s.channels() + c] = slot[l * s.image_size() + texel + c];
    }
    return out;
  }

  // Codec::Value at N points: uv (N, 2), wi and wo (N, 3), each also accepted as one row that is
  // repeated. Returns (N, channels).
  F32Array decode(const py::array_t<double, py::array::c_style | py::array::forcecast>& uv,
                  const py::array_t<double, py::array::c_style | py::array::forcecast>& wi,
                  const py::array_t<double, py::array::c_style | py::array::forcecast>& wo,
                  const std::string& filter) const {
    if (!codec_)
      btf::ThrowUsage("'{}' is a {}, not a codec: decode() evaluates codecs; read datasets with image() or view_slot()",
                      path_.string(), format_);
    btf::UvFilter f = btf::UvFilter::kBilinear;
    if (filter == "nearest")
      f = btf::UvFilter::kNearest;
    else if (filter != "bilinear")
      btf::ThrowUsage("invalid option 'filter': '{}' (use 'bilinear' or 'nearest')", filter);
    const py::ssize_t nu = Rows(uv, 2, "uv"), ni = Rows(wi, 3, "wi"), no = Rows(wo, 3, "wo");
    const py::ssize_t n = std::max({nu, ni, no});
    for (const auto& [rows, name] : {std::pair{nu, "uv"}, std::pair{ni, "wi"}, std::pair{no, "wo"}})
      if (rows != n && rows != 1)
        btf::ThrowUsage("decode: '{}' has {} rows but another argument has {}; give N rows (or one) each", name, rows, n);
    const btf::Codec& codec = codec_->codec();
    F32Array out({n, py::ssize_t(codec.channels())});
    const double *pu = uv.data(), *pi = wi.data(), *po = wo.data();
    const bool su = nu > 1, si = ni > 1, so = no > 1;
    for (py::ssize_t k = 0; k < n; ++k) {
      const double* u = pu + (su ? 2 * k : 0);
      const double* i = pi + (si ? 3 * k : 0);
      const double* o = po + (so ? 3 * k : 0);
      codec.Value(btf::Vec2(u[0], u[1]), btf::Vec3(i[0], i[1], i[2]), btf::Vec3(o[0], o[1], o[2]),
                  out.mutable_data() + k * codec.channels(), f);
    }
    return out;
  }

  // btf-info's summary (without the value scan unless stats); an open codec is not read again.
  py::object describe(bool stats) const {
    return ToPython(codec_ ? codec_->Describe() : btf::DescribeFile(path_, stats));
  }

 private:
  static void CheckIndex(const char* what, int i, int n) {
    if (i < 0 || i >= n) btf::ThrowUsage("{} index {} is out of range [0, {})", what, i, n);
  }
  // Rows of an (N, cols) or (cols,) array; anything else is a usage error naming the argument.
  static py::ssize_t Rows(const py::array_t<double, py::array::c_style | py::array::forcecast>& a, py::ssize_t cols,
                          const char* name) {
    if (a.ndim() == 1 && a.shape(0) == cols) return 1;
    if (a.ndim() == 2 && a.shape(1) == cols) return a.shape(0);
    btf::ThrowUsage("decode: '{}' must have shape (N, {}) or ({},)", name, cols, cols);
  }

  std::filesystem::path path_;
  std::unique_ptr<btf::SlotSource> source_;
  std::string format_;
  const btf::CodecSource* codec_;  // source_ when the file is a codec, else nullptr
};

// A neural codec's decoder and latents (docs/format.md, "Neural"), read-only views as below:
// `latents` (H, W, c), the stored latents as float (what decodes); per layer n `weights`[n]
// (out_n, in_n) and `biases`[n] (out_n,).
py::dict NeuralCoefficients(const py::object& self, const btf::Codec& c, py::dict d) {
  const btf::NeuralCodecModel& m = c.neural();
  auto frozen = [](py::array_t<float> a) {
    a.attr("setflags")(py::arg("write") = false);
    return a;
  };
  const py::ssize_t H = c.height(), W = c.width(), k = m.latent, f = sizeof(float);
  d["latents"] = frozen(py::array_t<float>({H, W, k}, m.latents.data(), self));
  py::list weights, biases;
  for (int l = 0; l < m.net.layers(); ++l) {
    const auto w = m.net.weight(l);  // column-major out x in
    const py::ssize_t out = w.rows(), in = w.cols();
    weights.append(frozen(py::array_t<float>({out, in}, {f, f * out}, w.data(), self)));
    biases.append(frozen(py::array_t<float>({out}, m.net.bias(l).data(), self)));
  }
  d["weights"] = weights;
  d["biases"] = biases;
  d["activation"] = std::string(btf::ActivationName(m.net.shape().activation));
  d["half_vector"] = m.encoding.half_vector;
  d["fourier"] = m.encoding.fourier;
  d["latent_storage"] = btf::LatentStorageName(m.storage);
  return d;
}

// A codec's stored coefficients as read-only NumPy arrays over the Codec's own memory (no copy);
// each array keeps the Source `self` alive. Layouts: libbtf/compress/codec.h, docs/format.md.
py::dict Coefficients(const py::object& self) {
  const Source& src = self.cast<const Source&>();
  if (!src.codec())
    btf::ThrowUsage("'{}' is a {}, not a codec: only codecs have coefficients", src.path().string(), src.format());
  const btf::Codec& c = *src.codec();
  auto view = [&self](const auto& values, std::vector<py::ssize_t> shape) {
    using T = typename std::decay_t<decltype(values)>::value_type;
    py::array_t<T> a(shape, values.data(), self);
    a.attr("setflags")(py::arg("write") = false);
    return a;
  };
  const py::ssize_t V = c.num_views(), L = c.num_lights(), H = c.height(), W = c.width(), C = c.channels();
  py::dict d;
  d["method"] = btf::MethodName(c.method());
  d["transform"] = c.transform() == btf::ValueTransform::kLog ? "log" : "none";
  d["log_epsilon"] = c.log_epsilon();
  if (c.method() == btf::CodecMethod::kNeural) return NeuralCoefficients(self, c, d);
  if (c.method() != btf::CodecMethod::kPcaView && c.method() != btf::CodecMethod::kLpca)
    btf::ThrowUsage("'{}': coefficients() reads pca-view, lpca and neural codecs, not {}", src.path().string(),
                    btf::MethodName(c.method()));
  if (c.method() == btf::CodecMethod::kPcaView) {
    py::list slots;
    for (const btf::PcaViewSlot& s : c.pca_view()) {
      py::dict slot;
      const py::ssize_t k = s.components;
      slot["mean"] = view(s.mean, {H, W, C});
      slot["basis"] = view(s.basis, {k, H, W, C});
      slot["weights"] = view(s.weights, {L, k});
      slot["eigenvalues"] = view(s.eigenvalues, {k});
      slots.append(slot);
    }
    d["slots"] = slots;
  } else {
    const btf::LpcaModel& m = c.lpca();
    const py::ssize_t k = m.clusters, n = m.components;
    d["means"] = view(m.means, {k, V, L, C});
    d["basis"] = view(m.basis, {k, n, V, L, C});
    d["cluster_components"] = view(m.cluster_components, {k});
    d["cluster_of"] = view(m.cluster_of, {H, W});
    d["weights"] = view(m.weights, {H, W, n});
  }
  return d;
}

py::dict SamplingDict(const btf::Sampling& s) {
  py::array_t<double> dirs({py::ssize_t(s.size()), py::ssize_t(3)});
  py::array_t<double> angles({py::ssize_t(s.size()), py::ssize_t(2)});
  auto d = dirs.mutable_unchecked<2>();
  auto a = angles.mutable_unchecked<2>();
  for (int i = 0; i < s.size(); ++i) {
    for (int k = 0; k < 3; ++k) d(i, k) = s[i][k];
    a(i, 0) = s.angles(i).theta;
    a(i, 1) = s.angles(i).phi;
  }
  py::dict out;
  out["name"] = s.name();
  out["directions"] = dirs;
  out["angles"] = angles;
  return out;
}

// A Reporter whose progress callback lets Ctrl-C stop the work (btf::Cancelled, raised as
// KeyboardInterrupt) and forwards to the user's progress(done, total, stage) -> bool.
struct PyReporter {
  explicit PyReporter(std::optional<py::function> progress) : progress(std::move(progress)) {}
  std::optional<py::function> progress;
  bool interrupted = false;
  std::optional<py::error_already_set> callback_error;

  btf::Reporter Make() {
    return btf::Reporter({}, [this](std::size_t done, std::size_t total, std::string_view stage) {
      if (PyErr_CheckSignals() != 0) {
        interrupted = true;
        return false;
      }
      if (!progress) return true;
      try {
        py::object r = (*progress)(done, total, std::string(stage));
        return r.is_none() || r.cast<bool>();
      } catch (py::error_already_set& e) {
        callback_error = std::move(e);
        return false;
      }
    });
  }
  // After a btf::Cancelled: re-raise what stopped it.
  void Rethrow() {
    if (callback_error) throw std::move(*callback_error);
    if (interrupted) throw py::error_already_set();  // the KeyboardInterrupt PyErr_CheckSignals set
  }
};

// libbtf.compress's keywords: btf-compress's options by their names with dashes as underscores
// (docs/python.md), each read from CompressOptions for its default and written into it from the
// call, in the order of the signature. Applied in that order: method and storage are parsed
// (usage errors naming them) before the scene file is read.
template <typename T, typename Get, typename Set>
struct Keyword {
  using Value = T;
  const char* name;
  Get get;  // T(const CompressOptions&)
  Set set;  // void(CompressOptions&, const T&)
};

template <typename T, typename Get, typename Set>
Keyword<T, Get, Set> Converted(const char* name, Get get, Set set) {
  return {name, get, set};
}

// A keyword that is a field of CompressOptions as it is; `field` returns it (const or not).
template <typename Field>
auto Member(const char* name, Field field) {
  using T = std::decay_t<decltype(field(std::declval<btf::CompressOptions&>()))>;
  return Converted<T>(
      name, [field](const btf::CompressOptions& o) -> T { return field(o); },
      [field](btf::CompressOptions& o, const T& v) { field(o) = v; });
}

auto CompressKeywords() {
  using btf::CompressOptions;
  using Path = std::optional<std::filesystem::path>;
  return std::make_tuple(
      Converted<std::string>(
          "method", [](const CompressOptions& o) { return btf::MethodName(o.method); },
          [](CompressOptions& o, const std::string& v) { o.method = btf::ParseMethod(v); }),
      Member("components", [](auto& o) -> auto& { return o.components; }),
      Member("clusters", [](auto& o) -> auto& { return o.clusters; }),
      Member("error", [](auto& o) -> auto& { return o.target_error; }),
      Member("energy", [](auto& o) -> auto& { return o.retained_energy; }),
      Member("bytes", [](auto& o) -> auto& { return o.max_bytes; }),
      Converted<std::string>(
          "storage", [](const CompressOptions& o) { return btf::StorageName(o.storage); },
          [](CompressOptions& o, const std::string& v) { o.storage = btf::ParseStorage(v); }),
      Member("quant_bits", [](auto& o) -> auto& { return o.tensor.quant_bits; }),
      Member("tensor_growth", [](auto& o) -> auto& { return o.tensor.growth; }),
      Member("seed", [](auto& o) -> auto& { return o.seed; }),
      Member("log", [](auto& o) -> auto& { return o.log_transform; }),
      Member("log_epsilon", [](auto& o) -> auto& { return o.log_epsilon; }),
      Member("max_iterations", [](auto& o) -> auto& { return o.lpca.max_iterations; }),
      Member("min_improvement", [](auto& o) -> auto& { return o.lpca.min_improvement; }),
      Member("lpca_memory", [](auto& o) -> auto& { return o.lpca.memory; }),
      Member("lpca_sample", [](auto& o) -> auto& { return o.lpca.sample; }),
      Member("lpca_splits", [](auto& o) -> auto& { return o.lpca.splits; }),
      Member("lpca_subspace", [](auto& o) -> auto& { return o.lpca.subspace; }),
      Member("lpca_matrix", [](auto& o) -> auto& { return o.lpca.matrix; }),
      Member("neural_latent", [](auto& o) -> auto& { return o.neural.latent; }),
      Member("neural_hidden", [](auto& o) -> auto& { return o.neural.hidden; }),
      Member("neural_fourier", [](auto& o) -> auto& { return o.neural.fourier; }),
      Member("neural_latent_storage", [](auto& o) -> auto& { return o.neural.latent_storage; }),
      Member("neural_samples", [](auto& o) -> auto& { return o.neural.samples; }),
      Member("neural_steps", [](auto& o) -> auto& { return o.neural.steps; }),
      Member("neural_epochs", [](auto& o) -> auto& { return o.neural.epochs; }),
      Member("neural_batch", [](auto& o) -> auto& { return o.neural.batch; }),
      Member("neural_lr", [](auto& o) -> auto& { return o.neural.learning_rate; }),
      Member("neural_linear_loss", [](auto& o) -> auto& { return o.neural.linear_loss; }),
      // The path of a scene.json (SceneSpec::Load); a default CompressOptions has no scene: None.
      Converted<Path>(
          "scene", [](const CompressOptions&) { return Path(); },
          [](CompressOptions& o, const Path& v) {
            if (v) o.scene = btf::SceneSpec::Load(*v);
          }));
}

// btf-compress INPUT -o OUTPUT with checked options.
py::object RunCompress(const btf::CompressOptions& o, const std::filesystem::path& input,
                       const std::filesystem::path& output, const std::optional<py::function>& progress) {
  o.Check();
  btf::CheckOutput(output, {input});
  // As btf-compress: claim the output first, so an unwritable folder fails before the work.
  btf::AtomicOutput target(output, btf::AtomicOutput::kReserve);
  const auto source = btf::OpenCompressInput(input);
  PyReporter reporter(progress);
  btf::CompressSummary s;
  try {
    s = btf::CompressToFile(o, *source, &target, "libbtf-python", reporter.Make());
  } catch (const btf::Cancelled&) {
    reporter.Rethrow();
    throw;
  }
  nlohmann::json j = s.ToJson();
  j["output"] = output.string();
  return ToPython(j);
}

// Defines libbtf.compress(input, output, *, <keywords>, progress=None): one typed parameter per
// keyword (pybind11 converts and type-checks each), defaults from a default CompressOptions.
template <typename... K>
void DefineCompress(py::module_& m, const std::tuple<K...>& keywords) {
  const btf::CompressOptions defaults;
  std::apply(
      [&](const K&... k) {
        m.def(
            "compress",
            [keywords](const std::filesystem::path& input, const std::filesystem::path& output,
                       const typename K::Value&... values, const std::optional<py::function>& progress) {
              btf::CompressOptions o;
              std::apply([&](const K&... kw) { (kw.set(o, values), ...); }, keywords);
              return RunCompress(o, input, output, progress);
            },
            py::arg("input"), py::arg("output"), py::kw_only(), (py::arg(k.name) = k.get(defaults))...,
            py::arg("progress") = py::none(),
            "btf-compress INPUT -o OUTPUT with the same options; returns its --json summary as a dict");
      },
      keywords);
}

py::object Compare(const py::object& reference, const py::object& test, double peak, double ssim_sigma, bool ssim,
                   const std::optional<std::filesystem::path>& error_maps, int maps, int worst_images,
                   const std::optional<py::function>& progress) {
  // A libbtf.Source or a path (opened as btf-eval compare does).
  auto resolve = [](const py::object& o, std::unique_ptr<Source>& owned) -> const btf::SlotSource& {
    if (py::isinstance<Source>(o)) return o.cast<const Source&>().source();
    owned = std::make_unique<Source>(o.cast<std::filesystem::path>());
    return owned->source();
  };
  std::unique_ptr<Source> ref_owned, test_owned;
  const btf::SlotSource& ref = resolve(reference, ref_owned);
  const btf::SlotSource& tst = resolve(test, test_owned);
  btf::CompareOptions o;
  o.peak = peak;
  o.ssim_sigma = ssim_sigma;
  o.ssim = ssim;
  if (error_maps) {  // as btf-eval compare --error-maps: the folder is created
    o.error_maps_dir = *error_maps;
    std::filesystem::create_directories(*error_maps);
  }
  o.error_maps = maps;
  o.worst_images = worst_images;
  o.Check();
  PyReporter reporter(progress);
  try {
    return ToPython(btf::Compare(o, ref, tst, reporter.Make()).ToJson());
  } catch (const btf::Cancelled&) {
    reporter.Rethrow();
    throw;
  }
}

}  // namespace

PYBIND11_MODULE(libbtf, m) {
  // Every array libbtf returns or takes is a NumPy array: without NumPy the import fails here,
  // naming it, instead of at the first array.
  try {
    py::module_::import("numpy");
  } catch (const py::error_already_set&) {
    throw py::import_error("libbtf needs NumPy, which this Python cannot import: install it (Debian: apt install "
                           "python3-numpy; pip: pip install numpy)");
  }
  m.doc() = "libbtf: BTF datasets, codecs and Bonn .btf files as NumPy arrays (docs/python.md)";
  m.attr("__version__") = btf::Version();
  btf::h5::SilenceErrors();
  btf::FixEigenBlocking();

  // libbtf.Error(message): .exit_code (docs/errors.md), .category ("usage", "bad_input", "io", ...).
  static py::exception<btf::Error> error(m, "Error", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const btf::Error& thrown) {
      // As the tools' handler: a file read as damaged after a failed read system call is an I/O error.
      const btf::Error e = btf::h5::ReportedError(thrown);
      py::object exc = py::handle(error)(e.what());
      exc.attr("exit_code") = static_cast<int>(e.code());
      exc.attr("category") = Category(e.code());
      PyErr_SetObject(error.ptr(), exc.ptr());
    }
  });

  py::class_<Source>(m, "Source", "An open dataset, codec or Bonn .btf file (libbtf.open)")
      .def_property_readonly("path", [](const Source& s) { return s.path().string(); })
      .def_property_readonly("format", &Source::format,
                             "'libbtf-dataset', 'libbtf-codec', 'bonn-bdi', 'bonn-dfmf', 'bonn-fmf' or 'bonn-pvf'")
      .def_property_readonly("is_codec", &Source::is_codec)
      .def_property_readonly("shape", &Source::shape, "(views, lights, height, width, channels)")
      .def_property_readonly("views", [](const Source& s) { return SamplingDict(s.source().views()); },
                             "view sampling: {'name', 'directions' (n, 3), 'angles' (n, 2) theta, phi in radians}")
      .def_property_readonly("lights", [](const Source& s) { return SamplingDict(s.source().lights()); },
                             "light sampling, as views")
      .def_property_readonly("conventions", &Source::conventions,
                             "color_space, units, cos_theta_i_included, channel_names, texel_size_mm, provenance")
      .def("view_slot", &Source::view_slot, py::arg("view"), "float32 (lights, height, width, channels)")
      .def("image", &Source::image, py::arg("view"), py::arg("light"), "float32 (height, width, channels)")
      .def(
          "write_image",
          [](const Source& s, int view, int light, const std::filesystem::path& path, double exposure) {
            btf::CheckOutput(path, {s.path()});
            btf::WriteSampleImage(s.source(), view, light, exposure, path);
          },
          py::arg("view"), py::arg("light"), py::arg("path"), py::kw_only(), py::arg("exposure") = 1.0,
          "writes image (view, light) as .png (8-bit sRGB of exposure x value, clamped, as the renders) or .exr "
          "(linear float x exposure), as btf-convert --view --light does")
      .def("abrdf", &Source::abrdf, py::arg("y"), py::arg("x"), "float32 (views, lights, channels) of texel (y, x)")
      .def("read_all", &Source::read_all, "float32 (views, lights, height, width, channels)")
      .def("decode", &Source::decode, py::arg("uv"), py::arg("wi"), py::arg("wo"), py::arg("filter") = "bilinear",
           "codec value at uv (N, 2), light wi (N, 3) and view wo (N, 3): float32 (N, channels)")
      .def("describe", &Source::describe, py::arg("stats") = false, "btf-info's summary as a dict")
      .def("coefficients", &Coefficients, "codecs: the stored coefficients as read-only arrays (no copy)")
      .def("__repr__", [](const Source& s) {
        const auto& src = s.source();
        return "<libbtf.Source " + s.format() + " '" + s.path().string() + "' " + std::to_string(src.views().size()) +
               "x" + std::to_string(src.lights().size()) + "x" + std::to_string(src.height()) + "x" +
               std::to_string(src.width()) + "x" + std::to_string(src.channels()) + ">";
      });

  m.def("open", [](const std::filesystem::path& path) { return Source(path); }, py::arg("path"),
        "Opens a libbtf dataset or codec file, or a Bonn .btf file");

  DefineCompress(m, CompressKeywords());

  const btf::CompareOptions mo;
  m.def("compare", &Compare, py::arg("reference"), py::arg("test"), py::kw_only(), py::arg("peak") = mo.peak,
        py::arg("ssim_sigma") = mo.ssim_sigma, py::arg("ssim") = mo.ssim, py::arg("error_maps") = py::none(),
        py::arg("maps") = mo.error_maps, py::arg("worst_images") = mo.worst_images, py::arg("progress") = py::none(),
        "btf-eval compare REFERENCE TEST: error metrics as a dict (paths or libbtf.Source objects)");
}
