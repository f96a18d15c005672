// module: compress
// Structure-aware fuzzing of the codec reader (libbtf-codec, schema validation on top of HDF5).
// Four valid codec files (pca-view, lpca, fmf with a log, dfmf) are made once; each input then deletes, retypes,
// reshapes or overwrites some of their items and attributes before ReadCodec reads the result,
// so the fuzzer explores our validation rather than HDF5's checksum rejection. Whatever the
// reader accepts must decode every view slot and an ABRDF without touching memory it does not
// own (ASan) or undefined behavior (UBSan).
#include <hdf5.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/core/error.h"
#include "libbtf/io/hdf5.h"

namespace {

class Bytes {
 public:
  Bytes(const std::uint8_t* d, std::size_t n) : d_(d), n_(n) {}
  bool empty() const { return i_ >= n_; }
  std::uint8_t Next() { return i_ < n_ ? d_[i_++] : 0; }
  double Number() {
    switch (Next() % 10) {
      case 0: return std::numeric_limits<double>::quiet_NaN();
      case 1: return std::numeric_limits<double>::infinity();
      case 2: return -1;
      case 3: return 0;
      case 4: return 1e300;
      case 5: return 1 << 20;
      case 6: return 4294967296.0 + Next();
      default: return Next() % 8;
    }
  }

 private:
  const std::uint8_t* d_;
  std::size_t n_, i_ = 0;
};

std::array<std::string, 8> base_paths;

btf::Dataset TinyDataset() {
  const btf::Sampling views("v", {btf::Vec3(0, 0, 1), btf::Vec3(0.5, 0, 0.866), btf::Vec3(0, 0.5, 0.866)});
  const btf::Sampling lights("l", {btf::Vec3(0, 0, 1), btf::Vec3(0.6, 0, 0.8), btf::Vec3(0, 0.6, 0.8),
                                   btf::Vec3(-0.6, 0, 0.8)});
  btf::Dataset d(views, lights, 3, 2, 3);
  for (int v = 0; v < d.num_views(); ++v)
    for (int l = 0; l < d.num_lights(); ++l) {
      auto img = d.image(v, l);
      for (std::size_t i = 0; i < img.size(); ++i) img[i] = 0.2f + 0.05f * float((v * 7 + l * 3 + i) % 11);
    }
  return d;
}

// Collects every object path and every attribute as "object@name" in the file.
struct Items {
  std::vector<std::string> datasets, attributes;
};

herr_t CollectAttr(hid_t, const char* name, const H5A_info_t*, void* op) {
  auto* pair = static_cast<std::pair<Items*, std::string>*>(op);
  pair->first->attributes.push_back(pair->second + "@" + name);
  return 0;
}

herr_t CollectObject(hid_t root, const char* name, const H5O_info_t* info, void* op) {
  auto* items = static_cast<Items*>(op);
  const std::string path = std::string(name) == "." ? "/" : "/" + std::string(name);
  if (info->type == H5O_TYPE_DATASET) items->datasets.push_back(path);
  std::pair<Items*, std::string> pair{items, path};
  H5Aiterate_by_name(root, path.c_str(), H5_INDEX_NAME, H5_ITER_NATIVE, nullptr, CollectAttr, &pair, H5P_DEFAULT);
  return 0;
}

void ReplaceDataset(const btf::h5::File& f, const std::string& name, Bytes& b) {
  H5Ldelete(f.id(), name.c_str(), H5P_DEFAULT);
  std::vector<hsize_t> dims(b.Next() % 6);
  hsize_t n = 1;
  for (auto& d : dims) n *= (d = b.Next() % 5);
  if (n == 0) return;  // a zero-size item is as good as a missing one
  const double value = b.Number();
  switch (b.Next() % 3) {
    case 0: {
      std::vector<float> v(n, static_cast<float>(value));
      f.WriteFloats(name, dims, v.data());
      break;
    }
    case 1: {
      std::vector<std::int32_t> v(n, std::isfinite(value) && std::abs(value) < 1e9 ? std::int32_t(value) : -7);
      f.WriteInts(name, dims, v.data());
      break;
    }
    default: f.WriteString(name, b.Next() & 1 ? "{\"a\": 1}" : "not json {"); break;
  }
}

void PokeDataset(const btf::h5::File& f, const std::string& name, Bytes& b) {
  // Overwrites one element of a numeric dataset, keeping its shape and type.
  const auto dims = f.Dims(name);
  hsize_t n = 1;
  for (auto d : dims) n *= d;
  if (n == 0 || n > (1u << 20)) return;
  const hid_t ds = H5Dopen2(f.id(), name.c_str(), H5P_DEFAULT);
  if (ds < 0) return;
  const hid_t type = H5Dget_type(ds);
  if (H5Tget_class(type) == H5T_FLOAT || H5Tget_class(type) == H5T_INTEGER) {
    std::vector<double> v(n);
    if (H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()) >= 0) {
      v[(b.Next() * 256u + b.Next()) % n] = b.Number();
      H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
    }
  }
  H5Tclose(type);
  H5Dclose(ds);
}

