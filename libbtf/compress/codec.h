#pragma once
// BTF codecs: per-view PCA (Sattler et al. 2003), local PCA (Mueller et al. 2003, as described
// in Schneider 2004 section 3), LPCA with factorised Eigen-ABRDFs (lpca_tensor.h) and Bonn's
// full-matrix factorisations FMF / DFMF (fmf_codec.h),
// their file format "libbtf-codec" (docs/format.md) and decoders.
//
// Stable public API (btf-eval and btf-compress code against it):
//   Compress                     CompressOptions + view-slot source (memory or file) -> Codec
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
#include "libbtf/compress/scene.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/dataset.h"
#include "libbtf/core/progress.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/slot_source.h"

namespace btf {

inline constexpr const char* kCodecFormat = "libbtf-codec";
inline constexpr const char* kCodecFormatVersion = "1.2.0";
inline constexpr int kCodecFormatMajor = 1;

enum class CodecMethod { kPcaView, kLpca, kFmf, kDfmf, kLpcaTensor };
// "pca-view" / "lpca" / "fmf" / "dfmf" / "lpca-tensor".
std::string MethodName(CodecMethod method);
// Throws btf::Error (usage) for unknown names.
CodecMethod ParseMethod(const std::string& name);
// fmf or dfmf: one truncated SVD of the whole BTF (fmf_codec.h).
inline bool IsFullMatrixFactorisation(CodecMethod m) { return m == CodecMethod::kFmf || m == CodecMethod::kDfmf; }

// Value transform applied before the decomposition and undone after reconstruction.
// kLog: y = log(x + epsilon); decoding gives exp(y) - epsilon. Inputs must be > -epsilon.
enum class ValueTransform { kNone, kLog };

// How the codec's float coefficient arrays (means, bases, weights) are stored: float32, or IEEE
// half (float16 in the file: half the bytes; values rounded to nearest even before the errors
// are measured, so the summary's errors are those of the stored codec). Eigenvalues stay float64.
enum class CodecStorage { kFloat, kHalf };
// "float" / "half".
std::string StorageName(CodecStorage storage);
// Throws btf::Error (usage) for unknown names.
CodecStorage ParseStorage(const std::string& name);
// LPCA's memory limit: min(MaxAllocationBytes() (BTF_MAX_BYTES), MemAvailable of /proc/meminfo
// where readable). --lpca-memory auto goes out of core above it; out of core uses half of it.
std::uint64_t LpcaMemoryLimit();

struct CompressOptions {
  CodecMethod method = CodecMethod::kPcaView;
  // Components c: per view slot (pca-view) or per cluster (lpca). With an error or energy target
  // this is the maximum. Clamped (with a warning) to what the data allows: pca-view at most
  // lights - 1 per slot, lpca at most (cluster size - 1). Components whose eigenvalue is below
  // 1e-12 of the slot's (cluster's) largest are dropped (rank-deficient or constant data).
  // fmf / dfmf: components of the one SVD (per YUV channel for dfmf), at most min(rows, texels);
  // --error / --energy then apply per matrix, to the uncentred energy (fmf_codec.h).
  int components = 16;
  // LPCA clusters k; clamped (with a warning) to the number of texels.
  int clusters = 32;
  // If > 0: the smallest c (<= components) whose relative RMS error ||X - X'|| / ||X|| (in the
  // transformed domain) is <= target_error, chosen per slot / per cluster.
  double target_error = 0;
  // If > 0 (and < 1): the smallest c retaining this fraction of the centered variance.
  double retained_energy = 0;
  // If > 0: a byte budget for Codec::StoredBytes() (--bytes). pca-view, lpca, fmf, dfmf: the
  // largest c <= components whose codec is guaranteed to fit (their size grows with c; clamping
  // only shrinks it), refused (usage) if c = 1 does not fit. lpca-tensor: the factor terms with
  // the largest error reduction that fit after the fixed part (cluster tables and weights).
  // Excludes target_error and retained_energy.
  std::uint64_t max_bytes = 0;
  // lpca-tensor: bits of the quantised factors and weights (8 or 16).
  int quant_bits = 16;
  // lpca-tensor without target_error or max_bytes: keep factor terms until the dropped energy is
  // at most this fraction of the LPCA stage's squared residual (the codec's squared error grows
  // by at most this factor, before quantisation).
  double tensor_growth = 0.1;
  std::uint64_t seed = 1;  // k-means++ seeding and randomized SVD (deterministic for a seed)
  bool log_transform = false;
  double log_epsilon = 1e-3;  // epsilon of the log transform, in data units (1/sr)
  int max_iterations = 20;    // LPCA: PCA/reassignment rounds at most
  // LPCA memory mode: "auto" (out-of-core when the texel-major matrix, 4 N V L C bytes, exceeds
  // LpcaMemoryLimit()), "in-core" (hold the matrix; refused above BTF_MAX_BYTES) or "out-of-core"
  // (stream the view slots, docs/btf-compress.md "Out-of-core LPCA"). Same codec either way.
  std::string lpca_memory = "auto";
  // LPCA's texel-major matrix (in core, and each chunk out of core): "half" (IEEE binary16, 2 bytes
  // a value; the clusters are fitted to the half-rounded input, relative rounding <= 2^-11, the
  // error is measured against the input itself; a transformed value beyond +-65504 is refused,
  // naming it) or "float" (4 bytes a value, any finite input).
  std::string lpca_matrix = "half";
  // LPCA stops when an iteration improves the relative error by less than this fraction.
  double min_improvement = 1e-3;
  // LPCA: texels of the k-means sample, max(lpca_sample, clusters), all texels if there are no
  // more. When the sample is smaller than the texels, local-PCA rounds run on the sample alone
  // (mini-batch, in memory) before the rounds over all texels.
  int lpca_sample = 8192;
  // LPCA: split/merge trials on the sample after its rounds, at most (each: the cluster with the
  // largest residual split in two, the cluster whose removal costs least merged into the others,
  // rounds from there; kept if the sample's error falls, stopped at the first that does not fall
  // by min_improvement). 0: none, as before 2026-12-03.
  int lpca_splits = 4;
  // LPCA's per-cluster decomposition: Gram matrix of the smaller side (double) when min(n, d) <=
  // this, randomized SVD (c + 10 oversampling, 2 power iterations) otherwise. 256: the measured
  // crossover at c = 8 (bench_compress BM_ClusterPca, docs/btf-compress.md "Performance"); the
  // default was 1024 before 2026-12-03.
  int gram_limit = 256;
  // LPCA: a cluster refitted by the randomized path (more than gram_limit texels) after a
  // reassignment, or in the first fit over all texels (from the sample rounds' models), starts
  // from its previous basis plus 10 Gaussian columns with 1 subspace iteration (3 passes over its
  // rows instead of 4) instead of a Gaussian sketch; false: every fit starts cold as before
  // 2026-12-03.
  bool lpca_warm_start = true;
  // LPCA: each reassignment of all texels computes a texel's residual only under the clusters that
  // bounds on a sketch (the span of the clusters' means and first basis rows, built at the first
  // reassignment) leave as possibly best; the same assignment as under every cluster
  // (lpca_reassign.h). false: every cluster, as the check of that.
  bool lpca_prune = true;
  CodecStorage storage = CodecStorage::kFloat;  // coefficient storage (--storage float|half)
  std::optional<SceneSpec> scene;  // keep only what a scene needs (scene.h)
  void Check() const;
  // The options as stored in a codec's provenance (the scene separately).
  nlohmann::json ToJson() const;
};

struct CompressSummary {
  std::string method;
  std::string storage = "float";  // StorageName of the coefficient arrays; lpca-tensor: "uint8" / "uint16" codes
  std::string input;  // dataset path or "in-memory dataset"
  int views = 0, lights = 0, height = 0, width = 0, channels = 0;
  int components = 0;                  // the maximum stored per slot / cluster
  std::vector<int> slot_components;    // pca-view: per view slot; lpca: per cluster
  int clusters = 0;                    // lpca
  std::vector<double> iteration_errors;  // lpca: relative error after each PCA/reassignment round
  std::vector<int> iteration_changes;    // lpca: texels that changed cluster in each round
  // lpca: clusters whose residual was computed per texel (mean over all texels) in each
  // reassignment of all texels (the first from the sample's models): K without lpca_prune.
  std::vector<double> lpca_compared;
  // lpca: the sample's relative error after each local-PCA round on it (the first: Lloyd's
  // clusters; the sample is all texels when there are no more than lpca_sample), and after each
  // split/merge trial's rounds (kept only if lower).
  std::vector<double> sample_errors, split_errors;
  std::string lpca_memory;               // lpca: "in-core" or "out-of-core" (the mode used)
  std::string lpca_matrix;               // lpca: "half" or "float" (the texel matrix's storage)
  int lpca_passes = 0;                   // lpca: passes over the input's view slots
  std::uint64_t peak_rss_bytes = 0;      // lpca: the process's peak resident memory after compressing
  // lpca-tensor: rank-1 terms kept, quantisation bits, the LPCA stage's relative error and the
  // predicted error of the factorised codec (transformed domain, before quantisation of weights).
  int tensor_terms = 0, quant_bits = 0;
  double lpca_stage_error = 0, predicted_error = 0;
  std::uint64_t codec_bytes = 0;         // Codec::StoredBytes() (float arrays at 2 bytes with half storage)
  std::uint64_t raw_float32_bytes = 0, raw_half_bytes = 0;  // of the encoded (possibly reduced) BTF
  double ratio_float32 = 0, ratio_half = 0;
  // Errors of the decoded codec against its input, in the original (untransformed) domain.
  double rmse = 0, relative_error = 0, max_abs_error = 0;
  double psnr_db = 0, psnr_peak = 0;  // PSNR = 20 log10(peak / rmse), peak = max |input value|
  std::string psnr_peak_definition = "max |input value|";
  std::vector<std::string> warnings;
  // With a scene: what the full (scene-less) input would have taken at the same components.
  bool scene_used = false;
  int input_views = 0, input_lights = 0, input_height = 0, input_width = 0, input_channels = 0;
  std::uint64_t full_codec_bytes = 0, bytes_saved = 0;
  PhaseTimes times;
  nlohmann::json ToJson() const;
  std::string Report() const;  // what btf-compress prints
};

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
  ValueTransform transform() const { return transform_; }
  CodecStorage storage() const { return storage_; }
  double log_epsilon() const { return log_epsilon_; }
  const std::vector<PcaViewSlot>& pca_view() const { return slots_; }
  const LpcaModel& lpca() const { return lpca_; }
  const FmfModel& fmf() const { return fmf_; }
  const LpcaTensorModel& lpca_tensor() const { return tensor_; }
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
  // light directions (9 pairs), nearest or bilinear in uv. out: C floats.
  void Value(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out, UvFilter filter = UvFilter::kBilinear) const;

