#pragma once
// The numerical core of a neural BTF codec: per texel a latent vector, one small decoder MLP
// shared by all texels, (latent, encoded wi, wo) -> C values in the log domain (y = log(x + eps),
// the caller's transform), trained jointly (latents and weights) with Adam on samples
// (texel, light, view) drawn from a dataset (NeuMIP, Kuznetsov et al. 2021; Rainer et al. 2019).
//
// Batches are column-major (one sample a column), so that each layer is one GEMM
// W (out x in) * X (in x batch). Training splits every minibatch into blocks of a fixed size whose
// gradients are computed independently (OpenMP over blocks, Eigen single-threaded inside each)
// and summed in block order: the result depends on the seed alone, not on the thread count, and
// a caller may compute some of a step's blocks elsewhere and hand all of them, in order, to
// ApplyStep. With MPI: every rank holds the samples (or the ones its blocks draw) and the whole
// model, computes its share of the blocks (NeuralTrainer::ComputeBlockGradients), gathers every
// rank's blocks and applies the step with all of them, so the replicas stay bit-identical.
#include <cstdint>
#include <functional>
#include <span>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace btf {

// Hidden-layer activation. SiLU (z sigmoid(z)) is the default: on the synthetic lobes of
// bench/neural_bench.cpp (BM_NeuralFit, one thread, 3000 steps of 1024) it left the lowest
// held-out error with every direction encoding, for about the time a step of ReLU takes (the
// step is GEMM-bound; SiLU's exp adds ~10-25 %), so it is also ahead per training second: SiLU
// with the half vector after 3000 steps is below ReLU after 6000.
enum class Activation { kRelu, kLeakyRelu, kSoftplus, kSilu };
std::string_view ActivationName(Activation a);

// How (wi, wo), unit vectors in the texel's tangent frame (z = normal), become network inputs:
// always wi.x, wi.y, wo.x, wo.y (4 values); optionally the half vector's x, y (normalize(wi + wo),
// 2 values; (0, 0) where wi + wo vanishes) and Fourier features sin(2^k pi v), cos(2^k pi v) of the
// 4 base values for k < fourier (8 values per k).
// Default: with the half vector, no Fourier features. On the synthetic lobes (BM_NeuralFit) the
// half vector lowered the held-out error 2-3x at a few % more time per step (those lobes are
// functions of the half vector, as microfacet specular lobes are; to be confirmed on measured
// BTFs); 2 Fourier octaves helped less and cost ~50 % more per step, so more steps paid better.
struct DirectionEncoding {
  bool half_vector = true;
  int fourier = 0;  // 0..8
  int Width() const { return 4 + (half_vector ? 2 : 0) + 8 * fourier; }
  void Check() const;  // throws btf::Error (usage) naming the field
};
// Writes encoding.Width() floats for one pair; finite for every finite input.
void EncodeDirections(const DirectionEncoding& encoding, const float* wi, const float* wo, float* out);

struct NeuralNetShape {
  int inputs = 12;                   // latent + direction encoding width
  std::vector<int> hidden{32, 32};   // hidden layer widths, each followed by the activation
  int outputs = 3;                   // channels (linear output layer)
  Activation activation = Activation::kSilu;
  void Check() const;  // throws btf::Error (usage) naming the field
};

// A multilayer perceptron with its parameters in one flat array: layer by layer, the weights
// W_l (out x in, column-major) then the biases b_l (out). Scalar float for training and decoding;
// double for the gradient tests.
template <typename Scalar>
class BasicNeuralNet {
 public:
  using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

  // What Forward keeps for Backward (pre-activations and activations per layer). One per thread.
  struct Workspace {
    std::vector<Matrix> z, a;  // per layer: z_l = W_l a_{l-1} + b_l, a_l = act(z_l) (last: a = z)
    std::vector<Matrix> sig;   // SiLU: sigmoid(z_l) per hidden layer, for the backward pass
    Matrix delta, next;        // backward scratch
  };

  BasicNeuralNet() = default;
  // Kaiming-uniform weights (bound sqrt(6 / fan_in); the linear output layer sqrt(3 / fan_in)),
  // zero biases, from the seed alone.
  BasicNeuralNet(const NeuralNetShape& shape, std::uint64_t seed);

  const NeuralNetShape& shape() const { return shape_; }
  int layers() const { return int(shape_.hidden.size()) + 1; }
  Eigen::Index parameter_count() const { return Eigen::Index(params_.size()); }
  std::vector<Scalar>& parameters() { return params_; }
  const std::vector<Scalar>& parameters() const { return params_; }
  Eigen::Map<const Matrix> weight(int layer) const;
  Eigen::Map<const Vector> bias(int layer) const;
  // Offset of W_l and of b_l in parameters().
  Eigen::Index weight_offset(int layer) const { return offsets_[layer]; }
  Eigen::Index bias_offset(int layer) const;