void ReplaceAttribute(const btf::h5::File& f, const std::string& item, Bytes& b) {
  const auto at = item.find('@');
  const std::string object = item.substr(0, at), name = item.substr(at + 1);
  H5Adelete_by_name(f.id(), object.c_str(), name.c_str(), H5P_DEFAULT);
  static const char* const kStrings[] = {"pca-view", "lpca", "fmf", "dfmf", "lpca-tensor", "neural", "uint8", "float16", "silu", "log", "none", "R,G,B", "", "2.0.0",
                                         "1.0.0", "libbtf-codec", "libbtf-dataset", "Y", "R,,B"};
  switch (b.Next() % 4) {
    case 0: return;  // deleted
    case 1: f.SetAttr(object, name, static_cast<std::int64_t>(std::isfinite(b.Number()) ? b.Number() : -1)); return;
    case 2: f.SetAttr(object, name, b.Number()); return;
    default: f.SetAttr(object, name, std::string(kStrings[b.Next() % std::size(kStrings)])); return;
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  btf::h5::SilenceErrors();
  const btf::Dataset d = TinyDataset();
  const std::string dir = std::filesystem::temp_directory_path() / ("btf-fuzz-codec-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  btf::CompressOptions pca;
  pca.components = 2;
  btf::CompressOptions lpca;
  lpca.method = btf::CodecMethod::kLpca;
  lpca.clusters = 2;
  lpca.components = 1;
  lpca.log_transform = true;
  base_paths[0] = dir + "/pca.h5";
  base_paths[1] = dir + "/lpca.h5";
  btf::Codec codec;
  btf::Compress(pca, *btf::MemorySource(d), &codec);
  btf::WriteCodec(base_paths[0], codec);
  btf::Compress(lpca, *btf::MemorySource(d), &codec);
  btf::WriteCodec(base_paths[1], codec);
  for (int i : {2, 3}) {  // full-matrix factorisations: fmf (log) and dfmf
    btf::CompressOptions fmf;
    fmf.method = i == 2 ? btf::CodecMethod::kFmf : btf::CodecMethod::kDfmf;
    fmf.components = 2;
    fmf.log_transform = i == 2;
    base_paths[std::size_t(i)] = dir + (i == 2 ? "/fmf.h5" : "/dfmf.h5");
    btf::Compress(fmf, *btf::MemorySource(d), &codec);
    btf::WriteCodec(base_paths[std::size_t(i)], codec);
  }
  for (int i : {4, 5}) {  // lpca-tensor: 8-bit codes (log) and 16-bit codes
    btf::CompressOptions t;
    t.method = btf::CodecMethod::kLpcaTensor;
    t.clusters = 2;
    t.components = 2;
    t.tensor.quant_bits = i == 4 ? 8 : 16;
    t.log_transform = i == 4;
    t.tensor.growth = 0;  // every term: the largest factor arrays the tiny input gives
    base_paths[std::size_t(i)] = dir + (i == 4 ? "/tensor8.h5" : "/tensor16.h5");
    btf::Compress(t, *btf::MemorySource(d), &codec);
    btf::WriteCodec(base_paths[std::size_t(i)], codec);
  }
  for (int i : {6, 7}) {  // neural: uint8 and half latents, a small decoder, a few steps
    btf::CompressOptions n;
    n.method = btf::CodecMethod::kNeural;
    n.neural.latent = 2;
    n.neural.hidden = {4};
    n.neural.samples = 256;
    n.neural.steps = 2;
    n.neural.batch = 64;
    n.neural.latent_storage = i == 6 ? "uint8" : "half";
    base_paths[std::size_t(i)] = dir + (i == 6 ? "/neural8.h5" : "/neural16.h5");
    btf::Compress(n, *btf::MemorySource(d), &codec);
    btf::WriteCodec(base_paths[std::size_t(i)], codec);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes b(data, size);
  const std::string path = "/tmp/btf-fuzz-codec-" + std::to_string(::getpid()) + ".h5";
  std::filesystem::copy_file(base_paths[b.Next() % base_paths.size()], path, std::filesystem::copy_options::overwrite_existing);
  try {
    btf::h5::File f = btf::h5::File::OpenForUpdate(path);
    Items items;
    H5Ovisit(f.id(), H5_INDEX_NAME, H5_ITER_NATIVE, CollectObject, &items);
    for (int edits = b.Next() % 4 + 1; edits > 0 && !b.empty(); --edits) {
      const std::size_t pick = b.Next();
      if (pick & 1) {
        if (items.attributes.empty()) continue;
        ReplaceAttribute(f, items.attributes[(pick >> 1) % items.attributes.size()], b);
      } else {
        if (items.datasets.empty()) continue;
        const std::string& name = items.datasets[(pick >> 1) % items.datasets.size()];
        if (b.Next() & 1) PokeDataset(f, name, b);
        else ReplaceDataset(f, name, b);
      }
    }
  } catch (const btf::Error&) {
    return 0;  // the mutator itself could not apply an edit; nothing to read
  }
  try {
    const btf::Codec c = btf::ReadCodec(path);
    std::vector<float> slot(c.image_size() * std::size_t(c.num_lights()));
    for (int v = 0; v < c.num_views(); ++v) c.DecodeViewSlot(v, slot.data());
    const auto abrdf = c.DecodeAbrdf(c.height() - 1, c.width() - 1);
    if (abrdf.size() != c.abrdf_size()) __builtin_trap();
  } catch (const btf::Error&) {
  }
  return 0;
}
