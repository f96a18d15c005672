#pragma once
// BTF codecs as stored: per-view PCA (Sattler et al. 2003), local PCA (Mueller et al. 2003, as
// described in Schneider 2004 section 3), LPCA with factorised Eigen-ABRDFs (lpca_tensor.h) and
// Bonn's full-matrix factorisations FMF / DFMF (fmf_codec.h), the neural codec (neural_codec.h); their file format "libbtf-codec"
// (docs/format.md) and decoders. The bottom layer of compress/: the compressors
// (compress.h) fill a Codec through CodecBuilder; nothing here calls them.
//
// Stable public API (btf-eval and btf-compress code against it):
//   WriteCodec / ReadCodec       codec file I/O (atomic write; versioned like the dataset format)
//   Codec::Decode*               whole BTF, one view slot, one image, one texel ABRDF, one value
//   Codec::StoredBytes, RawBytes sizes; Codec::views()/lights() the samplings
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/compress/fmf_codec.h"
#include "libbtf/compress/lpca_tensor.h"
#include "libbtf/compress/neural_codec.h"
#include "libbtf/compress/value_transform.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/dataset.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/slot_source.h"

namespace btf {

inline constexpr const char* kCodecFormat = "libbtf-codec";
inline constexpr const char* kCodecFormatVersion = "1.2.0";
// Written by neural codecs only (the first version with them); every other codec stays 1.2.0.
inline constexpr const char* kNeuralCodecFormatVersion = "1.3.0";
inline constexpr int kCodecFormatMajor = 1;

enum class CodecMethod { kPcaView, kLpca, kFmf, kDfmf, kLpcaTensor, kNeural };
// "pca-view" / "lpca" / "fmf" / "dfmf" / "lpca-tensor" / "neural".
std::string MethodName(CodecMethod method);
// Throws btf::Error (usage) for unknown names.
CodecMethod ParseMethod(const std::string& name);
// fmf or dfmf: one truncated SVD of the whole BTF (fmf_codec.h).
inline bool IsFullMatrixFactorisation(CodecMethod m) { return m == CodecMethod::kFmf || m == CodecMethod::kDfmf; }

// How the codec's float coefficient arrays (means, bases, weights) are stored: float32, or IEEE
// half (float16 in the file: half the bytes; values rounded to nearest even before the errors
// are measured, so the summary's errors are those of the stored codec). Eigenvalues stay float64.
enum class CodecStorage { kFloat, kHalf };
// "float" / "half".
std::string StorageName(CodecStorage storage);
// Throws btf::Error (usage) for unknown names.
CodecStorage ParseStorage(const std::string& name);
// Per-view PCA of one view slot: the lights' images (H*W*C vectors) are the observations.
// value(l, t) = mean[t] + sum_k weights[l*c + k] * basis[k*D + t]   (D = H*W*C, t = texel*C + ch)
struct PcaViewSlot {
  int components = 0;
  std::vector<float> mean;     // D: the mean image ("mean normtexture")
  std::vector<float> basis;    // c x D: eigen-normtextures, orthonormal
  std::vector<float> weights;  // L x c: per-light weights
  std::vector<double> eigenvalues;  // c: variance captured by each component (sum of squares)
};

// Local PCA: ABRDF vectors (d = V*L*C, index (v*L + l)*C + ch) clustered into k clusters.
// value(texel, i) = means[k*d + i] + sum_j weights[texel*c + j] * basis[(k*c + j)*d + i],
// k = cluster_of[texel]; components beyond cluster_components[k] are stored as zeros.
struct LpcaModel {
  int clusters = 0, components = 0;  // components = c, the stride of basis and weights
  std::vector<float> means;          // k x d
  std::vector<float> basis;          // k x c x d, orthonormal per cluster
  std::vector<std::int32_t> cluster_components;  // k
  std::vector<std::int32_t> cluster_of;          // H*W (row-major, row 0 = top)
  std::vector<float> weights;                    // H*W x c
};

enum class UvFilter { kNearest, kBilinear };

class Codec {
 public:
  Codec() = default;

  CodecMethod method() const { return method_; }
  const Sampling& views() const { return views_; }
  const Sampling& lights() const { return lights_; }
  int num_views() const { return views_.size(); }
  int num_lights() const { return lights_.size(); }
  int height() const { return height_; }
  int width() const { return width_; }
  int channels() const { return channels_; }
  const DatasetInfo& info() const { return info_; }
  ValueTransform transform() const { return value_map_.kind; }
  const ValueMap& value_map() const { return value_map_; }
  CodecStorage storage() const { return storage_; }
  double log_epsilon() const { return value_map_.epsilon; }
  const std::vector<PcaViewSlot>& pca_view() const { return slots_; }
  const LpcaModel& lpca() const { return lpca_; }
  const FmfModel& fmf() const { return fmf_; }
  const LpcaTensorModel& lpca_tensor() const { return tensor_; }
  const NeuralCodecModel& neural() const { return neural_; }
  // Options and summary of the compression that made it (JSON, stored in the file).
  const nlohmann::json& provenance() const { return provenance_; }

