#include "libbtf/core/atomic_file.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <array>
#include <atomic>
#include <csignal>
#include <cstring>
#include <fstream>
#include <string>
#include <random>

#include "libbtf/core/error.h"

namespace btf {
namespace {

// Fixed table of live temporaries, readable from a signal handler without locks.
constexpr int kSlots = 64;
constexpr std::size_t kPathMax = 4096;
std::array<std::atomic<bool>, kSlots> g_used{};
std::array<bool, kSlots> g_is_dir{};
std::array<std::array<char, kPathMax>, kSlots> g_paths{};

int Register(const std::string& path, bool is_dir) {
  if (path.size() >= kPathMax) return -1;
  for (int i = 0; i < kSlots; ++i) {
    bool expected = false;
    if (!g_used[i].load() && g_used[i].compare_exchange_strong(expected, true)) {
      std::memcpy(g_paths[i].data(), path.c_str(), path.size() + 1);
      g_is_dir[i] = is_dir;
      std::atomic_signal_fence(std::memory_order_seq_cst);
      return i;
    }
  }
  return -1;
}

void Unregister(int slot) {
  if (slot >= 0) g_used[slot].store(false);
}

// Removes the contents of the folder open as `fd`, with async-signal-safe calls only (getdents64,
// unlinkat): a signal handler cannot use std::filesystem. Folders nest at most `depth` deep.
void RemoveContentsAt(int fd, int depth) {
  alignas(8) char buf[4096];
  for (;;) {
    const long n = ::syscall(SYS_getdents64, fd, buf, sizeof buf);
    if (n <= 0) return;
    bool removed = false;
    for (long off = 0; off < n;) {
      const auto* d = reinterpret_cast<const struct dirent64*>(buf + off);
      off += d->d_reclen;
      const char* name = d->d_name;
      if (name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'))) continue;
      if (d->d_type == DT_DIR && depth > 0) {
        const int sub = ::openat(fd, name, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (sub >= 0) {
          RemoveContentsAt(sub, depth - 1);
          ::close(sub);
        }
        removed |= ::unlinkat(fd, name, AT_REMOVEDIR) == 0;
      } else {
        removed |= ::unlinkat(fd, name, 0) == 0;
      }
    }
    if (removed) ::lseek(fd, 0, SEEK_SET);  // entries moved: read the folder again
  }
}

extern "C" void CleanupAndReraise(int sig) {
  for (int i = 0; i < kSlots; ++i) {
    if (!g_used[i].load()) continue;
    if (g_is_dir[i]) {
      const int fd = ::open(g_paths[i].data(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
      if (fd >= 0) {
        RemoveContentsAt(fd, 4);
        ::close(fd);
      }
      ::rmdir(g_paths[i].data());
    } else {
      ::unlink(g_paths[i].data());
    }
  }
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

// A temporary name beside `final_path` in its folder: ".STEM.tmp-PID-RANDOM.EXT" (the extension
// last: some writers, OpenImageIO among them, choose the file type from it).
std::filesystem::path TemporaryName(const std::filesystem::path& final_path) {
  std::random_device rd;
  const auto dir = final_path.has_parent_path() ? final_path.parent_path() : std::filesystem::path(".");
  return dir / fmt::format(".{}.tmp-{}-{:08x}{}", final_path.stem().string(), ::getpid(), rd(),
                           final_path.extension().string());
}

// What sits at `path` (not following a final symbolic link), in words, when it is something an
// output must not replace: a folder, device, named pipe or socket; empty otherwise.
std::string UnreplaceableKind(const std::filesystem::path& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0 || S_ISREG(st.st_mode) || S_ISLNK(st.st_mode)) return {};
  if (S_ISDIR(st.st_mode)) return "a folder";
  if (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode)) return "a device";
  if (S_ISFIFO(st.st_mode)) return "a named pipe";
  return S_ISSOCK(st.st_mode) ? "a socket" : "not a regular file";
}

void RefuseUnreplaceable(const std::filesystem::path& path) {
  if (const std::string kind = UnreplaceableKind(path); !kind.empty())
    ThrowUsage("output '{}' is {}: only a regular file is replaced; choose a file name", path.string(), kind);
}

void RefuseMissingFolder(const std::filesystem::path& path) {
  const auto dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(dir))
    ThrowIo("output folder '{}' does not exist: create it first (mkdir -p '{}')", dir.string(), dir.string());
}

}  // namespace

void CheckOutput(const std::filesystem::path& output, const std::vector<std::filesystem::path>& inputs,
                 OutputKind kind) {
  namespace fs = std::filesystem;
  if (output.empty()) return;
  if (kind == OutputKind::kFile) RefuseUnreplaceable(output);
  RefuseMissingFolder(output);
  struct stat out {};
  if (::stat(output.c_str(), &out) != 0) return;  // a new output destroys nothing
  std::error_code ec;
  const fs::path folder = S_ISDIR(out.st_mode) ? fs::weakly_canonical(output, ec) : fs::path();
  for (const fs::path& input : inputs) {
    struct stat in {};
    if (input.empty() || ::stat(input.c_str(), &in) != 0) continue;
    if (in.st_dev == out.st_dev && in.st_ino == out.st_ino)
      ThrowUsage("output '{}' is the input '{}' (the same file): writing it would destroy the input; choose another "
                 "output name",
                 output.string(), input.string());
    if (folder.empty()) continue;
    const fs::path canonical = fs::weakly_canonical(input, ec);
    const auto [end, rest] = std::mismatch(folder.begin(), folder.end(), canonical.begin(), canonical.end());
    if (end == folder.end())
      ThrowUsage("output folder '{}' holds the input '{}': the folder is replaced as a whole, which would destroy "
                 "the input; choose another output folder",
                 output.string(), input.string());
  }
}

AtomicOutput::AtomicOutput(std::filesystem::path final_path) : final_(std::move(final_path)) {
  RefuseUnreplaceable(final_);
  RefuseMissingFolder(final_);
  temp_ = TemporaryName(final_);
  slot_ = Register(temp_.string(), false);
}

AtomicOutput::AtomicOutput(std::filesystem::path final_path, ReserveNow) : AtomicOutput(std::move(final_path)) {
  Reserve();  // the object is constructed: a throw here still runs the destructor
}

AtomicOutput::~AtomicOutput() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
  Unregister(slot_);
}

void AtomicOutput::Reserve() {
  std::ofstream f(temp_, std::ios::binary);
  if (!f) ThrowIo("cannot create '{}' in the output folder: no permission or disk full?", temp_.string());
}

namespace {

// fsync of a file or folder by path; false (errno set) on failure.
bool SyncPath(const std::filesystem::path& path, int flags) {
  const int fd = ::open(path.c_str(), flags | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  const int err = errno;
  ::close(fd);
  errno = err;
  return ok;
}

std::filesystem::path ParentOf(const std::filesystem::path& p) {
  return p.has_parent_path() ? p.parent_path() : std::filesystem::path(".");
}

}  // namespace

void AtomicOutput::Commit() {
  // The data reaches the disk before the name does, so a power cut leaves the old file or the
  // complete new one under the final name (docs/errors.md, "Faults").
  if (!SyncPath(temp_, O_RDONLY))
    ThrowIo("cannot write '{}' ({}): disk full or I/O error?", temp_.string(), std::strerror(errno));
  std::error_code ec;
  std::filesystem::rename(temp_, final_, ec);
  if (ec) ThrowIo("cannot move '{}' onto '{}': {}", temp_.string(), final_.string(), ec.message());
  committed_ = true;
  SyncPath(ParentOf(final_), O_RDONLY | O_DIRECTORY);  // best effort: some file systems refuse a folder fsync
}

void AtomicOutput::CommitTogether(const std::vector<AtomicOutput*>& outputs) {
  for (AtomicOutput* o : outputs)
    if (!SyncPath(o->temp_, O_RDONLY))
      ThrowIo("cannot write '{}' ({}): disk full or I/O error?", o->temp_.string(), std::strerror(errno));
  std::vector<std::filesystem::path> backups(outputs.size());
  const auto drop_backups = [&] {
    for (const auto& b : backups)
      if (!b.empty()) ::unlink(b.c_str());
  };
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    const auto& final = outputs[i]->final_;
    backups[i] = TemporaryName(final);
    if (::link(final.c_str(), backups[i].c_str()) != 0) backups[i].clear();  // no old file (or no hard links)
  }
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    AtomicOutput& o = *outputs[i];
    if (::rename(o.temp_.c_str(), o.final_.c_str()) == 0) {
      o.committed_ = true;
      continue;
    }
    const int err = errno;
    for (std::size_t j = 0; j < i; ++j) {  // undo: the old file back, or no file as before
      const auto& f = outputs[j]->final_;
      if (!backups[j].empty() && ::rename(backups[j].c_str(), f.c_str()) == 0) backups[j].clear();
      else if (backups[j].empty()) ::unlink(f.c_str());
    }
    drop_backups();
    ThrowIo("cannot move '{}' onto '{}': {}", o.temp_.string(), o.final_.string(), std::strerror(err));
  }
  drop_backups();
  for (AtomicOutput* o : outputs) SyncPath(ParentOf(o->final_), O_RDONLY | O_DIRECTORY);
}

AtomicDirectory::AtomicDirectory(std::filesystem::path final_path, std::string marker)
    : final_(std::move(final_path)) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(final_, ec)) {
    if (!fs::is_directory(final_, ec)) ThrowUsage("output '{}' exists and is not a folder: choose another name", final_.string());
    if (!fs::is_empty(final_, ec) && !fs::exists(final_ / marker, ec))
      ThrowUsage("output folder '{}' is not empty and holds no '{}', so it is not an earlier output of this kind; it "
                 "would be replaced as a whole: choose an empty or new folder",
                 final_.string(), marker);
  }
  RefuseMissingFolder(final_);  // one rule for file and folder outputs: the folder they go in exists
  temp_ = TemporaryName(final_);
  if (!fs::create_directory(temp_, ec))
    ThrowIo("cannot create '{}' beside the output folder: {} (no permission or disk full?)", temp_.string(), ec.message());
  slot_ = Register(temp_.string(), true);
}

