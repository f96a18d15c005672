#include "libbtf/io/hdf5.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <type_traits>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fmt/ranges.h>

#include "libbtf/core/dataset.h"
#include "libbtf/core/error.h"
#include "libbtf/io/half.h"
#include "libbtf/io/raw_chunks.h"

namespace btf::h5 {

namespace {
// HDF5 1.10 leaves a file whose H5Fclose failed (a write at close failing: disk full, I/O error)
// half-destroyed, and the handler it registers with atexit then crashes closing it again. Every
// file is closed explicitly (File::Close, File::CloseQuietly), so the handler is not needed;
// H5dont_atexit must run before any other HDF5 call, hence a static initializer.
[[maybe_unused]] const herr_t kNoAtexit = H5dont_atexit();

// Closes that failed, process-wide. Closing a dataset writes its cached chunks, so a failed
// close is lost data; File::Close() refuses a file when any close failed since it was created.
std::atomic<std::uint64_t> g_failed_closes{0};

// Set once any HDF5 call failed on a failed read or write system call (see IoErrorSeen()).
std::atomic<bool> g_io_error_seen{false};

herr_t FindIoError(unsigned, const H5E_error2_t* e, void* found) {
  // The file driver's failed read or write system call; a failed checksum is H5E_STORAGE.
  if (e->maj_num == H5E_IO && (e->min_num == H5E_READERROR || e->min_num == H5E_WRITEERROR))
    *static_cast<bool*>(found) = true;
  return 0;
}

// True when HDF5's current error stack holds a failed read or write system call (an I/O
// error, not a damaged file).
bool LastErrorWasIo() {
  bool found = false;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, FindIoError, &found);
  if (found) g_io_error_seen = true;
  return found;
}

// HDF5 calls this when an API call fails: nothing is printed (we report errors ourselves), but
// a failed system call underneath is remembered.
herr_t NoteIoError(hid_t, void*) {
  LastErrorWasIo();
  return 0;
}
}  // namespace

void SilenceErrors() {
  // Per thread: the thread-safe HDF5 keeps one error-reporting setting per thread (slots are
  // read on a prefetch thread).
  thread_local bool silenced = false;
  if (!silenced) H5Eset_auto2(H5E_DEFAULT, NoteIoError, nullptr);
  silenced = true;
}

bool IoErrorSeen() { return g_io_error_seen.load(); }

Error ReportedError(const Error& e) {
  if (e.code() == ExitCode::kBadInput && IoErrorSeen())
    return Error(ExitCode::kIo, fmt::format("{} (after an I/O error reading it: failing disk or network file system?)", e.what()));
  return Error(e.code(), e.what());
}

void Handle::reset() {
  if (id_ < 0) return;
  herr_t r = 0;
  switch (H5Iget_type(id_)) {
    case H5I_FILE: r = H5Fclose(id_); break;
    case H5I_GROUP: r = H5Gclose(id_); break;
    case H5I_DATASET: r = H5Dclose(id_); break;
    case H5I_DATASPACE: r = H5Sclose(id_); break;
    case H5I_DATATYPE: r = H5Tclose(id_); break;
    case H5I_ATTR: r = H5Aclose(id_); break;
    case H5I_GENPROP_LST: r = H5Pclose(id_); break;
    default: break;
  }
  if (r < 0) ++g_failed_closes;
  id_ = H5I_INVALID_HID;
}

hid_t HalfType() {
  static hid_t type = [] {
    hid_t t = H5Tcopy(H5T_IEEE_F32LE);
    H5Tset_fields(t, 15, 10, 5, 0, 10);
    H5Tset_precision(t, 16);
    H5Tset_size(t, 2);
    H5Tset_ebias(t, 15);
    H5Tlock(t);
    return t;
  }();
  return type;
}

