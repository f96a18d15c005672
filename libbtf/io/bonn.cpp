#include "libbtf/io/bonn.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>

#include <Eigen/Core>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/io/half.h"

namespace btf {

static_assert(std::endian::native == std::endian::little, "Bonn files are little-endian; this reader does not swap");

namespace {

// Known signatures, longest first so that the longest match wins (docs/format.md).
constexpr const char* kSignatures[] = {"!BDIF06R2!", "!DFMF08FCR", "!FMF12FCER", "!FMF06FCR",
                                       "!PVF06FCR",  "!FMF06FC",   "!PVF06FC"};
constexpr std::int32_t kLegacyPvfMagic = 301074;

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A read-only file accessed by offset (pread), so several threads may decode at once.
class BinFile {
 public:
  explicit BinFile(const std::filesystem::path& path) : path_(path.string()) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) ThrowIo("cannot open '{}': no such file", path_);
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) ThrowIo("cannot open '{}': {}", path_, std::strerror(errno));
    const off_t end = ::lseek(fd_, 0, SEEK_END);
    if (end < 0) {
      ::close(fd_);
      ThrowIo("cannot read '{}': {}", path_, std::strerror(errno));
    }
    size_ = std::uint64_t(end);
  }
  ~BinFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  BinFile(const BinFile&) = delete;
  BinFile& operator=(const BinFile&) = delete;

  const std::string& path() const { return path_; }
  std::uint64_t size() const { return size_; }

  // Throws bad input unless [offset, offset + bytes) lies in the file. `bytes` in double: a
  // header's counts can multiply past 2^64.
  void Need(std::uint64_t offset, double bytes, const std::string& field) const {
    if (double(offset) + bytes > double(size_))
      ThrowBadInput("'{}': {} at byte {} needs {:.0f} bytes but the file ends at byte {}: the file is truncated or "
                    "the field is corrupt",
                    path_, field, offset, bytes, size_);
  }
  void ReadAt(std::uint64_t offset, void* dst, std::size_t bytes, const std::string& field) const {
    Need(offset, double(bytes), field);
    auto* p = static_cast<char*>(dst);
    while (bytes > 0) {
      const ssize_t got = ::pread(fd_, p, bytes, off_t(offset));
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) ThrowIo("cannot read '{}' at byte {}: {}", path_, offset, got < 0 ? std::strerror(errno) : "end of file");
      p += got;
      offset += std::uint64_t(got);
      bytes -= std::size_t(got);
    }
  }

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

// Sequential reading of header fields; errors name the field and its byte offset.
class Cursor {
 public:
  Cursor(const BinFile& f, std::uint64_t pos) : f_(f), pos_(pos) {}
  std::uint64_t pos() const { return pos_; }
  void Skip(double bytes, const std::string& field) {
    f_.Need(pos_, bytes, field);
    pos_ += std::uint64_t(bytes);
  }
  template <typename T>
  T Get(const std::string& field) {
    T v;
    f_.ReadAt(pos_, &v, sizeof v, field);
    pos_ += sizeof v;
    return v;
  }
  std::uint32_t U32(const std::string& field) { return Get<std::uint32_t>(field); }
  float F32(const std::string& field) {
    const std::uint64_t at = pos_;
    const float v = Get<float>(field);
    if (!std::isfinite(v)) Fail(at, field, fmt::format("holds {}; it must be finite", v));
    return v;
  }
  std::string Chars(std::size_t n, const std::string& field) {
    std::string s(n, '\0');
    f_.ReadAt(pos_, s.data(), n, field);
    pos_ += n;
    return s;
  }
  // A count that must lie in [lo, hi].
  std::uint32_t Count(const std::string& field, std::uint32_t lo, std::uint32_t hi) {
    const std::uint64_t at = pos_;
    const std::uint32_t v = U32(field);
    if (v < lo || v > hi) Fail(at, field, fmt::format("is {}; expected {} to {}", v, lo, hi));
    return v;
  }
  [[noreturn]] void Fail(std::uint64_t at, const std::string& field, const std::string& problem) const {
    ThrowBadInput("'{}': {} at byte {} {}", f_.path(), field, at, problem);
  }
  const BinFile& file() const { return f_; }

 private:
  const BinFile& f_;
  std::uint64_t pos_;
};

std::string TrimNul(const std::string& s) {
  const auto end = s.find('\0');
  std::string t = end == std::string::npos ? s : s.substr(0, end);
  while (!t.empty() && (t.back() == ' ' || t.back() == '\n' || t.back() == '\r')) t.pop_back();
  return t;
}

float ScalarAt(const unsigned char* p, int scalar_size) {
  switch (scalar_size) {
    case 2: {
      std::uint16_t h;
      std::memcpy(&h, p, 2);
      return HalfToFloat(h);
    }
    case 4: {
      float f;
      std::memcpy(&f, p, 4);
      return f;
    }
    default: {
      double d;
      std::memcpy(&d, p, 8);
      return float(d);
    }
  }
}

int ScalarSize(Cursor& c, const std::string& field) {
  const std::uint64_t at = c.pos();
  const int s = c.Get<std::uint8_t>(field);
  if (s != 2 && s != 4 && s != 8) c.Fail(at, field, fmt::format("is {}; expected 2 (half), 4 (float) or 8 (double)", s));
  return s;
}

