#pragma once
// The libbtf dataset file, format "libbtf-dataset" version 1 (normative: docs/format.md).
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "libbtf/core/dataset.h"
#include "libbtf/io/hdf5.h"

namespace btf {

inline constexpr const char* kDatasetFormat = "libbtf-dataset";
inline constexpr const char* kDatasetFormatVersion = "1.0.0";
// Written by files that mark images missing (/btf/missing), the first version that has it.
inline constexpr const char* kDatasetFormatVersionMissing = "1.1.0";
inline constexpr int kDatasetFormatMajor = 1;

struct DatasetWriteOptions {
  h5::Storage storage = h5::Storage::kFloat32;  // kFloat16 halves the size (about 3 significant digits)
  int deflate_level = 4;                        // 0 = no compression, 1..9 = deflate level (with shuffle)
  std::string creator = "libbtf";               // stored in the root attribute "creator"
  void Check() const;
};

struct DatasetReadOptions {
  // true: the chunks of /btf/data are read raw and decoded on the compute threads (Fletcher-32,
  // libdeflate inflate, unshuffle, half -> float; docs/btf-compress.md "Reading"), whenever the
  // file stores them as libbtf writes them; other files, and false: H5Dread (single-threaded
  // zlib). Both give the same values. The tools set false when the environment has
  // BTF_RAW_CHUNKS=0 (A/B timings).
  bool raw_chunks = true;
};

// Everything about a dataset file except the texel values.
struct DatasetHeader {
  std::string path, format_version, creator, creation_time, storage;
  int num_views = 0, num_lights = 0, height = 0, width = 0, channels = 0;
  Sampling views, lights;
  DatasetInfo info;
  // (view, light) images the file marks missing (format 1.1, /btf/missing): their values are 0,
  // not measurements. Empty: every image was measured.
  std::vector<std::pair<int, int>> missing;
};

// Throws btf::Error (bad input) naming the file when it marks images missing; `needs` says what
// needs every image (e.g. "rendering interpolates between all sampled directions").
void RequireEveryImage(const DatasetHeader& header, const std::string& needs);

// Writes atomically (temporary file + rename).
void WriteDataset(const std::filesystem::path& path, const Dataset& dataset, const DatasetWriteOptions& options = {});
Dataset ReadDataset(const std::filesystem::path& path, const DatasetReadOptions& options = {});

// The sampling tables PREFIX_directions / PREFIX_angles as in the dataset format (also used by
// the codec format). Reading checks shape and unit length (bad input naming the file).
void WriteSamplingTables(const h5::File& file, const std::string& prefix, const Sampling& sampling);
Sampling ReadSamplingTables(const h5::File& file, const std::string& prefix);

// Random access without reading the whole file: one image or one view slot at a time.
class DatasetReader {
 public:
  explicit DatasetReader(const std::filesystem::path& path, const DatasetReadOptions& options = {});
  const DatasetHeader& header() const { return header_; }
  // height x width x channels floats.
  void ReadImage(int view, int light, float* out) const;
  // lights x height x width x channels floats.
  void ReadViewSlot(int view, float* out) const;

 private:
  h5::File file_;
  DatasetHeader header_;
  bool raw_chunks_;
};

// Incremental writer: create, write view slots (or images) in any order, then Commit(). Lets
// producers stream datasets larger than memory. Destroying without Commit() leaves no file.
class DatasetWriter {
 public:
  DatasetWriter(const std::filesystem::path& path, const Sampling& views, const Sampling& lights, int height, int width,
                int channels, const DatasetInfo& info, const DatasetWriteOptions& options = {});
  ~DatasetWriter();
  void WriteImage(int view, int light, const float* data);
  void WriteViewSlot(int view, const float* data);
  // Marks image (view, light) missing (write its values as 0): stored in /btf/missing at Commit.
  void MarkMissing(int view, int light);
  void Commit();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace btf
