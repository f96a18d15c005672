// Writing Bonn BDI files (WriteBdi) and the meta data and sampling block of the Bonn formats
// (docs/format.md); reading them is bonn.cpp.
#include "libbtf/io/bonn.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/io/half.h"

namespace btf {

static_assert(std::endian::native == std::endian::little, "Bonn files are little-endian; this writer does not swap");

void BdiWriteOptions::Check() const {
  BTF_CHECK_OPTION(scan_lines_per_chunk >= 1, "scan_lines_per_chunk", "must be at least 1");
  BTF_CHECK_OPTION(measurement_setup.size() < 80, "measurement_setup", "must be shorter than 80 bytes");
}

namespace {

class ByteWriter {
 public:
  template <typename T>
  void Put(T v) {
    const auto* p = reinterpret_cast<const char*>(&v);
    bytes.insert(bytes.end(), p, p + sizeof v);
  }
  void Chars(const std::string& s, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) bytes.push_back(i < s.size() ? s[i] : '\0');
  }
  std::vector<char> bytes;
};

void WriteAllAt(int fd, const char* p, std::size_t n, std::uint64_t offset, const std::string& path) {
  while (n > 0) {
    const ssize_t w = ::pwrite(fd, p, n, off_t(offset));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) ThrowIo("cannot write '{}' ({}): disk full or I/O error?", path, w < 0 ? std::strerror(errno) : "no progress");
    p += w;
    n -= std::size_t(w);
    offset += std::uint64_t(w);
  }
}

}  // namespace

std::string EncodeBonnMetaAndSampling(const Sampling& views, const Sampling& lights, const DatasetInfo& info,
                                      const std::string& measurement_setup) {
  if (measurement_setup.size() >= 80) ThrowUsage("measurement_setup '{}' must be shorter than 80 bytes", measurement_setup);
  ByteWriter meta;
  meta.Put<std::uint32_t>(0);  // struct_size, patched below
  meta.Put<std::uint32_t>(4);
  meta.Chars(measurement_setup, 80);
  meta.Chars("", 80);
  meta.Chars("", 80);
  meta.Put<float>(info.texel_size_mm > 0 ? float(1.0 / info.texel_size_mm) : 0.0f);
  for (int i = 0; i < 3; ++i) meta.Put<float>(1.0f);
  meta.Put<std::uint32_t>(info.cos_theta_i_included ? 1 : 0);
  meta.Put<std::uint32_t>(0);  // no XML
  meta.Put<std::uint32_t>(std::uint32_t(info.channel_names.size()));
  for (const auto& name : info.channel_names) {
    meta.Put<std::uint32_t>(std::uint32_t(name.size()));
    meta.Chars(name, name.size());
  }
  const auto meta_size = std::uint32_t(meta.bytes.size());
  std::memcpy(meta.bytes.data(), &meta_size, 4);
  ByteWriter& b = meta;
  b.Put<std::uint32_t>(std::uint32_t(views.size()));
  for (int v = 0; v < views.size(); ++v) {
    const Angles a = views.angles(v);
    b.Put<float>(float(a.theta));
    b.Put<float>(float(a.phi));
    b.Put<std::uint32_t>(std::uint32_t(lights.size()));
    for (int l = 0; l < lights.size(); ++l) {
      const Angles al = lights.angles(l);
      b.Put<float>(float(al.theta));
      b.Put<float>(float(al.phi));
    }
  }
  return std::string(b.bytes.begin(), b.bytes.end());
}