// One stored factor matrix: where it is and how to read it (rows x stride scalars, row-major,
// of which the first k columns are used).
struct MatrixRef {
  std::uint64_t offset = 0;
  std::uint64_t rows = 0;
  int stride = 0, k = 0, scalar_size = 2;
  std::string field;
  double bytes() const { return double(rows) * stride * scalar_size; }
};

MatrixRef Locate(Cursor& c, std::uint64_t rows, int stride, int k, int scalar_size, const std::string& field) {
  MatrixRef m{c.pos(), rows, stride, k, scalar_size, field};
  c.Skip(m.bytes(), field);
  return m;
}

// Reads a factor matrix into rows x k floats; NaN/Inf are refused naming the element's offset.
RowMatrix Load(const BinFile& f, const MatrixRef& m) {
  CheckAllocation(4.0 * double(m.rows) * m.k, fmt::format("'{}': {}", f.path(), m.field));
  RowMatrix out(Eigen::Index(m.rows), m.k);
  const std::size_t row_bytes = std::size_t(m.stride) * m.scalar_size;
  const std::size_t rows_per_read = std::max<std::size_t>(1, (std::size_t(8) << 20) / std::max<std::size_t>(1, row_bytes));
  std::vector<unsigned char> buf;
  for (std::uint64_t r0 = 0; r0 < m.rows && row_bytes > 0; r0 += rows_per_read) {
    const std::size_t n = std::size_t(std::min<std::uint64_t>(rows_per_read, m.rows - r0));
    buf.resize(n * row_bytes);
    const std::uint64_t at = m.offset + r0 * row_bytes;
    f.ReadAt(at, buf.data(), buf.size(), m.field);
    for (std::size_t r = 0; r < n; ++r)
      for (int j = 0; j < m.k; ++j) {
        const std::size_t i = r * row_bytes + std::size_t(j) * m.scalar_size;
        const float v = ScalarAt(buf.data() + i, m.scalar_size);
        if (!std::isfinite(v))
          ThrowBadInput("'{}': {} at byte {} (row {}, component {}) holds {}; factors must be finite", f.path(),
                        m.field, at + i, r0 + r, j, v);
        out(Eigen::Index(r0 + r), j) = v;
      }
  }
  return out;
}

// Per view slot of a PVF file.
struct PvfView {
  std::uint64_t weights_rows = 0, dim = 0;
  int k = 0, scalar_size = 2;
  std::uint64_t mean_offset = 0;
  MatrixRef components, weights;
};

// DFMF colour models (decorrelations) this reader undoes; others are refused (bad input).
// 0 RGB, 1 YUV, 3 PCA, 4 YCoCg, 9 Ylog_UV, 10 Ylog_Ulog_Vlog, 11 Ylog_UdivY_VdivY, 12 log RGB.
bool BonnColorModelSupported(int m) { return m == 0 || m == 1 || m == 3 || m == 4 || (m >= 9 && m <= 12); }


// Undoes colour model `model` on `n` pixels of 3 (or, for models 0 and 12, `channels`) values in
// place. `mean` and `transform` (row-major) are used by model 3 only.
void BonnUndecorrelate(int model, const std::array<float, 3>& mean, const std::array<float, 9>& t, int channels,
                       float* values, std::size_t n) {
  const double eps = kBonnEpsilon;
  if (model == 0) return;
  if (model == 12) {
    for (std::size_t i = 0; i < n * std::size_t(channels); ++i) values[i] = float(std::exp(double(values[i])) - eps);
    return;
  }
  BTF_CHECK(channels == 3 && BonnColorModelSupported(model));
  for (std::size_t i = 0; i < n; ++i) {
    float* p = values + 3 * i;
    double a = p[0], b = p[1], c = p[2];
    double r = 0, g = 0, bl = 0;
    if (model == 3) {
      r = a * t[0] + b * t[3] + c * t[6] + mean[0];
      g = a * t[1] + b * t[4] + c * t[7] + mean[1];
      bl = a * t[2] + b * t[5] + c * t[8] + mean[2];
    } else if (model == 4) {
      r = a + b - c;
      g = a + c;
      bl = a - b - c;
    } else {
      // YUV family: model 1 stores YUV; 9-11 store a logarithmic Y and U, V as below.
      if (model >= 9) a = std::exp(a) - eps;
      if (model == 10) {
        b = b == 0 ? 0 : std::copysign(eps * std::exp(std::abs(b)), b);
        c = c == 0 ? 0 : std::copysign(eps * std::exp(std::abs(c)), c);
      } else if (model == 11) {
        b *= a + eps;
        c *= a + eps;
      }
      r = a + 1.13983 * c;
      g = a - 0.39465 * b - 0.5806 * c;
      bl = a + 2.03211 * b;
    }
    p[0] = float(r);
    p[1] = float(g);
    p[2] = float(bl);
  }
}

}  // namespace

