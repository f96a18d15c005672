#pragma once
// btf-compress's options (docs/btf-compress.md lists every flag with its default): what every
// method reads at the top, and one nested struct per method family, as RegisterOptions does.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/scene.h"

namespace btf {

// LPCA's memory limit: min(MaxAllocationBytes() (BTF_MAX_BYTES), MemAvailable of /proc/meminfo
// where readable). --lpca-memory auto goes out of core above it; out of core uses half of it.
std::uint64_t LpcaMemoryLimit();

// Local PCA (lpca, and the LPCA stage of lpca-tensor).
struct LpcaOptions {
  int max_iterations = 20;  // PCA/reassignment rounds at most
  // Stop when an iteration improves the relative error by less than this fraction.
  double min_improvement = 1e-3;
  // Memory mode: "auto" (out-of-core when the texel-major matrix, 4 N V L C bytes, exceeds
  // LpcaMemoryLimit()), "in-core" (hold the matrix; refused above BTF_MAX_BYTES) or "out-of-core"
  // (stream the view slots, docs/btf-compress.md "Out-of-core LPCA"). Same codec either way.
  std::string memory = "auto";
  // The texel-major matrix (in core, and each chunk out of core): "half" (IEEE binary16, 2 bytes
  // a value; the clusters are fitted to the half-rounded input, relative rounding <= 2^-11, the
  // error is measured against the input itself; a transformed value beyond +-65504 is refused,
  // naming it) or "float" (4 bytes a value, any finite input).
  std::string matrix = "half";
  // Texels of the k-means sample, max(sample, clusters), all texels if there are no more. When
  // the sample is smaller than the texels, local-PCA rounds run on the sample alone (mini-batch,
  // in memory) before the rounds over all texels.
  int sample = 8192;
  // Split/merge trials on the sample after its rounds, at most (each: the cluster with the
  // largest residual split in two, the cluster whose removal costs least merged into the others,
  // rounds from there; kept if the sample's error falls, stopped at the first that does not fall
  // by min_improvement). 0: none.
  int splits = 4;
  // k-means and the sample rounds work in the sample's principal subspace of this many dimensions
  // (a PCA of 2 subspace sample texels drawn with the seed; each texel's energy outside it is
  // carried as a constant), and their models are lifted back for the rounds over every texel,
  // which then fit the full dimension. Used where 2 subspace <= min(d, sample); 0: never (the
  // sample rounds in the full dimension, d = V L C). 128: on the 64² twill 1.70-1.95 s against
  // 8.25 s at a lower error (docs/performance.md, "LPCA").
  int subspace = 128;
  // Per-cluster decomposition: Gram matrix of the smaller side (double) when min(n, d) <= this,
  // randomized SVD (c + 10 oversampling, 2 power iterations) otherwise. 256: the measured
  // crossover at c = 8 (bench_compress BM_ClusterPca).
  int gram_limit = 256;
  // A cluster refitted by the randomized path after a reassignment, or in the first fit over all
  // texels, starts from its previous basis plus 4 Gaussian columns with 1 subspace iteration
  // (3 passes over its rows instead of 4); false: every fit starts cold.
  bool warm_start = true;
  // Each reassignment of all texels computes a texel's residual only under the clusters that
  // bounds on a sketch leave as possibly best: the same assignment as under every cluster
  // (lpca_reassign.h). false: every cluster, as the check of that.
  bool prune = true;
  void Check() const;
};

// lpca-tensor's factorisation of the LPCA clusters (lpca_tensor.h).
struct LpcaTensorOptions {
  int quant_bits = 16;  // bits of the quantised factors and weights (8 or 16)
  // Without target_error or max_bytes: keep factor terms until the dropped energy is at most this
  // fraction of the LPCA stage's squared residual (the codec's squared error grows by at most
  // this factor, before quantisation).
  double growth = 0.1;
  void Check() const;
};

// The neural codec (neural_codec.h, neural_net.h): its shape, training set and training. The
// provenance names are those of ToJson (neural_latent, ...), the flags --neural-latent etc.
struct NeuralOptions {
  // The defaults: on the 128² bonn81 twill (bench/neural_vs_linear.sh, docs/btf-compress.md
  // "Neural codec") relative error 0.113 at 269,836 bytes, where lpca-tensor needs 3 MB for 0.126.
  // Against them: latent 8 (137,676 bytes), 2^24 samples in 4 epochs, linear_loss 0 / 0.25 / 0.5 /
  // 0.75 / 1: 0.309 / 0.225 / 0.232 / 0.255 / 0.280. Hidden 64,64 with latent 8 reaches 0.088 at
  // 152,396 bytes (2^25 samples, 8 epochs) but its steps take about 3x longer and it decodes about
  // 3x slower.
  int latent = 16;                  // latent values per texel (the maximum with --bytes)
  std::vector<int> hidden{32, 32};  // decoder hidden widths
  int fourier = 0;                  // Fourier octaves of the direction encoding (0..8); the half vector always
  std::string latent_storage = "uint8";  // "uint8" (codes, scale and bias per latent channel) or "half"
  // Training samples (texel, light, view), drawn per view slot in one pass (4 (7 + C) bytes each:
  // 1.34 GB for RGB). 2^25 in 8 epochs (65536 steps of 4096).
  std::int64_t samples = std::int64_t(1) << 25;
  std::int64_t steps = 0;           // > 0: training steps; 0: ceil(epochs * samples / batch)
  double epochs = 8;
  int batch = 4096;                 // samples per step
  double learning_rate = 1e-2;      // decoder and latents, at step 0 (cosine decay to 5 %)
  double linear_loss = 0.5;         // weight of the linear-domain term in the loss (NeuralTrainOptions)
  void Check() const;
};

struct CompressOptions {
  CodecMethod method = CodecMethod::kPcaView;
  // Components c: per view slot (pca-view) or per cluster (lpca). With an error or energy target
  // this is the maximum. Clamped (with a warning) to what the data allows: pca-view at most
  // lights - 1 per slot, lpca at most (cluster size - 1). Components whose eigenvalue is below
  // 1e-12 of the slot's (cluster's) largest are dropped (rank-deficient or constant data).
  // fmf / dfmf: components of the one SVD (per YUV channel for dfmf), at most min(rows, texels);
  // --error / --energy then apply per matrix, to the uncentred energy (fmf_codec.h).
  int components = 16;
  // LPCA clusters k (lpca, lpca-tensor); clamped (with a warning) to the number of texels.
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
  std::uint64_t seed = 1;  // k-means++ seeding and randomized SVD (deterministic for a seed)
  bool log_transform = false;
  double log_epsilon = 1e-3;  // epsilon of the log transform, in data units (1/sr)
  CodecStorage storage = CodecStorage::kFloat;  // coefficient storage (--storage float|half)
  std::optional<SceneSpec> scene;  // keep only what a scene needs (scene.h)
  LpcaOptions lpca;
  LpcaTensorOptions tensor;
  NeuralOptions neural;

  // Throws btf::Error (usage) naming the first bad field.
  void Check() const;
  // The value transform these options ask for (neural: always the log).
  bool LogTransform() const { return log_transform || method == CodecMethod::kNeural; }
  ValueMap Transform() const { return LogTransform() ? ValueMap::Log(log_epsilon) : ValueMap{}; }
  // The options as stored in a codec's provenance (the scene separately): one flat object, the
  // nested options under their historical names (lpca_memory, quant_bits, tensor_growth, ...);
  // the neural_* keys only for the neural method.
  nlohmann::json ToJson() const;
};

}  // namespace btf