namespace {
// float16 storage is converted by libbtf (io/half.h: IEEE 754 round to nearest, ties to even),
// never by HDF5: HDF5 1.10.8's float32 -> float16 conversion truncates results in the half
// subnormal range and drops the carry when rounding up reaches the next power of two (3.99956 is
// stored as 2). The data are written and read as raw half bits, so HDF5 converts nothing.
std::vector<std::uint16_t> ToHalf(const float* data, std::size_t n) {
  std::vector<std::uint16_t> h(n);
  for (std::size_t i = 0; i < n; ++i) h[i] = FloatToHalf(data[i]);
  return h;
}
void FromHalf(const std::vector<std::uint16_t>& h, float* out) {
  for (std::size_t i = 0; i < h.size(); ++i) out[i] = HalfToFloat(h[i]);
}
bool StoredAsHalf(hid_t ds) {
  Handle type(H5Dget_type(ds));
  return H5Tget_class(type.id()) == H5T_FLOAT && H5Tget_size(type.id()) == 2;
}
std::size_t Elements(const std::vector<hsize_t>& dims) {
  std::size_t n = 1;
  for (auto d : dims) n *= static_cast<std::size_t>(d);
  return n;
}

// Semantic version "MAJOR.MINOR.PATCH" -> MAJOR; -1 if malformed.
int MajorVersion(const std::string& semver) {
  std::size_t pos = 0;
  int major = 0;
  while (pos < semver.size() && std::isdigit(static_cast<unsigned char>(semver[pos]))) {
    major = major * 10 + (semver[pos] - '0');
    if (++pos > 6) return -1;
  }
  if (pos == 0 || pos >= semver.size() || semver[pos] != '.') return -1;
  return major;
}

// Refuses files without checksummed metadata before HDF5 parses them: libbtf writes superblock
// version >= 2 (metadata checksums); older layouts carry no checksums, and HDF5 1.10.8 can
// crash on damaged unchecksummed metadata.
// Returns the checked file's identity (device, inode), so the caller can tell whether HDF5 then
// opened the same file.
std::pair<dev_t, ino_t> CheckSuperblock(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) ThrowIo("cannot open '{}': {}", path, std::strerror(errno));
  struct stat st{};
  fstat(fileno(f), &st);
  static const unsigned char kSignature[8] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n'};
  int version = -1;
  // The superblock sits at byte 0, 512, 1024, 2048, ... (user block).
  for (long offset = 0; offset <= (1L << 20) && version < 0; offset = offset ? offset * 2 : 512) {
    unsigned char buf[9];
      if (std::fseek(f, offset, SEEK_SET) != 0 || std::fread(buf, 1, 9, f) != 9) break;
    if (std::memcmp(buf, kSignature, 8) == 0) version = buf[8];
  }
  const bool read_error = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (read_error) ThrowIo("cannot read '{}': {}", path, std::strerror(err));
  if (version < 0) ThrowBadInput("'{}' is not an HDF5 file (wrong file, or its header is corrupt)", path);
  if (version < 2)
    ThrowBadInput("'{}' uses HDF5 superblock version {} without metadata checksums; libbtf writes and reads "
                  "version >= 2 files only (re-create it with libbtf, or convert it with h5repack)",
                  path, version);
  return {st.st_dev, st.st_ino};
}
}  // namespace

File File::Create(const std::filesystem::path& path) {
  SilenceErrors();
  File f;
  f.path_ = path.string();
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  // HDF5 1.10 file format: superblock v3 and object headers, chunk indexes and heaps with
  // checksums, so corrupted metadata is refused by checksum before HDF5 parses it (HDF5 1.10.8's
  // parser is not memory-safe on damaged metadata; see docs/format.md). Readable by HDF5 >= 1.10.
  H5Pset_libver_bounds(fapl.id(), H5F_LIBVER_V110, H5F_LIBVER_V110);
  f.file_ = Handle(H5Fcreate(f.path_.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.id()));
  f.created_ = true;
  f.failed_closes_at_create_ = g_failed_closes.load();
  if (!f.file_.valid()) ThrowIo("cannot create HDF5 file '{}': check the folder exists and is writable", f.path_);
  return f;
}

File File::OpenExisting(const std::filesystem::path& path, unsigned flags) {
  SilenceErrors();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) ThrowIo("cannot open '{}': no such file", path.string());
  const auto checked = CheckSuperblock(path.string());
  const hid_t id = H5Fopen(path.c_str(), flags, H5P_DEFAULT);
  const auto changed = [&] {
    ThrowIo("'{}' was deleted or replaced by another program while it was being opened; run again", path.string());
  };
  if (id < 0) {
    if (LastErrorWasIo()) ThrowIo("cannot read HDF5 file '{}': I/O error (failing disk or network file system?)", path.string());
    if (!std::filesystem::exists(path, ec)) changed();
    ThrowBadInput("cannot open HDF5 file '{}': the file is truncated or corrupt; re-create or re-copy it", path.string());
  }
  File f;
  f.file_ = Handle(id);
  f.path_ = path.string();
  // From here on the open file is read whatever happens to its name; it must be the one checked.
  int* fd = nullptr;
  struct stat st{};
  if (H5Fget_vfd_handle(id, H5P_DEFAULT, reinterpret_cast<void**>(&fd)) >= 0 && fd && fstat(*fd, &st) == 0 &&
      (st.st_dev != checked.first || st.st_ino != checked.second))
    changed();
  return f;
}

