// Structure-aware fuzzing of the dataset reader's schema validation: the input bytes decide which
// required items a well-formed HDF5 file lacks or gets wrong (shapes, element types, attribute
// types and values, versions, direction vectors), so the fuzzer explores our validation rather
// than HDF5's checksum rejection (raw bytes: fuzz_dataset).
#include <cmath>
#include <cstring>
#include <limits>

#include "fuzz/fuzz_util.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/hdf5.h"

namespace {

class Bytes {
 public:
  Bytes(const std::uint8_t* d, std::size_t n) : d_(d), n_(n) {}
  std::uint8_t Next() { return i_ < n_ ? d_[i_++] : 0; }
  bool Flag() { return Next() & 1; }
  double Number() {
    switch (Next() % 8) {
      case 0: return std::numeric_limits<double>::quiet_NaN();
      case 1: return std::numeric_limits<double>::infinity();
      case 2: return -1;
      case 3: return 0;
      case 4: return 1e300;
      default: return Next() / 16.0;
    }
  }

 private:
  const std::uint8_t* d_;
  std::size_t n_, i_ = 0;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes b(data, size);
  const std::string path = "/tmp/btf-fuzz-schema-" + std::to_string(::getpid()) + ".h5";
  try {
    const btf::h5::File f = btf::h5::File::Create(path);
    if (!b.Flag()) f.SetAttr("/", "format", std::string(b.Flag() ? "libbtf-dataset" : "libbtf-codec"));
    if (!b.Flag()) f.SetAttr("/", "format_version", std::string(b.Flag() ? "1.0.0" : b.Flag() ? "2.1.0" : "x.y"));
    if (!b.Flag()) f.SetAttr("/", "creator", std::string("fuzz"));
    if (!b.Flag()) f.SetAttr("/", "creation_time", std::int64_t(b.Next()));
    if (!b.Flag()) {
      f.CreateGroup("/btf");
      if (!b.Flag()) f.SetAttr("/btf", "color_space", std::string("linear_srgb"));
      if (!b.Flag()) f.SetAttr("/btf", "units", std::string("brdf_per_sr"));
      if (!b.Flag()) f.SetAttr("/btf", "cos_theta_i_included", std::int64_t(b.Next() % 3));
      if (!b.Flag()) f.SetAttr("/btf", "channel_names", std::string(b.Flag() ? "R,G,B" : "Y"));
      if (!b.Flag()) f.SetAttr("/btf", "texel_size_mm", b.Number());
    }
    const hsize_t nv = b.Next() % 4, nl = b.Next() % 4, h = b.Next() % 3 + (b.Flag() ? 0 : 1), w = 2, c = b.Next() % 4;
    for (const char* prefix : {"/btf/view_directions", "/btf/light_directions"}) {
      if (b.Flag() || !f.Exists("/btf")) continue;
      const hsize_t n = prefix[5] == 'v' ? nv : nl;
      std::vector<double> xyz(n * 3);
      for (auto& v : xyz) v = b.Flag() ? b.Number() : 0.0;
      for (hsize_t i = 0; i < n; ++i)
        if (b.Flag()) xyz[3 * i + 2] = 1, xyz[3 * i] = xyz[3 * i + 1] = 0;
      const hsize_t cols = b.Flag() ? 3 : 2;
      if (n > 0) f.WriteDoubles(prefix, {n, cols}, xyz.data());
    }
    if (f.Exists("/btf") && !b.Flag()) {
      std::vector<hsize_t> dims{nv, nl, h, w, c};
      if (b.Flag()) dims.pop_back();
      hsize_t n = 1;
      for (auto d : dims) n *= d;
      if (n > 0) {
        std::vector<float> values(n, 0.5f);
        if (b.Flag()) {
          std::vector<std::int32_t> ints(n, 1);
          f.WriteInts("/btf/data", dims, ints.data());
        } else {
          f.WriteFloats("/btf/data", dims, values.data(), b.Flag() ? btf::h5::Storage::kFloat16 : btf::h5::Storage::kFloat32);
        }
      }
    }
  } catch (const btf::Error&) {
    std::remove(path.c_str());
    return 0;  // the generator itself may refuse a combination; nothing to read then
  }
  try {
    btf::Dataset d = btf::ReadDataset(path);
    // Whatever the reader accepts must be self-consistent.
    if (d.views().size() != d.num_views() || d.size() != d.image_size() * d.num_views() * d.num_lights()) __builtin_trap();
  } catch (const btf::Error&) {
  }
  std::remove(path.c_str());
  return 0;
}