const char* BonnFormatName(BonnFormat format) {
  switch (format) {
    case BonnFormat::kBdi: return "bdi";
    case BonnFormat::kDfmf: return "dfmf";
    case BonnFormat::kFmf: return "fmf";
    case BonnFormat::kPvf: return "pvf";
  }
  return "?";
}

std::string BonnColorModelName(int m) {
  static const char* const kNames[] = {"rgb",     "yuv",     "lab",           "pca",           "ycocg",
                                       "spectral", "spectral_linear", "unknown", "unknown", "ylog_uv",
                                       "ylog_ulog_vlog", "ylog_udivy_vdivy", "log_rgb"};
  return m >= 0 && m <= 12 ? kNames[m] : "unknown";
}

std::string BonnSignatureOf(const std::filesystem::path& path) {
  const BinFile f(path);
  char head[16] = {};
  const std::size_t n = std::size_t(std::min<std::uint64_t>(f.size(), 10));
  if (n == 0) return "";
  f.ReadAt(0, head, n, "signature");
  if (head[0] != '!') return "";
  const std::string h(head, n);
  for (const char* s : kSignatures)
    if (h.starts_with(s)) return s;
  std::string shown;
  for (char ch : h) shown += (ch >= 32 && ch < 127) ? ch : '?';
  ThrowBadInput("'{}': signature at byte 0 is '{}', which is no known Bonn .btf signature (known: !DFMF08FCR, "
                "!FMF12FCER, !FMF06FCR, !FMF06FC, !PVF06FCR, !PVF06FC, !BDIF06R2!)",
                path.string(), shown);
}

bool IsBonnFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  char c = 0;
  {
    const BinFile f(path);
    if (f.size() == 0) return false;
    f.ReadAt(0, &c, 1, "signature");
  }
  return c == '!';
}

DatasetInfo BonnHeader::Info() const {
  DatasetInfo info;
  info.units = "relative";
  info.color_space = channel_names == std::vector<std::string>{"R", "G", "B"} ? "linear_srgb" : "multispectral";
  info.cos_theta_i_included = cosine_flag;
  info.channel_names = channel_names;
  info.texel_size_mm = ppmm > 0 ? 1.0 / ppmm : 0.0;
  info.provenance = {{"source", "bonn-btf"},
                     {"file", std::filesystem::path(path).filename().string()},
                     {"signature", signature},
                     {"measurement_setup", measurement_setup},
                     {"image_sensor", image_sensor},
                     {"light_source", light_source},
                     {"rgb_scale_factor", rgb_scale_factor}};
  return info;
}

struct BonnReader::Impl {
  explicit Impl(const std::filesystem::path& p) : file(p) {}
  BinFile file;
  BonnHeader h;
  // DFMF: per channel; FMF: one. `abrdf` rows are directions (and channels for FMF), `texture`
  // rows are texels (and channels for transposed FMF).
  std::vector<MatrixRef> abrdf_refs, texture_refs;
  std::vector<RowMatrix> abrdf, texture;
  std::vector<PvfView> pvf;
  std::vector<std::uint64_t> chunk_offsets;
  std::vector<std::int64_t> storage_index;  // BDI: texel -> stored ABRDF index, -1 = masked out
  bool loaded = false;

  void ReadMeta(Cursor& c);
  void ReadSampling(Cursor& c);
  void ReadSize(Cursor& c, bool rotations);
  void ReadRotations(Cursor& c);
  void ReadDfmf(Cursor& c);
  void ReadFmf(Cursor& c);
  void ReadPvf(Cursor& c);
  void ReadBdi(Cursor& c);
  void CheckEnd(const Cursor& c) const {
    if (c.pos() != file.size())
      ThrowBadInput("'{}': {} trailing bytes after the last block (which ends at byte {}): the sizes in the header "
                    "disagree with the file length",
                    file.path(), file.size() - c.pos(), c.pos());
  }
  void DecodeSlot(int view, float* out) const;
};

void BonnReader::Impl::ReadMeta(Cursor& c) {
  const std::uint64_t start = c.pos();
  const std::uint32_t size = c.U32("meta block struct_size");
  h.meta_version = c.Count("meta block struct_version", 1, 4);
  h.measurement_setup = TrimNul(c.Chars(80, "measurement_setup"));
  h.image_sensor = TrimNul(c.Chars(80, "image_sensor"));
  h.light_source = TrimNul(c.Chars(80, "light_source"));
  h.ppmm = c.F32("ppmm");
  for (int i = 0; i < 3; ++i) h.rgb_scale_factor[std::size_t(i)] = c.F32("rgb_scale_factor");
  if (h.meta_version > 1) h.cosine_flag = c.U32("cosine_flag") != 0;
  if (h.meta_version > 2) {
    const std::uint64_t at = c.pos();
    const std::uint32_t xml_size = c.U32("xml_size");
    c.file().Need(c.pos(), double(xml_size), fmt::format("XML text (xml_size at byte {})", at));
    h.xml = TrimNul(c.Chars(xml_size, "XML text"));
  }
  if (h.meta_version > 3) {
    const std::uint32_t n = c.Count("num_channels", 1, 1024);
    h.channel_names.clear();
    for (std::uint32_t i = 0; i < n; ++i) {
      const std::string field = fmt::format("channel {} name length", i);
      const std::uint32_t len = c.Count(field, 0, 4096);
      std::string name = TrimNul(c.Chars(len, fmt::format("channel {} name", i)));
      if (name.empty()) name = fmt::format("C{}", i);
      h.channel_names.push_back(name);
    }
  }
  if (c.pos() != start + size)
    c.Fail(start, "meta block struct_size",
           fmt::format("is {} but the meta block (version {}) holds {} bytes", size, h.meta_version, c.pos() - start));
}

