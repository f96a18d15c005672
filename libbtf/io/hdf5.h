#pragma once
// Thin RAII layer over the HDF5 C API (HDF5 1.10, thread-safe build: call from one thread).
// Every failure becomes a btf::Error that names the file and the item.
#include <hdf5.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "libbtf/core/error.h"

namespace btf::h5 {

// Owns one hid_t and closes it with the matching H5xclose.
class Handle {
 public:
  Handle() = default;
  explicit Handle(hid_t id) : id_(id) {}
  ~Handle() { reset(); }
  Handle(Handle&& o) noexcept : id_(o.id_) { o.id_ = H5I_INVALID_HID; }
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      o.id_ = H5I_INVALID_HID;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  hid_t id() const { return id_; }
  bool valid() const { return id_ >= 0; }
  void reset();
  // Gives up ownership without closing.
  hid_t release() {
    const hid_t id = id_;
    id_ = H5I_INVALID_HID;
    return id;
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
};

enum class Storage { kFloat32, kFloat16 };

// An open file with its path kept for messages.
class File {
 public:
  File() = default;
  File(File&&) noexcept = default;
  File& operator=(File&& other) noexcept;
  // Closes the file if Close() was not called (error paths): a created file whose cached data
  // cannot be written (disk full) has its space freed first so that the close succeeds and no
  // HDF5 object outlives the caller; its content is lost, which an error path wants (its owner
  // removes it).
  ~File();
  // Creates (truncating) a file for writing.
  static File Create(const std::filesystem::path& path);
  // Opens read-only; a missing, truncated or non-HDF5 file gives a bad-input/I/O error.
  static File Open(const std::filesystem::path& path);
  // Opens read-write, with the same checks as Open (edits in place: tests and fuzzers that damage files).
  static File OpenForUpdate(const std::filesystem::path& path);

  hid_t id() const { return file_.id(); }
  const std::string& path() const { return path_; }

  bool Exists(const std::string& object) const;
  void CreateGroup(const std::string& group) const;

  // Attributes on an object ("/" = root). Missing/ill-typed attributes throw bad-input errors.
  void SetAttr(const std::string& object, const std::string& name, const std::string& value) const;
  void SetAttr(const std::string& object, const std::string& name, std::int64_t value) const;
  void SetAttr(const std::string& object, const std::string& name, double value) const;
  bool HasAttr(const std::string& object, const std::string& name) const;
  std::string GetString(const std::string& object, const std::string& name) const;
  std::int64_t GetInt(const std::string& object, const std::string& name) const;
  double GetDouble(const std::string& object, const std::string& name) const;

  // Whole small datasets.
  void WriteString(const std::string& name, const std::string& text) const;
  std::string ReadString(const std::string& name) const;
  void WriteDoubles(const std::string& name, const std::vector<hsize_t>& dims, const double* data) const;
  void WriteFloats(const std::string& name, const std::vector<hsize_t>& dims, const float* data,
                   Storage storage = Storage::kFloat32, const std::vector<hsize_t>& chunk = {}) const;
  void WriteInts(const std::string& name, const std::vector<hsize_t>& dims, const std::int32_t* data) const;
  // Unsigned codes stored as 8- or 16-bit little-endian integers (bits 8: every value <= 255); read with ReadInts.
  void WriteCodes(const std::string& name, const std::vector<hsize_t>& dims, const std::uint16_t* data, int bits) const;
  std::vector<hsize_t> Dims(const std::string& name) const;
  // Reads a whole dataset converted to the requested type (checks the element count).
  std::vector<double> ReadDoubles(const std::string& name) const;
  std::vector<float> ReadFloats(const std::string& name) const;
  std::vector<std::int32_t> ReadInts(const std::string& name) const;

  // Chunked float dataset for large arrays: shuffle + deflate (deflate_level > 0), then fletcher32.
  void CreateFloatArray(const std::string& name, const std::vector<hsize_t>& dims, const std::vector<hsize_t>& chunk,
                        Storage storage, int deflate_level) const;
  // Reads or writes the hyperslab [offset, offset+count) of a float dataset.
  void WriteSlab(const std::string& name, const std::vector<hsize_t>& offset, const std::vector<hsize_t>& count,
                 const float* data) const;
  // raw_chunks: the chunks of a dataset stored as libbtf writes them are read raw and decoded on
  // the compute threads (raw_chunks.h; same values as H5Dread); false, or any other dataset: H5Dread.
  void ReadSlab(const std::string& name, const std::vector<hsize_t>& offset, const std::vector<hsize_t>& count,
                float* data, bool raw_chunks = true) const;
  // "float32" or "float16".
  std::string StorageOf(const std::string& name) const;

  // Writes the root attributes format, format_version, creator, creation_time.
  void WriteFormatHeader(const std::string& format, const std::string& version, const std::string& creator) const;
  // Checks the root `format` equals `format` and the major version is <= supported_major.
  // Returns the version string.
  std::string CheckFormatHeader(const std::string& format, int supported_major) const;

  // Asks the kernel to start writing this file's data written so far back to the disk, without
  // waiting (sync_file_range; best effort: nothing happens where the driver has no descriptor),
  // so that a long write's final fsync waits only for its tail.
  void StartWriteback() const;

  // Flushes and closes a file written through this object. Throws btf::Error (I/O) naming the
  // file when the data did not all reach it (disk full, I/O error): never commit it then.
  void Close();

 private:
  static File OpenExisting(const std::filesystem::path& path, unsigned flags);
  Handle OpenDataset(const std::string& name) const;
  // After a failed flush of a file this object created: frees its space and flushes again.
  void DiscardUnwritten() const;
  // Closes without reporting (destructor, move assignment).
  void CloseQuietly();
  Handle file_;
  std::string path_;
  mutable std::vector<std::uint8_t> raw_chunks_;  // raw chunk bytes read (ReadSlab) or written, reused
  bool created_ = false;  // made by Create(): its content may be discarded on a failed close
  std::uint64_t failed_closes_at_create_ = 0;
};

// The HDF5 type used for Storage::kFloat16 (IEEE binary16, little-endian).
hid_t HalfType();
// Turns off HDF5's automatic error printing (we report errors ourselves) and makes HDF5 note
// failed system calls for IoErrorSeen().
void SilenceErrors();
// True once an HDF5 call in this process failed because a read or write system call failed. A
// "corrupt file" conclusion drawn after that is unreliable (ReportedError).
bool IoErrorSeen();
// The error to report for `e` (the tools' top-level handler, libbtf.Error): a file read as
// damaged (bad input) after IoErrorSeen() is a failing disk, not bad data, so it becomes an I/O
// error (exit 4) whose message says so; any other error is returned unchanged.
Error ReportedError(const Error& e);
// Throws btf::Error for a failed read of `what` (e.g. "dataset 'x'") in `path`: I/O when the
// read system call failed, bad input (truncated or corrupt file) otherwise.
[[noreturn]] void ThrowUnreadable(const std::string& path, const std::string& what);

}  // namespace btf::h5