  std::size_t image_size() const { return std::size_t(height_) * width_ * channels_; }
  std::size_t abrdf_size() const { return std::size_t(num_views()) * num_lights() * channels_; }
  // Bytes of the coefficient arrays as stored (float32 or float16, int32); sampling tables not counted.
  std::uint64_t StoredBytes() const;
  // Bytes of the decoded BTF as float32 / float16.
  std::uint64_t RawBytes(int bytes_per_value = 4) const;

  // Decoders (values in the original domain; transform undone).
  Dataset DecodeAll() const;
  void DecodeViewSlot(int view, float* out) const;            // L x H x W x C
  void DecodeImage(int view, int light, float* out) const;    // H x W x C
  std::vector<float> DecodeAbrdf(int y, int x) const;         // V x L x C (Dataset::Abrdf layout)
  // Value at texture coordinates uv (wrapping: the tile repeats), light direction wi and view
  // direction wo (both leaving the surface): barycentric over the three nearest sampled view and
  // light directions (9 pairs), nearest or bilinear in uv. neural: the decoder at (wi, wo)
  // themselves (normalised), its latent nearest or bilinear in uv. out: C floats.
  void Value(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out, UvFilter filter = UvFilter::kBilinear) const;

  // btf-info's summary.
  nlohmann::json Describe() const;

 private:
  friend class CodecBuilder;
  float Untransform(float y) const { return value_map_.Inverse(y); }
  // Value of sampled (view, light) at texel t (row-major index), transformed domain, C floats.
  void SampleTransformed(int view, int light, std::size_t texel, float* out) const;
  // neural: Value's decoder at (wi, wo) with the texel taps' latents mixed.
  void NeuralValue(const std::vector<std::pair<std::size_t, double>>& taps, const Vec3& wi, const Vec3& wo,
                   float* out) const;

  CodecMethod method_ = CodecMethod::kPcaView;
  Sampling views_, lights_;
  int height_ = 0, width_ = 0, channels_ = 0;
  DatasetInfo info_;
  ValueMap value_map_;
  CodecStorage storage_ = CodecStorage::kFloat;
  std::vector<PcaViewSlot> slots_;
  LpcaModel lpca_;
  FmfModel fmf_;
  LpcaTensorModel tensor_;
  NeuralCodecModel neural_;
  nlohmann::json provenance_ = nlohmann::json::object();
};

// Fills the private parts of a Codec (used by the compressors and the reader).
class CodecBuilder {
 public:
  static Codec Make(CodecMethod method, Sampling views, Sampling lights, int height, int width, int channels,
                    DatasetInfo info, const ValueMap& transform);
  static std::vector<PcaViewSlot>& slots(Codec& c) { return c.slots_; }
  static LpcaModel& lpca(Codec& c) { return c.lpca_; }
  static FmfModel& fmf(Codec& c) { return c.fmf_; }
  static LpcaTensorModel& lpca_tensor(Codec& c) { return c.tensor_; }
  static NeuralCodecModel& neural(Codec& c) { return c.neural_; }
  static nlohmann::json& provenance(Codec& c) { return c.provenance_; }
  static CodecStorage& storage(Codec& c) { return c.storage_; }
};

// Codec files ("libbtf-codec" 1.2.0; neural codecs 1.3.0, the first version that has them;
// docs/format.md). Written atomically.
void WriteCodec(const std::filesystem::path& path, const Codec& codec, const std::string& creator = "libbtf");
// Writes into `out`'s temporary and commits it (for callers that reserved the output early).
void WriteCodec(AtomicOutput& out, const Codec& codec, const std::string& creator = "libbtf");
// Refuses other formats, newer major versions, missing items and inconsistent shapes (bad input).
Codec ReadCodec(const std::filesystem::path& path);

struct DecodeSummary {
  std::string output;
  std::string method;
  std::uint64_t bytes_decoded = 0;  // float32 values written
  PhaseTimes times;                 // decode (decode + write, interleaved per view slot)
  nlohmann::json ToJson() const;
  std::string Report() const;
};

// Decodes a codec into a dataset file, view slot by view slot (atomic).
DecodeSummary DecodeToDatasetFile(const Codec& codec, const std::filesystem::path& path, const Reporter& reporter = {});

// "1.23 MiB" etc., for text reports.
std::string FormatBytes(std::uint64_t bytes);

}  // namespace btf
