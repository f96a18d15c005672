#pragma once
// Fuzz targets feed bytes to readers that take file paths: write them to a private temp file.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

namespace btf::fuzz {

class TempInput {
 public:
  TempInput(const std::uint8_t* data, std::size_t size, const char* suffix) {
    path_ = "/tmp/btf-fuzz-" + std::to_string(::getpid()) + suffix;
    if (FILE* f = std::fopen(path_.c_str(), "wb")) {
      std::fwrite(data, 1, size, f);
      std::fclose(f);
    }
  }
  ~TempInput() { std::remove(path_.c_str()); }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace btf::fuzz