void BonnReader::Impl::ReadSampling(Cursor& c) {
  const std::uint64_t at = c.pos();
  const std::uint32_t nv = c.U32("n_views");
  if (nv == 0) c.Fail(at, "n_views", "is 0");
  c.file().Need(c.pos(), 12.0 * nv, fmt::format("sampling of {} views (n_views at byte {})", nv, at));
  std::vector<Vec3> views, lights;
  std::vector<float> first_lights;
  views.reserve(nv);
  for (std::uint32_t v = 0; v < nv; ++v) {
    const float theta = c.F32(fmt::format("view {} theta", v)), phi = c.F32(fmt::format("view {} phi", v));
    views.push_back(DirectionFromAngles(theta, phi));
    const std::uint64_t nl_at = c.pos();
    const std::string field = fmt::format("view {} n_lights", v);
    const std::uint32_t nl = c.U32(field);
    if (nl == 0) c.Fail(nl_at, field, "is 0");
    if (v > 0 && nl != first_lights.size() / 2)
      c.Fail(nl_at, field,
             fmt::format("is {} but view 0 has {} lights: libbtf reads tensor-product samplings only", nl,
                         first_lights.size() / 2));
    c.file().Need(c.pos(), 8.0 * nl, fmt::format("light list of view {} ({} lights, n_lights at byte {})", v, nl, nl_at));
    std::vector<float> list(2 * std::size_t(nl));
    const std::uint64_t list_at = c.pos();
    c.file().ReadAt(list_at, list.data(), list.size() * 4, fmt::format("light list of view {}", v));
    c.Skip(8.0 * nl, "light list");
    for (std::size_t i = 0; i < list.size(); ++i)
      if (!std::isfinite(list[i]))
        c.Fail(list_at + 4 * i, fmt::format("view {} light {} {}", v, i / 2, i % 2 ? "phi" : "theta"),
               "is not finite");
    if (v == 0) {
      first_lights = list;
      for (std::size_t i = 0; i < nl; ++i) lights.push_back(DirectionFromAngles(list[2 * i], list[2 * i + 1]));
    } else if (list != first_lights) {
      // Compared as values (0 equals -0), all finite: a difference exists at some i < size.
      std::size_t i = 0;
      while (i + 1 < list.size() && list[i] == first_lights[i]) ++i;
      c.Fail(list_at + 4 * i, fmt::format("view {} light {} {}", v, i / 2, i % 2 ? "phi" : "theta"),
             fmt::format("is {} but view 0 has {}: libbtf reads tensor-product samplings only (the same light list "
                         "for every view)",
                         list[i], first_lights[i]));
    }
  }
  const std::string name = "bonn:" + std::filesystem::path(file.path()).filename().string();
  h.views = Sampling(name + ":views", std::move(views));
  h.lights = Sampling(name + ":lights", std::move(lights));
}

void BonnReader::Impl::ReadSize(Cursor& c, bool rotations) {
  h.width = int(c.Count("width", 1, 1u << 20));
  h.height = int(c.Count("height", 1, 1u << 20));
  CheckAllocation(4.0 * h.lights.size() * h.width * h.height * h.channels(),
                  fmt::format("'{}': one view slot", file.path()));
  if (rotations) ReadRotations(c);
}

void BonnReader::Impl::ReadRotations(Cursor& c) {
  const std::uint64_t at = c.pos();
  const std::uint32_t n = c.U32("n_rotations");
  c.file().Need(c.pos(), 36.0 * n, fmt::format("{} rotations (n_rotations at byte {})", n, at));
  h.rotations.resize(n);
  for (auto& r : h.rotations)
    for (auto& x : r) x = c.F32("rotation");
}