std::uint64_t WriteBdi(const std::filesystem::path& path, const SlotSource& source, const BdiWriteOptions& options,
                       const Reporter& reporter) {
  options.Check();
  const int nv = source.views().size(), nl = source.lights().size(), nc = source.channels();
  const int w = source.width(), h = source.height();
  const DatasetInfo info = source.info();
  if (int(info.channel_names.size()) != nc)
    ThrowBadInput("'{}' has {} channels but {} channel names", source.name(), nc, info.channel_names.size());
  ByteWriter b;
  b.Chars("!BDIF06R2!", 10);
  const std::string head = EncodeBonnMetaAndSampling(source.views(), source.lights(), info, options.measurement_setup);
  b.bytes.insert(b.bytes.end(), head.begin(), head.end());
  b.Put<std::uint32_t>(std::uint32_t(w));
  b.Put<std::uint32_t>(std::uint32_t(h));
  b.Put<std::uint32_t>(std::uint32_t(options.scan_lines_per_chunk));
  b.Put<std::uint8_t>(2);  // sparse, with a full mask: the form btflib reads
  b.bytes.insert(b.bytes.end(), std::size_t(w) * h, char(1));
  b.Put<std::uint32_t>(0);  // no rotations
  const std::uint64_t texels = std::uint64_t(w) * h, part = std::uint64_t(nl) * nc;
  const std::uint64_t abrdf_bytes = 2ull * nv * part;
  const std::uint64_t per_chunk = std::uint64_t(w) * options.scan_lines_per_chunk;
  const std::uint64_t chunks = (texels + per_chunk - 1) / per_chunk;
  if (double(per_chunk) * double(abrdf_bytes) > 4294967295.0)
    ThrowUsage("a BDI chunk of {} scan lines of '{}' needs more than 4 GiB (its size field is 32-bit): use fewer scan "
               "lines per chunk",
               options.scan_lines_per_chunk, source.name());
  const std::uint64_t data_begin = b.bytes.size();
  const std::uint64_t total = data_begin + chunks * 4 + texels * abrdf_bytes;

  AtomicOutput out(path);
  out.Reserve();
  const int fd = ::open(out.temp_path().c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) ThrowIo("cannot write '{}' ({}): disk full or I/O error?", path.string(), std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() {
      if (fd >= 0) ::close(fd);
    }
  } closer{fd};
  if (::ftruncate(fd, off_t(total)) != 0)
    ThrowIo("cannot write '{}' ({} bytes, {}): disk full or I/O error?", path.string(), total, std::strerror(errno));
  WriteAllAt(fd, b.bytes.data(), b.bytes.size(), 0, path.string());
  auto abrdf_offset = [&](std::uint64_t t) {
    const std::uint64_t chunk = t / per_chunk;
    return data_begin + (chunk + 1) * 4 + t * abrdf_bytes;
  };
  for (std::uint64_t i = 0; i < chunks; ++i) {
    const std::uint64_t n = std::min(per_chunk, texels - i * per_chunk);
    const auto size = std::uint32_t(n * abrdf_bytes);
    WriteAllAt(fd, reinterpret_cast<const char*>(&size), 4, abrdf_offset(i * per_chunk) - 4, path.string());
  }
  std::vector<float> slot(source.slot_size());
  std::vector<std::uint16_t> buf(part);
  const std::size_t image = source.image_size();
  for (int v = 0; v < nv; ++v) {
    source.ReadViewSlot(v, slot.data());
    CheckFiniteSlot(source, v, slot.data());
    for (std::uint64_t t = 0; t < texels; ++t) {
      for (int l = 0; l < nl; ++l)
        for (int c = 0; c < nc; ++c) {
          const float x = slot[std::size_t(l) * image + t * nc + c];
          if (std::abs(x) > kHalfMax)
            ThrowBadInput("'{}' holds {} at view {}, light {}, texel (y {}, x {}), channel {}: BDI stores half floats "
                          "(|x| <= 65504); scale the data or keep it in a float32 dataset",
                          source.name(), x, v, l, t / w, t % w, c);
          buf[std::size_t(l) * nc + c] = FloatToHalf(x);
        }
      WriteAllAt(fd, reinterpret_cast<const char*>(buf.data()), part * 2, abrdf_offset(t) + std::uint64_t(v) * part * 2,
                 path.string());
    }
    reporter.Progress(std::size_t(v + 1), std::size_t(nv), "writing BDI");
  }
  if (::close(fd) != 0) {
    closer.fd = -1;
    ThrowIo("cannot write '{}' ({}): disk full or I/O error?", path.string(), std::strerror(errno));
  }
  closer.fd = -1;
  out.Commit();
  return total;
}

}  // namespace btf