  // X: inputs x batch. Returns the outputs x batch result (held in ws).
  const Matrix& Forward(const Eigen::Ref<const Matrix>& X, Workspace& ws) const;
  // Inference from layer 0's pre-activation, for a caller that computes the first layer in parts
  // (decoding many direction pairs for the same latents computes W_0's latent columns once per
  // texel): sample j < count has z0(i, j) = p[i * ld + j] + shift[i] (i < the first layer's
  // width); its outputs go to out[j * outputs + c]. Samples go through all layers in groups of a
  // few SIMD packets, lane-major (row i of a group contiguous), each product accumulated in
  // registers with the weights broadcast: no packing of small matrices as a general GEMM does, and
  // the group's activations stay in the L1 cache. Sums run over k in order and the activations
  // are Forward's, but SiLU where AVX2 is compiled: a faster exp and reciprocal, within ~4e-7
  // relative. So values agree with Forward's to rounding. ws: scratch, one per thread (holds
  // nothing for Backward afterwards).
  void Infer(const Scalar* p, Eigen::Index ld, const Scalar* shift, Eigen::Index count, Scalar* out,
             Workspace& ws) const;
  // After Forward(X, ws): dY (outputs x batch) is d(loss)/d(output). Adds d(loss)/d(parameters)
  // to grad (parameter_count() values); writes d(loss)/dX (inputs x batch) to dX unless null.
  void Backward(const Eigen::Ref<const Matrix>& X, const Eigen::Ref<const Matrix>& dY, Workspace& ws, Scalar* grad,
                Matrix* dX) const;

 private:
  NeuralNetShape shape_;
  std::vector<Scalar> params_;
  std::vector<Eigen::Index> offsets_;  // per layer, start of W_l
};
using NeuralNet = BasicNeuralNet<float>;

struct AdamOptions {
  double beta1 = 0.9, beta2 = 0.999;
  double epsilon = 1e-8;  // added to sqrt(v_hat)
  void Check() const;
};

// Adam (Kingma & Ba 2015) with bias correction, float moments. Dense: every value each step.
class Adam {
 public:
  Adam() = default;
  Adam(Eigen::Index size, const AdamOptions& options);
  // params -= lr * m_hat / (sqrt(v_hat) + epsilon) after folding in grad (size values).
  void Step(float* params, const float* grad, double learning_rate);
  std::int64_t steps() const { return t_; }

 private:
  AdamOptions o_;
  std::vector<float> m_, v_;
  std::int64_t t_ = 0;
};

// Adam over the rows of a table (one row per texel) of which each step touches a few: lazy, a
// row's moments change only on the steps whose batch contains the row, and its bias correction
// uses its own count of updates. Decaying every row's moments each step would cost the whole table
// per step (65536 texels x 8 values against a batch of 4096 samples) and would keep moving rows
// that got no gradient on the strength of stale momentum; with per-row counts a row's first
// update is a full-size Adam step however late in training it comes.
class LazyAdam {
 public:
  LazyAdam() = default;
  LazyAdam(Eigen::Index rows, int width, const AdamOptions& options);
  // row_values: the row's width values; grad: its gradient (width values).
  void StepRow(Eigen::Index row, float* row_values, const float* grad, double learning_rate);
  std::int32_t updates(Eigen::Index row) const { return t_[row]; }

 private:
  AdamOptions o_;
  int width_ = 0;
  std::vector<float> m_, v_;
  std::vector<std::int32_t> t_;
};

// Training samples, struct of arrays; targets already in the log domain.
struct NeuralSamples {
  std::int64_t texels = 0;         // texel indices are in [0, texels)
  int channels = 3;                // C
  std::vector<std::int32_t> texel; // n
  std::vector<float> wi, wo;       // 3n each: x, y, z per sample (tangent frame, unit length)
  std::vector<float> target;       // C n: the C values of sample i at [C i, C i + C)
  std::int64_t size() const { return std::int64_t(texel.size()); }
  // Throws btf::Error (bad input) for inconsistent sizes, a texel out of range, a non-finite
  // direction or target.
  void Check() const;
};

// A trained codec's numbers: the latent table and the decoder.
struct NeuralModel {
  DirectionEncoding encoding;
  int latent = 8;
  Eigen::MatrixXf latents;  // latent x texels: texel t's latent is column t
  NeuralNet net;
  // out (channels x n, column-major): the decoder's values for n (texel, wi, wo), log domain.
  // Throws btf::Error (bad input) for a texel out of range; directions as in NeuralSamples.
  void Evaluate(const std::int32_t* texel, const float* wi, const float* wo, Eigen::Index n,
                Eigen::MatrixXf* out) const;
};