File File::Open(const std::filesystem::path& path) { return OpenExisting(path, H5F_ACC_RDONLY); }
File File::OpenForUpdate(const std::filesystem::path& path) { return OpenExisting(path, H5F_ACC_RDWR); }

bool File::Exists(const std::string& object) const {
  if (object == "/") return true;
  // Check each path component so a missing parent is not an error.
  std::size_t pos = 0;
  while ((pos = object.find('/', pos + 1)) != std::string::npos)
    if (H5Lexists(id(), object.substr(0, pos).c_str(), H5P_DEFAULT) <= 0) return false;
  return H5Lexists(id(), object.c_str(), H5P_DEFAULT) > 0;
}

void File::CreateGroup(const std::string& group) const {
  Handle g(H5Gcreate2(id(), group.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  if (!g.valid()) ThrowIo("'{}': cannot create group '{}'", path_, group);
}

namespace {

Handle OpenObject(const File& f, const std::string& object) {
  if (!f.Exists(object)) ThrowBadInput("'{}': required item '{}' is missing", f.path(), object);
  Handle h(H5Oopen(f.id(), object.c_str(), H5P_DEFAULT));
  if (!h.valid()) ThrowBadInput("'{}': cannot open '{}' (corrupt file?)", f.path(), object);
  return h;
}

void WriteAttr(const File& f, const std::string& object, const std::string& name, hid_t type, const void* value) {
  Handle obj = OpenObject(f, object);
  if (H5Aexists(obj.id(), name.c_str()) > 0) H5Adelete(obj.id(), name.c_str());
  Handle space(H5Screate(H5S_SCALAR));
  Handle attr(H5Acreate2(obj.id(), name.c_str(), type, space.id(), H5P_DEFAULT, H5P_DEFAULT));
  if (!attr.valid() || H5Awrite(attr.id(), type, value) < 0)
    ThrowIo("'{}': cannot write attribute '{}' on '{}'", f.path(), name, object);
}

Handle OpenAttr(const File& f, const std::string& object, const std::string& name) {
  Handle obj = OpenObject(f, object);
  if (H5Aexists(obj.id(), name.c_str()) <= 0)
    ThrowBadInput("'{}': required attribute '{}' on '{}' is missing", f.path(), name, object);
  Handle attr(H5Aopen(obj.id(), name.c_str(), H5P_DEFAULT));
  if (!attr.valid()) ThrowBadInput("'{}': cannot open attribute '{}' on '{}'", f.path(), name, object);
  return attr;
}

template <typename T>
T ReadNumericAttr(const File& f, const std::string& object, const std::string& name, hid_t mem_type) {
  Handle attr = OpenAttr(f, object, name);
  Handle type(H5Aget_type(attr.id()));
  const H5T_class_t cls = H5Tget_class(type.id());
  Handle space(H5Aget_space(attr.id()));
  if ((cls != H5T_INTEGER && cls != H5T_FLOAT) || H5Sget_simple_extent_npoints(space.id()) != 1)
    ThrowBadInput("'{}': attribute '{}' on '{}' must be a single number", f.path(), name, object);
  T v{};
  if (H5Aread(attr.id(), mem_type, &v) < 0)
    ThrowUnreadable(f.path(), fmt::format("attribute '{}' on '{}'", name, object));
  return v;
}

Handle StringType(std::size_t size) {
  Handle t(H5Tcopy(H5T_C_S1));
  H5Tset_size(t.id(), size > 0 ? size : 1);
  H5Tset_strpad(t.id(), H5T_STR_NULLPAD);
  H5Tset_cset(t.id(), H5T_CSET_UTF8);
  return t;
}

// Reads a scalar fixed- or variable-length string from an attribute or dataset.
template <typename ReadFn>
std::string ReadStringValue(hid_t stored_type, hid_t space, ReadFn read, const std::string& what) {
  if (H5Tget_class(stored_type) != H5T_STRING || H5Sget_simple_extent_npoints(space) != 1)
    ThrowBadInput("{} must be a single string", what);
  if (H5Tis_variable_str(stored_type) > 0) {
    Handle mem(H5Tcopy(H5T_C_S1));
    H5Tset_size(mem.id(), H5T_VARIABLE);
    H5Tset_cset(mem.id(), H5Tget_cset(stored_type));  // HDF5 does not convert ASCII <-> UTF-8
    char* p = nullptr;
    if (read(mem.id(), &p) < 0) ThrowBadInput("cannot read {}", what);
    std::string s = p ? p : "";
    H5free_memory(p);
    return s;
  }
  const std::size_t n = H5Tget_size(stored_type);
  if (n > (std::size_t(1) << 30)) ThrowBadInput("{} claims an absurd size ({} bytes)", what, n);
  std::string s(n, '\0');
  Handle mem = StringType(n);
  H5Tset_cset(mem.id(), H5Tget_cset(stored_type));
  if (read(mem.id(), s.data()) < 0) ThrowBadInput("cannot read {}", what);
  s.resize(std::strlen(s.c_str()));
  return s;
}

}  // namespace

void File::SetAttr(const std::string& object, const std::string& name, const std::string& value) const {
  Handle type = StringType(value.size());
  WriteAttr(*this, object, name, type.id(), value.data());
}
void File::SetAttr(const std::string& object, const std::string& name, std::int64_t value) const {
  WriteAttr(*this, object, name, H5T_NATIVE_INT64, &value);
}
void File::SetAttr(const std::string& object, const std::string& name, double value) const {
  WriteAttr(*this, object, name, H5T_NATIVE_DOUBLE, &value);
}
bool File::HasAttr(const std::string& object, const std::string& name) const {
  if (!Exists(object)) return false;
  Handle obj(H5Oopen(id(), object.c_str(), H5P_DEFAULT));
  return obj.valid() && H5Aexists(obj.id(), name.c_str()) > 0;
}
std::string File::GetString(const std::string& object, const std::string& name) const {
  Handle attr = OpenAttr(*this, object, name);
  Handle type(H5Aget_type(attr.id()));
  Handle space(H5Aget_space(attr.id()));
  return ReadStringValue(
      type.id(), space.id(), [&](hid_t mem, void* buf) { return H5Aread(attr.id(), mem, buf); },
      fmt::format("'{}': attribute '{}' on '{}'", path_, name, object));
}
std::int64_t File::GetInt(const std::string& object, const std::string& name) const {
  return ReadNumericAttr<std::int64_t>(*this, object, name, H5T_NATIVE_INT64);
}
double File::GetDouble(const std::string& object, const std::string& name) const {
  return ReadNumericAttr<double>(*this, object, name, H5T_NATIVE_DOUBLE);
}

void File::StartWriteback() const {
  Handle fapl(H5Fget_access_plist(id()));
  void* handle = nullptr;  // an int* (the descriptor) with the default sec2 driver only
  if (!fapl.valid() || H5Pget_driver(fapl.id()) != H5FD_SEC2 || H5Fget_vfd_handle(id(), fapl.id(), &handle) < 0 ||
      handle == nullptr)
    return;
  ::sync_file_range(*static_cast<const int*>(handle), 0, 0, SYNC_FILE_RANGE_WRITE);  // error: the fsync reports it
}

void File::WriteString(const std::string& name, const std::string& text) const {
  Handle type = StringType(text.size());
  Handle space(H5Screate(H5S_SCALAR));
  // In the object header (checksummed metadata) up to 32 KiB, as small arrays (WriteWhole).
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
  if (text.size() <= (32u << 10)) H5Pset_layout(dcpl.id(), H5D_COMPACT);
  Handle ds(H5Dcreate2(id(), name.c_str(), type.id(), space.id(), H5P_DEFAULT, dcpl.id(), H5P_DEFAULT));
  if (!ds.valid() || H5Dwrite(ds.id(), type.id(), H5S_ALL, H5S_ALL, H5P_DEFAULT, text.data()) < 0)
    ThrowIo("'{}': cannot write '{}'", path_, name);
}

std::string File::ReadString(const std::string& name) const {
  Handle ds = OpenDataset(name);
  Handle type(H5Dget_type(ds.id()));
  Handle space(H5Dget_space(ds.id()));
  return ReadStringValue(
      type.id(), space.id(),
      [&](hid_t mem, void* buf) { return H5Dread(ds.id(), mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf); },
      fmt::format("'{}': dataset '{}'", path_, name));
}

namespace {
// Every value a libbtf writer stores is checksummed, so that a damaged file is refused instead of
// decoding to other values (docs/format.md, "Checksums"): small arrays and strings (up to
// kCompactBytes) are stored in their object header (compact layout), which HDF5 1.10's format
// checksums with the rest of the metadata; larger arrays in chunks of at most kChunkBytes with
// Fletcher-32.
constexpr hsize_t kCompactBytes = 32 << 10;
constexpr hsize_t kChunkBytes = hsize_t(1) << 28;

// Layout of a whole array of `dims` with elements of `element` bytes, given no chunk shape; true
// when it is one chunk holding the whole array.
bool ChecksummedLayout(hid_t dcpl, const std::vector<hsize_t>& dims, std::size_t element) {
  hsize_t bytes = element;
  for (const hsize_t d : dims) bytes *= d;
  if (bytes == 0) return false;  // nothing stored
  if (bytes <= kCompactBytes) {
    H5Pset_layout(dcpl, H5D_COMPACT);
    return false;
  }
  std::vector<hsize_t> chunk = dims;  // whole trailing dimensions, as many leading rows as fit
  chunk[0] = std::max<hsize_t>(1, std::min<hsize_t>(dims[0], kChunkBytes / std::max<hsize_t>(1, bytes / dims[0])));
  H5Pset_chunk(dcpl, static_cast<int>(chunk.size()), chunk.data());
  H5Pset_fletcher32(dcpl);
  return chunk[0] == dims[0];
}

// Writes the one chunk of `ds` (a ChecksummedLayout of `bytes` in one chunk, stored as it is in
// memory) as HDF5's pipeline would store it, the data followed by its Fletcher-32 checksum
// (little-endian), with H5Dwrite_chunk from `scratch`. The pipeline copies the chunk twice into
// buffers it allocates for each dataset (the chunk cache's and the fletcher32 filter's): fresh
// pages for every codec slot in a process whose allocator has not grown yet (the Python module's
// first libbtf.compress, docs/performance.md).
bool WriteOneChunk(hid_t ds, const void* data, hsize_t bytes, std::size_t rank, std::vector<std::uint8_t>& scratch) {
  scratch.resize(bytes + 4);
  std::memcpy(scratch.data(), data, bytes);
  const std::uint32_t sum = Fletcher32(scratch.data(), bytes);
  std::memcpy(scratch.data() + bytes, &sum, 4);  // little-endian (raw_chunks.cpp asserts the host is)
  const std::vector<hsize_t> origin(rank, 0);
  return H5Dwrite_chunk(ds, H5P_DEFAULT, 0, origin.data(), bytes + 4, scratch.data()) >= 0;
}

void WriteWhole(const File& f, const std::string& name, const std::vector<hsize_t>& dims, hid_t file_type,
                hid_t mem_type, const void* data, std::vector<std::uint8_t>& scratch,
                const std::vector<hsize_t>& chunk = {}) {
  Handle space(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr));
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
  bool one_chunk = false;
  if (!chunk.empty()) {
    H5Pset_chunk(dcpl.id(), static_cast<int>(chunk.size()), chunk.data());
    H5Pset_shuffle(dcpl.id());
    H5Pset_deflate(dcpl.id(), 4);
    H5Pset_fletcher32(dcpl.id());  // a damaged or truncated chunk is refused, never read as zeros
  } else if (!dims.empty()) {
    one_chunk = ChecksummedLayout(dcpl.id(), dims, H5Tget_size(file_type)) && H5Tequal(file_type, mem_type) > 0;
  }
  Handle ds(H5Dcreate2(f.id(), name.c_str(), file_type, space.id(), H5P_DEFAULT, dcpl.id(), H5P_DEFAULT));
  const bool written =
      ds.valid() && (one_chunk ? WriteOneChunk(ds.id(), data, Elements(dims) * H5Tget_size(file_type), dims.size(), scratch)
                               : H5Dwrite(ds.id(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) >= 0);
  if (!written) ThrowIo("'{}': cannot write dataset '{}' (disk full?)", f.path(), name);
}
}  // namespace

void File::WriteDoubles(const std::string& name, const std::vector<hsize_t>& dims, const double* data) const {
  WriteWhole(*this, name, dims, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, data, raw_chunks_);
}
void File::WriteFloats(const std::string& name, const std::vector<hsize_t>& dims, const float* data, Storage storage,
                       const std::vector<hsize_t>& chunk) const {
  if (storage == Storage::kFloat16) {
    const auto half = ToHalf(data, Elements(dims));
    WriteWhole(*this, name, dims, HalfType(), HalfType(), half.data(), raw_chunks_, chunk);
  } else {
    WriteWhole(*this, name, dims, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, data, raw_chunks_, chunk);
  }
}
void File::WriteInts(const std::string& name, const std::vector<hsize_t>& dims, const std::int32_t* data) const {
  WriteWhole(*this, name, dims, H5T_STD_I32LE, H5T_NATIVE_INT32, data, raw_chunks_);
}

void File::WriteCodes(const std::string& name, const std::vector<hsize_t>& dims, const std::uint16_t* data,
                      int bits) const {
  if (bits != 8 && bits != 16) ThrowUsage("codes of {} bits (8 or 16)", bits);
  WriteWhole(*this, name, dims, bits == 8 ? H5T_STD_U8LE : H5T_STD_U16LE, H5T_NATIVE_UINT16, data, raw_chunks_);
}

Handle File::OpenDataset(const std::string& name) const {
  if (!Exists(name)) ThrowBadInput("'{}': required dataset '{}' is missing", path_, name);
  Handle ds(H5Dopen2(id(), name.c_str(), H5P_DEFAULT));
  if (!ds.valid()) ThrowBadInput("'{}': '{}' is not a dataset (corrupt file?)", path_, name);
  return ds;
}

std::vector<hsize_t> File::Dims(const std::string& name) const {
  Handle ds = OpenDataset(name);
  Handle space(H5Dget_space(ds.id()));
  const int rank = H5Sget_simple_extent_ndims(space.id());
  if (rank < 0 || rank > 8) ThrowBadInput("'{}': dataset '{}' has an invalid shape", path_, name);
  std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
  H5Sget_simple_extent_dims(space.id(), dims.data(), nullptr);
  return dims;
}

namespace {
// A chunk of a chunked dataset that no writer wrote reads as fill values (zeros): refuses any
// chunk of [offset, offset + count) (empty vectors: the whole dataset) that holds no data.
void RefuseUnwrittenChunks(const File& f, hid_t ds, const std::string& name, const std::vector<hsize_t>& offset,
                           const std::vector<hsize_t>& count) {
  Handle dcpl(H5Dget_create_plist(ds));
  if (H5Pget_layout(dcpl.id()) != H5D_CHUNKED) return;
  Handle space(H5Dget_space(ds));
  const int rank = H5Sget_simple_extent_ndims(space.id());
  if (rank <= 0) return;
  const std::size_t n = static_cast<std::size_t>(rank);
  std::vector<hsize_t> dims(n), chunk(n), lo(n), hi(n), at(n);
  H5Sget_simple_extent_dims(space.id(), dims.data(), nullptr);
  if (H5Pget_chunk(dcpl.id(), rank, chunk.data()) != rank) return;
  for (std::size_t d = 0; d < dims.size(); ++d) {
    const hsize_t first = offset.empty() ? 0 : offset[d], n = count.empty() ? dims[d] : count[d];
    if (n == 0 || chunk[d] == 0) return;
    lo[d] = first / chunk[d], hi[d] = (first + n - 1) / chunk[d];
  }
  std::vector<hsize_t> c = lo;
  for (;;) {
    for (std::size_t d = 0; d < dims.size(); ++d) at[d] = c[d] * chunk[d];
    hsize_t stored = 0;
    if (H5Dget_chunk_storage_size(ds, at.data(), &stored) < 0 || stored == 0)
      ThrowBadInput("'{}': dataset '{}': its chunk at ({}) was never written, so it holds no values (the file is "
                    "incomplete: its writer stopped early or wrote only part of it); write the file again",
                    f.path(), name, fmt::join(at, ", "));
    std::size_t d = dims.size();
    while (d > 0 && ++c[d - 1] > hi[d - 1]) c[d - 1] = lo[d - 1], --d;
    if (d == 0) return;
  }
}

template <typename T>
std::vector<T> ReadWhole(const File& f, const std::string& name, hid_t mem_type, H5T_class_t want_class) {
  const auto dims = f.Dims(name);
  double elements = 1;
  for (auto d : dims) elements *= double(d);
  CheckAllocation(elements * sizeof(T), fmt::format("'{}': dataset '{}'", f.path(), name));
  const auto n = static_cast<std::size_t>(elements);
  Handle ds(H5Dopen2(f.id(), name.c_str(), H5P_DEFAULT));
  Handle type(H5Dget_type(ds.id()));
  const H5T_class_t cls = H5Tget_class(type.id());
  if (cls != want_class && !(want_class == H5T_FLOAT && cls == H5T_INTEGER))
    ThrowBadInput("'{}': dataset '{}' has the wrong element type", f.path(), name);
  RefuseUnwrittenChunks(f, ds.id(), name, {}, {});
  std::vector<T> out(n);
  if constexpr (std::is_same_v<T, float>) {
    if (StoredAsHalf(ds.id())) {
      std::vector<std::uint16_t> half(n);
      if (n > 0 && H5Dread(ds.id(), HalfType(), H5S_ALL, H5S_ALL, H5P_DEFAULT, half.data()) < 0)
        ThrowUnreadable(f.path(), fmt::format("dataset '{}'", name));
      FromHalf(half, out.data());
      return out;
    }
  }
  if (n > 0 && H5Dread(ds.id(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
    ThrowUnreadable(f.path(), fmt::format("dataset '{}'", name));
  return out;
}
}  // namespace

std::vector<double> File::ReadDoubles(const std::string& name) const {
  return ReadWhole<double>(*this, name, H5T_NATIVE_DOUBLE, H5T_FLOAT);
}
std::vector<float> File::ReadFloats(const std::string& name) const {
  return ReadWhole<float>(*this, name, H5T_NATIVE_FLOAT, H5T_FLOAT);
}
std::vector<std::int32_t> File::ReadInts(const std::string& name) const {
  return ReadWhole<std::int32_t>(*this, name, H5T_NATIVE_INT32, H5T_INTEGER);
}

void File::CreateFloatArray(const std::string& name, const std::vector<hsize_t>& dims,
                            const std::vector<hsize_t>& chunk, Storage storage, int deflate_level) const {
  Handle space(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr));
  Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
  H5Pset_chunk(dcpl.id(), static_cast<int>(chunk.size()), chunk.data());
  if (deflate_level > 0) {
    H5Pset_shuffle(dcpl.id());
    H5Pset_deflate(dcpl.id(), static_cast<unsigned>(deflate_level));
  }
  H5Pset_fletcher32(dcpl.id());  // a damaged or truncated chunk is refused, never read as zeros
  const hid_t type = storage == Storage::kFloat16 ? HalfType() : H5T_IEEE_F32LE;
  Handle ds(H5Dcreate2(id(), name.c_str(), type, space.id(), H5P_DEFAULT, dcpl.id(), H5P_DEFAULT));
  if (!ds.valid()) ThrowIo("'{}': cannot create dataset '{}'", path_, name);
}

namespace {
Handle SelectSlab(const File& f, hid_t ds, const std::string& name, const std::vector<hsize_t>& offset,
                  const std::vector<hsize_t>& count) {
  Handle space(H5Dget_space(ds));
  const int rank = H5Sget_simple_extent_ndims(space.id());
  std::vector<hsize_t> dims(static_cast<std::size_t>(std::max(rank, 0)));
  H5Sget_simple_extent_dims(space.id(), dims.data(), nullptr);
  if (dims.size() != offset.size() || dims.size() != count.size())
    ThrowBadInput("'{}': dataset '{}' has rank {}, expected {}", f.path(), name, dims.size(), offset.size());
  for (std::size_t i = 0; i < dims.size(); ++i)
    if (offset[i] + count[i] > dims[i])
      ThrowBadInput("'{}': slab of '{}' out of range in dimension {} ({} + {} > {})", f.path(), name, i, offset[i],
                    count[i], dims[i]);
  H5Sselect_hyperslab(space.id(), H5S_SELECT_SET, offset.data(), nullptr, count.data(), nullptr);
  return space;
}
}  // namespace

void File::WriteSlab(const std::string& name, const std::vector<hsize_t>& offset, const std::vector<hsize_t>& count,
                     const float* data) const {
  Handle ds = OpenDataset(name);
  Handle fspace = SelectSlab(*this, ds.id(), name, offset, count);
  Handle mspace(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr));
  herr_t status;
  if (StoredAsHalf(ds.id())) {
    const auto half = ToHalf(data, Elements(count));
    status = H5Dwrite(ds.id(), HalfType(), mspace.id(), fspace.id(), H5P_DEFAULT, half.data());
  } else {
    status = H5Dwrite(ds.id(), H5T_NATIVE_FLOAT, mspace.id(), fspace.id(), H5P_DEFAULT, data);
  }
  if (status < 0) ThrowIo("'{}': cannot write to '{}' (disk full?)", path_, name);
}

void File::ReadSlab(const std::string& name, const std::vector<hsize_t>& offset, const std::vector<hsize_t>& count,
                    float* data, bool raw_chunks) const {
  SilenceErrors();
  Handle ds = OpenDataset(name);
  Handle fspace = SelectSlab(*this, ds.id(), name, offset, count);
  RefuseUnwrittenChunks(*this, ds.id(), name, offset, count);
  if (raw_chunks && ReadRawChunks(*this, ds.id(), name, offset, count, data, raw_chunks_)) return;
  Handle mspace(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr));
  herr_t status;
  if (StoredAsHalf(ds.id())) {
    std::vector<std::uint16_t> half(Elements(count));
    status = H5Dread(ds.id(), HalfType(), mspace.id(), fspace.id(), H5P_DEFAULT, half.data());
    if (status >= 0) FromHalf(half, data);
  } else {
    status = H5Dread(ds.id(), H5T_NATIVE_FLOAT, mspace.id(), fspace.id(), H5P_DEFAULT, data);
  }
  if (status < 0) ThrowUnreadable(path_, fmt::format("dataset '{}'", name));
}

std::string File::StorageOf(const std::string& name) const {
  Handle ds = OpenDataset(name);
  Handle type(H5Dget_type(ds.id()));
  if (H5Tget_class(type.id()) != H5T_FLOAT) ThrowBadInput("'{}': '{}' must hold floating-point values", path_, name);
  const std::size_t size = H5Tget_size(type.id());
  if (size == 2) return "float16";
  if (size == 4) return "float32";
  if (size == 8) return "float64";
  ThrowBadInput("'{}': '{}' has an unsupported {}-byte float type", path_, name, size);
}

void File::WriteFormatHeader(const std::string& format, const std::string& version, const std::string& creator) const {
  SetAttr("/", "format", format);
  SetAttr("/", "format_version", version);
  SetAttr("/", "creator", creator);
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  SetAttr("/", "creation_time", std::string(buf));
}

std::string File::CheckFormatHeader(const std::string& format, int supported_major) const {
  if (!HasAttr("/", "format"))
    ThrowBadInput("'{}' is not a libbtf file: the root attribute 'format' is missing", path_);
  const std::string got = GetString("/", "format");
  if (got != format) ThrowBadInput("'{}' holds a '{}', expected a '{}'", path_, got, format);
  const std::string version = GetString("/", "format_version");
  const int major = MajorVersion(version);
  if (major < 0) ThrowBadInput("'{}': format_version '{}' is not MAJOR.MINOR.PATCH", path_, version);
  if (major > supported_major)
    ThrowBadInput("'{}' is {} version {}, newer than this libbtf reads (major {}); upgrade libbtf", path_, format,
                  version, supported_major);
  return version;
}

void ThrowUnreadable(const std::string& path, const std::string& what) {
  if (LastErrorWasIo()) ThrowIo("'{}': cannot read {}: I/O error (failing disk or network file system?)", path, what);
  ThrowBadInput("'{}': cannot read {}: the file is truncated or corrupt", path, what);
}

void File::Close() {
  if (!file_.valid()) return;
  const bool flushed = H5Fflush(file_.id(), H5F_SCOPE_GLOBAL) >= 0 &&
                       (!created_ || g_failed_closes.load() == failed_closes_at_create_);
  const int err = errno;
  if (!flushed) DiscardUnwritten();
  const bool closed = H5Fclose(file_.release()) >= 0;
  if (!flushed || !closed)
    ThrowIo("cannot write HDF5 file '{}' ({}): disk full or I/O error?", path_, std::strerror(flushed ? errno : err));
}

void File::DiscardUnwritten() const {
  // HDF5 1.10 cannot close a file whose cached data it cannot write, and a second H5Fclose of
  // it crashes: free the file's space (its content is being discarded: only files this object
  // created, whose owner removes them) and flush again, so the close that follows succeeds.
  if (created_ && truncate(path_.c_str(), 0) == 0) H5Fflush(file_.id(), H5F_SCOPE_GLOBAL);
}

void File::CloseQuietly() {
  if (!file_.valid()) return;
  if (created_ && H5Fflush(file_.id(), H5F_SCOPE_GLOBAL) < 0) DiscardUnwritten();
  H5Fclose(file_.release());
}

File& File::operator=(File&& other) noexcept {
  if (this != &other) {
    CloseQuietly();
    file_ = std::move(other.file_);
    path_ = std::move(other.path_);
    created_ = other.created_;
  }
  return *this;
}

File::~File() { CloseQuietly(); }

}  // namespace btf::h5