void BonnReader::Impl::ReadDfmf(Cursor& c) {
  h.header_components = c.U32("num_components");
  const std::uint64_t model_at = c.pos();
  h.color_model = c.Get<std::int32_t>("color_model");
  if (!BonnColorModelSupported(h.color_model))
    c.Fail(model_at, "color_model",
           fmt::format("is {} ({}), which libbtf does not decode (supported: 0, 1, 3, 4, 9, 10, 11, 12)", h.color_model,
                       BonnColorModelName(h.color_model)));
  if (h.color_model != 0 && h.color_model != 12 && h.channels() != 3)
    c.Fail(model_at, "color_model",
           fmt::format("is {} ({}), which needs 3 channels, but the file has {}", h.color_model,
                       BonnColorModelName(h.color_model), h.channels()));
  for (auto& m : h.color_mean) m = c.F32("color_mean");
  for (auto& t : h.color_transform) t = c.F32("color_transform");
  const std::uint64_t dirs = std::uint64_t(h.lights.size()) * h.views.size();
  const std::uint64_t texels = std::uint64_t(h.width) * h.height;
  for (int ch = 0; ch < h.channels(); ++ch) {
    const int ss = ScalarSize(c, fmt::format("channel {} scalar_size", ch));
    const std::uint32_t k = c.Count(fmt::format("channel {} num_components", ch), 0, 1u << 20);
    const std::uint64_t rows_at = c.pos();
    const std::uint32_t rows = c.U32(fmt::format("channel {} rows", ch));
    const std::uint32_t cols = c.U32(fmt::format("channel {} cols", ch));
    bool transposed;
    if (rows == dirs && cols == texels)
      transposed = false;
    else if (rows == texels && cols == dirs)
      transposed = true;
    else
      c.Fail(rows_at, fmt::format("channel {} rows x cols", ch),
             fmt::format("is {} x {}; expected n_lights*n_views x width*height = {} x {} (or transposed)", rows, cols,
                         dirs, texels));
    if (ch > 0 && transposed != h.transposed)
      c.Fail(rows_at, fmt::format("channel {} rows x cols", ch), "uses a different layout than channel 0");
    h.transposed = transposed;
    c.Skip(double(k) * ss, fmt::format("channel {} singular values", ch));
    MatrixRef u = Locate(c, rows, int(k), int(k), ss, fmt::format("channel {} U", ch));
    MatrixRef v = Locate(c, cols, int(k), int(k), ss, fmt::format("channel {} SxV", ch));
    if (transposed) std::swap(u, v);
    abrdf_refs.push_back(u);
    texture_refs.push_back(v);
    h.components.push_back(int(k));
    h.scalar_sizes.push_back(ss);
  }
}

void BonnReader::Impl::ReadFmf(Cursor& c) {
  if (h.signature == "!FMF12FCER") {
    const std::uint64_t at = c.pos();
    h.fmf_header_version = c.Get<std::uint8_t>("header_version");
    if (h.fmf_header_version >= 3)
      c.Fail(at, "header_version", fmt::format("is {}; libbtf reads FMF header versions 0 to 2", h.fmf_header_version));
  }
  if (h.fmf_header_version >= 1) h.dynamic_range_reduction = c.U32("dynamic_range_reduction");
  if (h.fmf_header_version >= 2) {
    const std::uint64_t at = c.pos();
    h.height_map_width = int(c.Count("height map width", 0, 1u << 20));
    h.height_map_height = int(c.Count("height map height", 0, 1u << 20));
    c.Skip(2.0 * h.height_map_width * h.height_map_height, fmt::format("height map (size at byte {})", at));
  }
  const std::uint32_t k_file = c.Count("num_components", 0, 1u << 20);
  const int ss = ScalarSize(c, "scalar_size");
  const std::uint32_t stride = c.Count("stored components", 0, 1u << 20);
  const int k = int(std::min(k_file, stride));
  const std::uint64_t rows_at = c.pos();
  const std::uint32_t rows = c.U32("rows");
  const std::uint32_t cols = c.U32("cols");
  const std::uint64_t dirs = std::uint64_t(h.lights.size()) * h.views.size();
  const std::uint64_t texels = std::uint64_t(h.width) * h.height;
  const std::uint64_t nc = std::uint64_t(h.channels());
  if (rows == nc * dirs && cols == texels)
    h.transposed = false;
  else if (rows == nc * texels && cols == dirs)
    h.transposed = true;
  else
    c.Fail(rows_at, "rows x cols",
           fmt::format("is {} x {}; expected channels*n_lights*n_views x width*height = {} x {} (or transposed)", rows,
                       cols, nc * dirs, texels));
  c.Skip(double(stride) * ss, "singular values");
  MatrixRef u = Locate(c, rows, int(stride), k, ss, "U");
  MatrixRef v = Locate(c, cols, int(stride), k, ss, "SxV");
  if (h.transposed) std::swap(u, v);
  abrdf_refs.push_back(u);
  texture_refs.push_back(v);
  h.components.push_back(k);
  h.scalar_sizes.push_back(ss);
}

