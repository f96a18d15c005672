#pragma once
// Atomic outputs: write to a temporary name in the target folder, rename on success.
// An interrupted or failed run leaves neither a half-written file under the final name nor a
// stray temporary (on SIGINT/SIGTERM the temporaries are removed by InstallSignalCleanup()).
#include <filesystem>
#include <string>

namespace btf {

class AtomicOutput {
 public:
  explicit AtomicOutput(std::filesystem::path final_path);
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

 private:
  std::filesystem::path final_, temp_;
  int slot_ = -1;
  bool committed_ = false;
};

// Writes `text` to `path` atomically.
void WriteTextFileAtomic(const std::filesystem::path& path, const std::string& text);

// Installs SIGINT/SIGTERM handlers that delete live AtomicOutput temporaries, then re-raise the
// signal with its default action. Tools call this once at start-up.
void InstallSignalCleanup();

}  // namespace btf
