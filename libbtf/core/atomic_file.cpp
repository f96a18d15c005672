#include "libbtf/core/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>

#include <array>
#include <atomic>
#include <csignal>
#include <cstring>
#include <fstream>
#include <random>

#include "libbtf/core/error.h"

namespace btf {
namespace {

// Fixed table of live temporaries, readable from a signal handler without locks.
constexpr int kSlots = 64;
constexpr std::size_t kPathMax = 4096;
std::array<std::atomic<bool>, kSlots> g_used{};
std::array<std::array<char, kPathMax>, kSlots> g_paths{};

int Register(const std::string& path) {
  if (path.size() >= kPathMax) return -1;
  for (int i = 0; i < kSlots; ++i) {
    bool expected = false;
    if (!g_used[i].load() && g_used[i].compare_exchange_strong(expected, true)) {
      std::memcpy(g_paths[i].data(), path.c_str(), path.size() + 1);
      std::atomic_signal_fence(std::memory_order_seq_cst);
      return i;
    }
  }
  return -1;
}

void Unregister(int slot) {
  if (slot >= 0) g_used[slot].store(false);
}

extern "C" void CleanupAndReraise(int sig) {
  for (int i = 0; i < kSlots; ++i)
    if (g_used[i].load()) ::unlink(g_paths[i].data());
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

}  // namespace

AtomicOutput::AtomicOutput(std::filesystem::path final_path) : final_(std::move(final_path)) {
  std::random_device rd;
  const auto dir = final_.has_parent_path() ? final_.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(dir))
    ThrowIo("output folder '{}' does not exist: create it first", dir.string());
  // Keep the extension last: some writers (OpenImageIO) choose the file type from it.
  temp_ = dir / fmt::format(".{}.tmp-{}-{:08x}{}", final_.stem().string(), ::getpid(), rd(),
                            final_.extension().string());
  slot_ = Register(temp_.string());
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
  const auto dir = final_.has_parent_path() ? final_.parent_path() : std::filesystem::path(".");
  SyncPath(dir, O_RDONLY | O_DIRECTORY);  // best effort: some file systems refuse a folder fsync
}

void WriteTextFileAtomic(const std::filesystem::path& path, const std::string& text) {
  AtomicOutput out(path);
  {
    std::ofstream f(out.temp_path(), std::ios::binary);
    f << text;
    f.close();
    if (!f) ThrowIo("cannot write '{}': disk full or no permission?", path.string());
  }
  out.Commit();
}

void InstallSignalCleanup() {
  std::signal(SIGINT, CleanupAndReraise);
  std::signal(SIGTERM, CleanupAndReraise);
}

}  // namespace btf