void BonnReader::Impl::ReadPvf(Cursor& c) {
  std::uint32_t slots = 0;
  if (h.pvf_legacy) {
    c.Skip(4, "legacy magic");
    h.header_components = c.U32("num_components");
    h.width = int(c.Count("width", 1, 1u << 20));
    h.height = int(c.Count("height", 1, 1u << 20));
    const std::uint64_t at = c.pos();
    slots = c.U32("view_slots");
    ReadSampling(c);
    CheckAllocation(4.0 * h.lights.size() * h.width * h.height * h.channels(),
                    fmt::format("'{}': one view slot", file.path()));
    if (slots != std::uint32_t(h.views.size()))
      c.Fail(at, "view_slots", fmt::format("is {} but the sampling has {} views", slots, h.views.size()));
  } else {
    h.header_components = c.U32("num_components");
    const std::uint64_t at = c.pos();
    slots = c.U32("view_slots");
    if (slots != std::uint32_t(h.views.size()))
      c.Fail(at, "view_slots", fmt::format("is {} but the sampling has {} views", slots, h.views.size()));
  }
  const std::uint64_t nc = std::uint64_t(h.channels()), nl = std::uint64_t(h.lights.size());
  const std::uint64_t texels = std::uint64_t(h.width) * h.height;
  for (std::uint32_t v = 0; v < slots; ++v) {
    PvfView p;
    p.scalar_size = ScalarSize(c, fmt::format("view {} scalar_size", v));
    p.k = int(c.Count(fmt::format("view {} num_components", v), 0, 1u << 20));
    const std::uint64_t at = c.pos();
    p.weights_rows = c.U32(fmt::format("view {} n_weights", v));
    p.dim = c.U32(fmt::format("view {} dimension", v));
    bool images;
    if (p.weights_rows == texels && p.dim == nc * nl)
      images = false;
    else if (p.weights_rows == nl && p.dim == nc * texels)
      images = true;
    else
      c.Fail(at, fmt::format("view {} n_weights x dimension", v),
             fmt::format("is {} x {}; expected width*height x channels*n_lights = {} x {} (light fields) or n_lights x "
                         "channels*width*height = {} x {} (images)",
                         p.weights_rows, p.dim, texels, nc * nl, nl, nc * texels));
    if (v > 0 && images != h.pvf_images)
      c.Fail(at, fmt::format("view {} n_weights x dimension", v), "uses a different layout than view 0");
    h.pvf_images = images;
    c.Skip(double(p.k) * p.scalar_size, fmt::format("view {} eigenvalues", v));
    p.mean_offset = c.pos();
    c.Skip(double(p.dim) * p.scalar_size, fmt::format("view {} mean", v));
    p.components = Locate(c, p.dim, p.k, p.k, p.scalar_size, fmt::format("view {} components", v));
    p.weights = Locate(c, p.weights_rows, p.k, p.k, p.scalar_size, fmt::format("view {} weights", v));
    CheckAllocation(4.0 * (double(p.dim) * (p.k + 1) + double(p.weights_rows) * p.k),
                    fmt::format("'{}': view {} factors", file.path(), v));
    h.components.push_back(p.k);
    h.scalar_sizes.push_back(p.scalar_size);
    pvf.push_back(p);
  }
}

void BonnReader::Impl::ReadBdi(Cursor& c) {
  const std::uint64_t size_at = c.pos();
  h.width = int(c.Count("width", 1, 1u << 20));
  h.height = int(c.Count("height", 1, 1u << 20));
  CheckAllocation(4.0 * h.lights.size() * h.width * h.height * h.channels(),
                  fmt::format("'{}': one view slot", file.path()));
  h.scan_lines_per_chunk = c.Count("scan_lines_per_chunk", 1, 1u << 20);
  const std::uint64_t comp_at = c.pos();
  h.compression = c.Get<std::uint8_t>("compression");
  if (h.compression == 1) c.Fail(comp_at, "compression", "is 1 (bzip2-compressed chunks), which libbtf does not read");
  if (h.compression != 0 && h.compression != 2)
    c.Fail(comp_at, "compression", fmt::format("is {}; expected 0 (full) or 2 (sparse)", h.compression));
  const std::uint64_t texels = std::uint64_t(h.width) * h.height;
  // Every claimed size is checked against the file before anything of that size is allocated.
  const std::uint64_t mask_at = c.pos();
  c.file().Need(mask_at, double(texels),
                fmt::format("mask of {} x {} texels (width and height at byte {})", h.width, h.height, size_at));
  std::vector<std::uint8_t> mask(texels);
  c.file().ReadAt(mask_at, mask.data(), mask.size(), "mask");
  c.Skip(double(texels), "mask");
  for (std::uint64_t t = 0; t < texels; ++t) h.stored_texels += h.compression == 0 || mask[t] != 0;
  ReadRotations(c);
  const std::uint64_t abrdf_bytes = 2ull * h.views.size() * h.lights.size() * std::uint64_t(h.channels());
  const std::uint64_t per_chunk = std::uint64_t(h.width) * h.scan_lines_per_chunk;
  const std::uint64_t chunks = (h.stored_texels + per_chunk - 1) / per_chunk;
  c.file().Need(c.pos(), double(h.stored_texels) * double(abrdf_bytes) + 4.0 * double(chunks),
                fmt::format("{} chunks of {} stored ABRDFs x {} bytes", chunks, h.stored_texels, abrdf_bytes));
  storage_index.assign(texels, -1);
  std::int64_t stored = 0;
  for (std::uint64_t t = 0; t < texels; ++t)
    if (h.compression == 0 || mask[t] != 0) storage_index[t] = stored++;
  for (std::uint64_t i = 0; i < chunks; ++i) {
    const std::uint64_t at = c.pos();
    const std::string field = fmt::format("chunk {} byte_size", i);
    const std::uint32_t bytes = c.U32(field);
    const std::uint64_t n = std::min(per_chunk, h.stored_texels - i * per_chunk);
    // btflib writes the last chunk padded to full scan lines (W x scan_lines_per_chunk ABRDFs).
    const bool short_last = i + 1 == chunks && n < per_chunk;
    const bool padded = short_last && double(bytes) == double(per_chunk) * double(abrdf_bytes);
    if (double(bytes) != double(n) * double(abrdf_bytes) && !padded)
      c.Fail(at, field,
             fmt::format("is {}; expected {} ABRDFs x {} bytes = {:.0f}{}", bytes, n, abrdf_bytes,
                         double(n) * double(abrdf_bytes),
                         short_last ? fmt::format(" (or, padded to full scan lines as btflib writes it, {} x {} ABRDFs = "
                                                  "{:.0f})",
                                                  h.scan_lines_per_chunk, h.width, double(per_chunk) * double(abrdf_bytes))
                                    : std::string()));
    if (padded) h.padding_abrdfs = per_chunk - n;
    chunk_offsets.push_back(c.pos());
    c.Skip(double(bytes), fmt::format("chunk {} data", i));
  }
}