AtomicDirectory::~AtomicDirectory() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove_all(temp_, ec);
  }
  Unregister(slot_);
}

void AtomicDirectory::Commit() {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(temp_, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    const bool dir = it->is_directory(ec);
    if (!SyncPath(it->path(), O_RDONLY | (dir ? O_DIRECTORY : 0)))
      ThrowIo("cannot write '{}' ({}): disk full or I/O error?", it->path().string(), std::strerror(errno));
  }
  if (ec) ThrowIo("cannot list '{}': {}", temp_.string(), ec.message());
  if (!SyncPath(temp_, O_RDONLY | O_DIRECTORY))
    ThrowIo("cannot write '{}' ({}): disk full or I/O error?", temp_.string(), std::strerror(errno));
  // A new name is taken by a rename; one that exists, or that another run created meanwhile
  // (ENOTEMPTY, EEXIST), is exchanged.
  fs::path old_folder = temp_;  // after the exchange, temp_ names the old folder
  const bool taken = ::rename(temp_.c_str(), final_.c_str()) != 0;
  if (taken && errno != ENOTEMPTY && errno != EEXIST)
    ThrowIo("cannot move '{}' onto '{}': {}", temp_.string(), final_.string(), std::strerror(errno));
  if (taken && ::renameat2(AT_FDCWD, temp_.c_str(), AT_FDCWD, final_.c_str(), RENAME_EXCHANGE) != 0) {
    if (errno != EINVAL && errno != ENOSYS && errno != ENOTSUP)
      ThrowIo("cannot move '{}' onto '{}': {}", temp_.string(), final_.string(), std::strerror(errno));
    // No exchange on this file system: move the old folder aside, then the new one in. A crash
    // between the two leaves the old folder under the aside name (docs/errors.md, "Faults").
    const fs::path aside = old_folder = TemporaryName(final_);
    if (::rename(final_.c_str(), aside.c_str()) != 0)
      ThrowIo("cannot move '{}' aside: {}", final_.string(), std::strerror(errno));
    if (::rename(temp_.c_str(), final_.c_str()) != 0) {
      const int err = errno;
      ::rename(aside.c_str(), final_.c_str());
      ThrowIo("cannot move '{}' onto '{}': {}", temp_.string(), final_.string(), std::strerror(err));
    }
  }
  committed_ = true;
  SyncPath(ParentOf(final_), O_RDONLY | O_DIRECTORY);
  fs::remove_all(old_folder, ec);
}