struct NeuralTrainOptions {
  int latent = 8;                    // latent values per texel
  std::vector<int> hidden{32, 32};   // decoder hidden widths
  Activation activation = Activation::kSilu;
  DirectionEncoding encoding;
  int batch = 4096;                  // samples per step
  int block = 256;                   // samples per gradient block (fixes the summation tree)
  std::int64_t steps = 0;            // > 0: this many steps; 0: ceil(epochs * n / batch)
  double epochs = 20;
  double learning_rate = 1e-2;       // decoder weights, at step 0
  double latent_learning_rate = 1e-2;
  // Cosine decay from the rates above to this fraction of them at the last step.
  double final_learning_rate = 0.05;
  double latent_init = 0.1;          // latents start uniform in [-latent_init, latent_init]
  // The loss per value: (1 - w) r^2 + w (e^y - e^t)^2 / mean(e^2t), with r = y - t the residual in
  // the log domain (y the decoder's value, t the target) and w = linear_loss. The second term is
  // the squared error in the linear domain (e^y = x + eps) relative to the samples' mean square,
  // which is what relative L2 errors measure; the first keeps dark values in shape.
  double linear_loss = 0;
  AdamOptions adam;
  std::uint64_t seed = 1;
  void Check() const;  // throws btf::Error (usage) naming the field
};

// One block's contribution to a step: the gradient of the block's sum of losses (not yet
// divided by the batch's value count) with respect to the decoder parameters and to each sample's
// latent.
struct BlockGradient {
  std::vector<float> parameters;     // parameter_count()
  std::vector<std::int32_t> texels;  // per sample of the block
  std::vector<float> latents;        // latent values per sample, in sample order
  double squared_error = 0;          // sum of the losses over the block's samples and channels
  std::int64_t values = 0;           // samples x channels
  void Clear();
};

// A step's gradient, summed over its blocks in block order and scaled to the mean squared error.
struct StepGradient {
  std::vector<float> parameters;
  std::vector<std::int32_t> texels;  // distinct texels, in the order of first appearance
  std::vector<float> latents;        // latent values per entry of texels
  double loss = 0;                   // mean loss over the batch's samples and channels
  std::int64_t values = 0;           // samples x channels
};
// blocks: all of a step's blocks, in block order; latent: values per texel; scratch: texels
// entries (the slot of each texel, -1 where none; left all -1 again).
StepGradient ReduceInOrder(std::span<const BlockGradient> blocks, int latent, std::vector<std::int32_t>& scratch);

class NeuralTrainer {
 public:
  // Checks the samples and options; initialises the latents and the decoder from the seed.
  // Keeps a reference to samples.
  NeuralTrainer(const NeuralSamples& samples, const NeuralTrainOptions& options);

  std::int64_t steps() const { return steps_; }
  std::int64_t step() const { return step_; }  // the next step to apply
  int blocks_per_step() const;
  // Sample indices of step s's minibatch (batch of them), from the seed alone: the sample stream
  // is a seeded permutation of all samples per epoch, the epochs concatenated.
  void StepSamples(std::int64_t s, std::vector<std::int64_t>* indices) const;
  // Gradients of blocks [first, first + count) of the next step, with the current parameters
  // (OpenMP over blocks). out is resized to count.
  void ComputeBlockGradients(int first, int count, std::vector<BlockGradient>* out) const;
  // Reduces all of the next step's blocks in order and applies Adam; returns the step's loss.
  double ApplyStep(std::span<const BlockGradient> blocks);
  // ComputeBlockGradients over all blocks, then ApplyStep.
  double Step();
  double LearningRate(std::int64_t s, double initial) const;

  const NeuralModel& model() const { return model_; }
  NeuralModel& model() { return model_; }

 private:
  void EnsurePermutation(std::int64_t epoch) const;

  const NeuralSamples& samples_;
  NeuralTrainOptions o_;
  NeuralModel model_;
  Adam adam_;
  LazyAdam latent_adam_;
  std::int64_t steps_ = 0, step_ = 0;
  std::vector<std::int32_t> slot_scratch_;
  double linear_scale_ = 0;  // 1 / mean(e^2t) over all target values
  float max_target_ = 0;     // the largest target: e^y is taken at min(y, max_target_ + 1)
  mutable std::int64_t perm_epoch_ = -1;
  mutable std::vector<std::int64_t> perm_;
  mutable std::vector<std::int64_t> batch_;
};

// Progress: return false to cancel (TrainNeural then throws btf::Cancelled). Called after every
// step with the step's loss (mean squared error in the log domain).
using NeuralProgress = std::function<bool(std::int64_t step, std::int64_t total, double loss)>;

struct NeuralTrainSummary {
  std::int64_t steps = 0;
  double first_loss = 0, last_loss = 0;
};

NeuralModel TrainNeural(const NeuralSamples& samples, const NeuralTrainOptions& options,
                        const NeuralProgress& progress = {}, NeuralTrainSummary* summary = nullptr);

}  // namespace btf