// The products that decode a slot are formed a block of texels at a time and scattered to the
// slot layout, so that decoding needs no second slot-sized buffer.
namespace {
template <class F>
void ForTexelBlocks(std::size_t texels, F&& f) {
  constexpr std::size_t kBlock = 4096;
  for (std::size_t i0 = 0; i0 < texels; i0 += kBlock) f(i0, std::min(kBlock, texels - i0));
}
}  // namespace

void BonnReader::Impl::DecodeSlot(int view, float* out) const {
  BTF_CHECK(loaded && view >= 0 && view < h.views.size());
  const int nc = h.channels(), nl = h.lights.size();
  const std::size_t texels = std::size_t(h.width) * h.height;
  switch (h.format) {
    case BonnFormat::kDfmf: {
      for (int ch = 0; ch < nc; ++ch) {
        const RowMatrix& a = abrdf[std::size_t(ch)];
        const RowMatrix& t = texture[std::size_t(ch)];
        ForTexelBlocks(texels, [&](std::size_t i0, std::size_t n) {
          const RowMatrix m = a.middleRows(Eigen::Index(view) * nl, nl) *
                              t.middleRows(Eigen::Index(i0), Eigen::Index(n)).transpose();  // lights x n texels
          for (int l = 0; l < nl; ++l)
            for (std::size_t i = 0; i < n; ++i)
              out[(std::size_t(l) * texels + i0 + i) * nc + ch] = m(l, Eigen::Index(i));
        });
      }
      BonnUndecorrelate(h.color_model, h.color_mean, h.color_transform, nc, out, std::size_t(nl) * texels);
      break;
    }
    case BonnFormat::kFmf: {
      const RowMatrix& a = abrdf[0];
      const RowMatrix& t = texture[0];
      if (!h.transposed) {
        // rows c + nc (l + nl v): a (nc nl) x texels product, scattered to [l][texel][c].
        ForTexelBlocks(texels, [&](std::size_t i0, std::size_t n) {
          const RowMatrix m = a.middleRows(Eigen::Index(view) * nl * nc, Eigen::Index(nl) * nc) *
                              t.middleRows(Eigen::Index(i0), Eigen::Index(n)).transpose();
          for (int l = 0; l < nl; ++l)
            for (std::size_t i = 0; i < n; ++i)
              for (int ch = 0; ch < nc; ++ch)
                out[(std::size_t(l) * texels + i0 + i) * nc + ch] = m(Eigen::Index(ch + nc * l), Eigen::Index(i));
        });
      } else {
        // texture rows c + nc * texel: the lights x (texels nc) product is the slot layout.
        Eigen::Map<RowMatrix>(out, nl, Eigen::Index(texels) * nc) = a.middleRows(Eigen::Index(view) * nl, nl) * t.transpose();
      }
      if (h.dynamic_range_reduction != 0)
        for (std::size_t i = 0; i < std::size_t(nl) * texels * nc; ++i)
          out[i] = float(std::exp(double(out[i])) - kBonnEpsilon);
      break;
    }
    case BonnFormat::kPvf: {
      const PvfView& p = pvf[std::size_t(view)];
      const RowMatrix comps = Load(file, p.components), weights = Load(file, p.weights);
      std::vector<float> mean(p.dim);
      {
        std::vector<unsigned char> buf(p.dim * std::size_t(p.scalar_size));
        file.ReadAt(p.mean_offset, buf.data(), buf.size(), fmt::format("view {} mean", view));
        for (std::size_t i = 0; i < p.dim; ++i) {
          mean[i] = ScalarAt(buf.data() + i * p.scalar_size, p.scalar_size);
          if (!std::isfinite(mean[i]))
            ThrowBadInput("'{}': view {} mean at byte {} (element {}) holds {}; factors must be finite", file.path(), view,
                          p.mean_offset + i * p.scalar_size, i, mean[i]);
        }
      }
      if (!h.pvf_images) {
        // val(c, l, texel) = W[texel] . C[c + nc l] + M[c + nc l]: a texels x (nc nl) product.
        ForTexelBlocks(texels, [&](std::size_t i0, std::size_t n) {
          const RowMatrix m = weights.middleRows(Eigen::Index(i0), Eigen::Index(n)) * comps.transpose();
          for (int l = 0; l < nl; ++l)
            for (std::size_t i = 0; i < n; ++i)
              for (int ch = 0; ch < nc; ++ch) {
                const std::size_t d = std::size_t(ch) + std::size_t(nc) * l;
                out[(std::size_t(l) * texels + i0 + i) * nc + ch] = m(Eigen::Index(i), Eigen::Index(d)) + mean[d];
              }
        });
      } else {
        // val(c, l, texel) = W[l] . C[c + nc texel] + M[c + nc texel]: lights x (texels nc), slot layout.
        Eigen::Map<RowMatrix> m(out, nl, Eigen::Index(texels) * nc);
        m = weights * comps.transpose();
        m.rowwise() += Eigen::Map<const Eigen::RowVectorXf>(mean.data(), Eigen::Index(mean.size()));
      }
      break;
    }
    case BonnFormat::kBdi: {
      const std::size_t abrdf = std::size_t(h.views.size()) * nl * nc, part = std::size_t(nl) * nc;
      const std::uint64_t per_chunk = std::uint64_t(h.width) * h.scan_lines_per_chunk;
      std::vector<std::uint16_t> buf(part);
      for (std::size_t t = 0; t < texels; ++t) {
        const std::int64_t s = storage_index[t];
        if (s < 0) {
          for (int l = 0; l < nl; ++l)
            std::fill_n(out + (std::size_t(l) * texels + t) * nc, nc, 0.0f);
          continue;
        }
        const std::uint64_t off = chunk_offsets[std::size_t(std::uint64_t(s) / per_chunk)] +
                                  (std::uint64_t(s) % per_chunk) * abrdf * 2 + std::uint64_t(view) * part * 2;
        file.ReadAt(off, buf.data(), part * 2, fmt::format("texel {} data", t));
        for (int l = 0; l < nl; ++l)
          for (int ch = 0; ch < nc; ++ch)
            out[(std::size_t(l) * texels + t) * nc + ch] = HalfToFloat(buf[std::size_t(l) * nc + ch]);
      }
      break;
    }
  }
}

