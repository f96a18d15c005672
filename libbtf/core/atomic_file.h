#pragma once
// Files, written and read with every system call checked. Atomic outputs: write to a temporary
// name in the target folder, rename on success.
// An interrupted or failed run leaves neither a half-written file under the final name nor a
// stray temporary (on SIGINT/SIGTERM the temporaries are removed by InstallSignalCleanup()).
#include <filesystem>
#include <string>
#include <vector>

namespace btf {

class AtomicOutput {
 public:
  // Only a regular file, a symbolic link (the link itself is replaced) or nothing may sit at
  // final_path: a folder, device, named pipe or socket there is refused (btf::Error, usage).
  explicit AtomicOutput(std::filesystem::path final_path);
  // Constructs and Reserve()s at once: an output claimed before long work, so that an unwritable
  // folder fails now, not after it (`AtomicOutput out(path, AtomicOutput::kReserve)`).
  enum ReserveNow { kReserve };
  AtomicOutput(std::filesystem::path final_path, ReserveNow);
  ~AtomicOutput();  // removes the temporary unless Commit() succeeded
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;

  const std::filesystem::path& temp_path() const { return temp_; }
  const std::filesystem::path& final_path() const { return final_; }
  // Creates the (empty) temporary now. Tools call it before long work so that an unwritable
  // folder fails at once, not after hours of compression. Throws btf::Error (I/O) on failure.
  void Reserve();
  // Renames the temporary onto the final name (replacing it). Throws btf::Error (I/O) on failure.
  void Commit();

  // Commits several outputs as one: all temporaries are synced, then renamed; if a rename fails,
  // the outputs already renamed get their old files back (kept as hard links meanwhile) or are
  // removed, so the set stays all old unless the process dies between two renames.
  static void CommitTogether(const std::vector<AtomicOutput*>& outputs);

 private:
  std::filesystem::path final_, temp_;
  int slot_ = -1;
  bool committed_ = false;
};

// A folder output (photos, export, sweep): written under a temporary name beside the final one,
// then swapped in whole by Commit(), so the final name holds the old folder or the complete new
// one. A tool writes into temp_path() and names files by final_path() in what it records.
class AtomicDirectory {
 public:
  // `marker` is a file every complete output of this kind holds (e.g. "manifest.json"). An
  // existing final path that is not a folder, or a non-empty folder without the marker (not an
  // earlier output), is refused here (btf::Error, usage) instead of being replaced later.
  AtomicDirectory(std::filesystem::path final_path, std::string marker);
  ~AtomicDirectory();  // removes the temporary folder unless Commit() succeeded
  AtomicDirectory(const AtomicDirectory&) = delete;
  AtomicDirectory& operator=(const AtomicDirectory&) = delete;

  const std::filesystem::path& temp_path() const { return temp_; }
  const std::filesystem::path& final_path() const { return final_; }
  // Syncs every file and folder under temp_path(), then exchanges it with the final folder
  // (renameat2 RENAME_EXCHANGE; two renames where the file system cannot exchange) and removes
  // the old one. Throws btf::Error (I/O) on failure, leaving the old folder in place.
  void Commit();

 private:
  std::filesystem::path final_, temp_;
  int slot_ = -1;
  bool committed_ = false;
};

// An output is one file (AtomicOutput) or one folder (AtomicDirectory).
enum class OutputKind { kFile, kFolder };

// Checks an output before any work, so that a run fails at once instead of after the work
// (empty output: nothing to check). Refuses (btf::Error, usage; exit 2) an output that would
// destroy an input: an output file that is the same file as an input (device and inode, so links
// and other spellings of the path count), or an output folder (replaced as a whole) that holds an
// input; a file output whose path holds a folder, device, named pipe or socket (as AtomicOutput);
// and (I/O, exit 4) an output whose folder does not exist. Inputs that do not exist are skipped.
void CheckOutput(const std::filesystem::path& output, const std::vector<std::filesystem::path>& inputs,
                 OutputKind kind = OutputKind::kFile);

// Writes `size` bytes to `path` atomically (checked POSIX writes, fsync, rename).
void WriteFileAtomic(const std::filesystem::path& path, const void* data, std::size_t size);
// Writes `text` to `path` atomically.
void WriteTextFileAtomic(const std::filesystem::path& path, const std::string& text);

// The whole content of `path`. Throws btf::Error naming `what` (e.g. "manifest") and the file:
// I/O when it cannot be opened or a read fails (streams would hide the read error, or throw
// std::ios_base::failure from inside a parser).
std::string ReadFileBytes(const std::filesystem::path& path, const std::string& what);

// Installs SIGINT/SIGTERM handlers that delete live AtomicOutput and AtomicDirectory
// temporaries, then re-raise the signal with its default action. Tools call this once at start-up.
void InstallSignalCleanup();

}  // namespace btf