void WriteFileAtomic(const std::filesystem::path& path, const void* data, std::size_t size) {
  AtomicOutput out(path);
  const int fd = ::open(out.temp_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) ThrowIo("cannot create '{}': {} (no permission or disk full?)", out.temp_path().string(), std::strerror(errno));
  const auto* p = static_cast<const char*>(data);
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, p + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : EIO;
      ::close(fd);
      ThrowIo("cannot write '{}' ({}): disk full or I/O error?", path.string(), std::strerror(err));
    }
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0) ThrowIo("cannot write '{}' ({}): disk full or I/O error?", path.string(), std::strerror(errno));
  out.Commit();
}

void WriteTextFileAtomic(const std::filesystem::path& path, const std::string& text) {
  WriteFileAtomic(path, text.data(), text.size());
}

std::string ReadFileBytes(const std::filesystem::path& path, const std::string& what) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) ThrowIo("cannot open {} '{}': {} (check the path)", what, path.string(), std::strerror(errno));
  std::string bytes;
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      ::close(fd);
      ThrowIo("cannot read {} '{}': {} (failing disk or network file system?)", what, path.string(), std::strerror(err));
    }
    if (n == 0) break;
    bytes.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return bytes;
}

void InstallSignalCleanup() {
  std::signal(SIGINT, CleanupAndReraise);
  std::signal(SIGTERM, CleanupAndReraise);
}

}  // namespace btf