BonnReader::BonnReader(const std::filesystem::path& path, bool header_only) : impl_(std::make_unique<Impl>(path)) {
  Impl& m = *impl_;
  BonnHeader& h = m.h;
  h.path = path.string();
  h.file_bytes = m.file.size();
  h.signature = BonnSignatureOf(path);
  if (h.signature.empty())
    ThrowBadInput("'{}' is not a Bonn .btf file: it does not start with a signature such as '!DFMF08FCR'", h.path);
  Cursor c(m.file, h.signature.size());
  const bool rotations = h.signature.back() == 'R';
  if (h.signature.starts_with("!BDI")) {
    h.format = BonnFormat::kBdi;
    m.ReadMeta(c);
    m.ReadSampling(c);
    m.ReadBdi(c);
  } else {
    if (h.signature.starts_with("!DFMF"))
      h.format = BonnFormat::kDfmf;
    else if (h.signature.starts_with("!FMF"))
      h.format = BonnFormat::kFmf;
    else
      h.format = BonnFormat::kPvf;
    if (h.format == BonnFormat::kPvf) {
      std::int32_t magic = 0;
      m.file.ReadAt(c.pos(), &magic, 4, "PVF header");
      h.pvf_legacy = magic == kLegacyPvfMagic;
    }
    if (h.pvf_legacy) {
      h.has_meta = false;
    } else {
      m.ReadMeta(c);
      m.ReadSampling(c);
      m.ReadSize(c, rotations);
    }
    if (h.format == BonnFormat::kDfmf) m.ReadDfmf(c);
    if (h.format == BonnFormat::kFmf) m.ReadFmf(c);
    if (h.format == BonnFormat::kPvf) m.ReadPvf(c);
  }
  m.CheckEnd(c);
  if (!header_only) {
    for (const auto& r : m.abrdf_refs) m.abrdf.push_back(Load(m.file, r));
    for (const auto& r : m.texture_refs) m.texture.push_back(Load(m.file, r));
    m.loaded = true;
  }
}

BonnReader::~BonnReader() = default;
BonnReader::BonnReader(BonnReader&&) noexcept = default;
const BonnHeader& BonnReader::header() const { return impl_->h; }
void BonnReader::ReadViewSlot(int view, float* out) const { impl_->DecodeSlot(view, out); }

namespace {

class BonnSlotSource final : public SlotSource {
 public:
  explicit BonnSlotSource(const std::filesystem::path& path) : reader_(path), name_(path.string()) {}
  const std::string& name() const override { return name_; }
  std::string kind() const override { return std::string("bonn-") + BonnFormatName(reader_.header().format); }
  const Sampling& views() const override { return reader_.header().views; }
  const Sampling& lights() const override { return reader_.header().lights; }
  int height() const override { return reader_.header().height; }
  int width() const override { return reader_.header().width; }
  int channels() const override { return reader_.header().channels(); }
  DatasetInfo info() const override { return reader_.header().Info(); }
  void ReadViewSlot(int view, float* out) const override { reader_.ReadViewSlot(view, out); }

 private:
  BonnReader reader_;
  std::string name_;
};

}  // namespace

std::unique_ptr<SlotSource> OpenBonnSource(const std::filesystem::path& path) {
  return std::make_unique<BonnSlotSource>(path);
}

}  // namespace btf