  // btf-info's summary.
  nlohmann::json Describe() const;

 private:
  friend class CodecBuilder;
  float Untransform(float y) const;
  // Value of sampled (view, light) at texel t (row-major index), transformed domain, C floats.
  void SampleTransformed(int view, int light, std::size_t texel, float* out) const;

  CodecMethod method_ = CodecMethod::kPcaView;
  Sampling views_, lights_;
  int height_ = 0, width_ = 0, channels_ = 0;
  DatasetInfo info_;
  ValueTransform transform_ = ValueTransform::kNone;
  double log_epsilon_ = 0;
  CodecStorage storage_ = CodecStorage::kFloat;
  std::vector<PcaViewSlot> slots_;
  LpcaModel lpca_;
  FmfModel fmf_;
  LpcaTensorModel tensor_;
  nlohmann::json provenance_ = nlohmann::json::object();
};

// Fills the private parts of a Codec (used by the compressors and the reader).
class CodecBuilder {
 public:
  static Codec Make(CodecMethod method, Sampling views, Sampling lights, int height, int width, int channels,
                    DatasetInfo info, ValueTransform transform, double log_epsilon);
  static std::vector<PcaViewSlot>& slots(Codec& c) { return c.slots_; }
  static LpcaModel& lpca(Codec& c) { return c.lpca_; }
  static FmfModel& fmf(Codec& c) { return c.fmf_; }
  static LpcaTensorModel& lpca_tensor(Codec& c) { return c.tensor_; }
  static nlohmann::json& provenance(Codec& c) { return c.provenance_; }
  static CodecStorage& storage(Codec& c) { return c.storage_; }
};

// Compresses `input` (an in-memory dataset through MemorySource, a file through
// OpenDatasetSource, ...) into *codec. pca-view reads it view slot by view slot (memory: about
// three view slots); lpca reads it slot by slot into a texel-major matrix (memory: the BTF once).
// NaN/Inf anywhere gives btf::Error (bad input) naming the item.
CompressSummary Compress(const CompressOptions& options, const SlotSource& input, Codec* codec,
                         const Reporter& reporter = {});

// Compress, then the codec file written into `out` and committed (nullptr: nothing written, e.g.
// on the MPI ranks other than 0): the same file as Compress + WriteCodec. pca-view in one process
// writes each view slot as soon as it and the slots before it are done, so the write overlaps the
// decomposition and the codec is never all in memory (at Bonn size 1 GiB of float coefficients).
// On failure nothing is committed.
CompressSummary CompressToFile(const CompressOptions& options, const SlotSource& input, AtomicOutput* out,
                               const std::string& creator, const Reporter& reporter = {});

// Codec files ("libbtf-codec" 1.2.0, docs/format.md). Written atomically.
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
