#include "libbtf/compress/neural_net.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <type_traits>

#include "libbtf/core/error.h"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

namespace btf {
namespace {

// SplitMix64 (Steele, Lea & Flood 2014): the seeded stream behind every random choice here, so
// that the same seed gives the same numbers with any standard library.
struct SplitMix64 {
  std::uint64_t state;
  std::uint64_t Next() {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double Uniform() { return double(Next() >> 11) * 0x1.0p-53; }  // [0, 1)
  std::uint64_t Below(std::uint64_t n) { return std::uint64_t((unsigned __int128)Next() * n >> 64); }
};

std::uint64_t Mix(std::uint64_t seed, std::uint64_t stream) {
  SplitMix64 r{seed ^ (stream * 0xD1B54A32D192ED03ull)};
  r.Next();
  return r.Next();
}

constexpr float kLeakySlope = 0.01f;

// d[i] *= (z[i] > 0 ? 1 : slope). Written so that GCC 12 vectorizes it (checked with
// -fopt-info-vec): a factor chosen between two constants into a temporary; the same select
// written inline, or a choice between two computed values, stays a scalar loop with a branch on
// the sign (with Eigen 3.4's select(), which is scalar too), 3x slower on random signs.
template <typename S>
void ScaleNonPositive(const S* __restrict z, S* __restrict d, Eigen::Index n, S slope) {
  for (Eigen::Index i = 0; i < n; ++i) {
    const S f = z[i] > S(0) ? S(1) : slope;
    d[i] = d[i] * f;
  }
}

// a = act(z), elementwise over n values: ReLU and leaky ReLU as vectorizable loops, softplus and
// SiLU through Eigen's vectorized exp. SiLU keeps sigmoid(z) in sig (n values) for the backward
// pass, which then needs no exp.
template <typename S>
void Activate(Activation act, const S* __restrict z, S* __restrict a, S* __restrict sig, Eigen::Index n) {
  using Array = Eigen::Array<S, Eigen::Dynamic, 1>;
  const Eigen::Map<const Array> zm(z, n);
  Eigen::Map<Array> am(a, n);
  switch (act) {
    case Activation::kRelu:
      for (Eigen::Index i = 0; i < n; ++i) a[i] = z[i] > S(0) ? z[i] : S(0);
      break;
    case Activation::kLeakyRelu:
      std::copy(z, z + n, a);
      ScaleNonPositive(z, a, n, S(kLeakySlope));
      break;
    // max(z, 0) + log1p(exp(-|z|)): no overflow for large |z|.
    case Activation::kSoftplus: am = zm.max(S(0)) + (-zm.abs()).exp().log1p(); break;
    // z sigmoid(z) with sigmoid = 1 / (1 + exp(-z)): exp overflows to inf for z < -88 (float),
    // giving sigmoid 0 and z * 0 = -0, the limit.
    // Without sig (inference: nothing to keep for a backward pass) the same expression, one pass.
    case Activation::kSilu: {
      if (sig == nullptr) {
        am = zm * (S(1) / (S(1) + (-zm).exp()));
        break;
      }
      Eigen::Map<Array> sm(sig, n);
      sm = S(1) / (S(1) + (-zm).exp());
      am = zm * sm;
      break;
    }
  }
}

// d *= act'(z), elementwise over n values (sig: what Activate kept).
template <typename S>
void ActivationBackward(Activation act, const S* __restrict z, const S* __restrict sig, S* __restrict d,
                        Eigen::Index n) {
  using Array = Eigen::Array<S, Eigen::Dynamic, 1>;
  const Eigen::Map<const Array> zm(z, n);
  Eigen::Map<Array> dm(d, n);
  switch (act) {
    case Activation::kRelu:
      for (Eigen::Index i = 0; i < n; ++i) d[i] = z[i] > S(0) ? d[i] : S(0);
      break;
    case Activation::kLeakyRelu: ScaleNonPositive(z, d, n, S(kLeakySlope)); break;
    case Activation::kSoftplus: dm = dm / (S(1) + (-zm).exp()); break;
    case Activation::kSilu: {
      // d/dz z s(z) = s (1 + z (1 - s)); s in [0, 1], finite for every z.
      const Eigen::Map<const Array> sm(sig, n);
      dm = dm * sm * (S(1) + zm * (S(1) - sm));
      break;
    }
  }
}

}  // namespace

std::string_view ActivationName(Activation a) {
  switch (a) {
    case Activation::kRelu: return "relu";
    case Activation::kLeakyRelu: return "leaky_relu";
    case Activation::kSoftplus: return "softplus";
    case Activation::kSilu: return "silu";
  }
  return "?";
}

void DirectionEncoding::Check() const {
  BTF_CHECK_OPTION(fourier >= 0 && fourier <= 8, "fourier", fmt::format("must be 0..8 (given {})", fourier));
}

void EncodeDirections(const DirectionEncoding& e, const float* wi, const float* wo, float* out) {
  out[0] = wi[0];
  out[1] = wi[1];
  out[2] = wo[0];
  out[3] = wo[1];
  int k = 4;
  if (e.half_vector) {
    const float h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
    const float norm2 = h[0] * h[0] + h[1] * h[1] + h[2] * h[2];
    const float s = norm2 > 1e-24f ? 1 / std::sqrt(norm2) : 0.f;  // wi = -wo: no half vector, (0, 0)
    out[k++] = h[0] * s;
    out[k++] = h[1] * s;
  }
  for (int f = 0; f < e.fourier; ++f)
    for (int b = 0; b < 4; ++b) {
      const double x = std::ldexp(std::numbers::pi, f) * out[b];
      out[k++] = float(std::sin(x));
      out[k++] = float(std::cos(x));
    }
}

void NeuralNetShape::Check() const {
  BTF_CHECK_OPTION(inputs >= 1 && inputs <= 4096, "inputs", fmt::format("must be 1..4096 (given {})", inputs));
  BTF_CHECK_OPTION(outputs >= 1 && outputs <= 4096, "outputs", fmt::format("must be 1..4096 (given {})", outputs));
  BTF_CHECK_OPTION(hidden.size() <= 16, "hidden", "at most 16 layers");
  for (const int h : hidden)
    BTF_CHECK_OPTION(h >= 1 && h <= 4096, "hidden", fmt::format("each width must be 1..4096 (given {})", h));
}

template <typename Scalar>
BasicNeuralNet<Scalar>::BasicNeuralNet(const NeuralNetShape& shape, std::uint64_t seed) : shape_(shape) {
  shape_.Check();
  Eigen::Index size = 0;
  for (int l = 0, in = shape_.inputs; l < layers(); ++l) {
    const int out = l + 1 < layers() ? shape_.hidden[l] : shape_.outputs;
    offsets_.push_back(size);
    size += Eigen::Index(out) * (in + 1);
    in = out;
  }
  params_.assign(size, Scalar(0));
  SplitMix64 rng{Mix(seed, 0x6e6574)};
  for (int l = 0; l < layers(); ++l) {
    const Eigen::Index in = weight(l).cols(), n = weight(l).size();
    const double bound = std::sqrt((l + 1 < layers() ? 6.0 : 3.0) / double(in));
    for (Eigen::Index i = 0; i < n; ++i) params_[offsets_[l] + i] = Scalar(bound * (2 * rng.Uniform() - 1));
  }
}

template <typename Scalar>
Eigen::Map<const typename BasicNeuralNet<Scalar>::Matrix> BasicNeuralNet<Scalar>::weight(int layer) const {
  const int in = layer == 0 ? shape_.inputs : shape_.hidden[layer - 1];
  const int out = layer + 1 < layers() ? shape_.hidden[layer] : shape_.outputs;
  return Eigen::Map<const Matrix>(params_.data() + offsets_[layer], out, in);
}

template <typename Scalar>
Eigen::Index BasicNeuralNet<Scalar>::bias_offset(int layer) const {
  const auto w = weight(layer);
  return offsets_[layer] + w.size();
}

template <typename Scalar>
Eigen::Map<const typename BasicNeuralNet<Scalar>::Vector> BasicNeuralNet<Scalar>::bias(int layer) const {
  return Eigen::Map<const Vector>(params_.data() + bias_offset(layer), weight(layer).rows());
}

template <typename Scalar>
const typename BasicNeuralNet<Scalar>::Matrix& BasicNeuralNet<Scalar>::Forward(const Eigen::Ref<const Matrix>& X,
                                                                               Workspace& ws) const {
  BTF_CHECK(X.rows() == shape_.inputs);
  ws.z.resize(layers());
  ws.z[0].noalias() = weight(0) * X;
  ws.z[0].colwise() += bias(0);
  const int L = layers();
  ws.a.resize(L);
  ws.sig.resize(L);
  for (int l = 0; l < L; ++l) {
    Matrix& z = ws.z[l];
    if (l > 0) {
      z.noalias() = weight(l) * ws.a[l - 1];
      z.colwise() += bias(l);
    }
    if (l + 1 < L) {
      ws.a[l].resize(z.rows(), z.cols());
      Scalar* sig = nullptr;
      if (shape_.activation == Activation::kSilu) {
        ws.sig[l].resize(z.rows(), z.cols());
        sig = ws.sig[l].data();
      }
      Activate(shape_.activation, z.data(), ws.a[l].data(), sig, z.size());
    }
  }
  return ws.z.back();
}

namespace {

#if defined(__AVX2__) && defined(__FMA__)
// SiLU for inference, a = z sigmoid(z) over n values (a multiple of 8), within ~4e-7 (relative)
// of Activate's: Eigen's exp and division are ~25 instructions and a divide per 8 values, half the
// decoder's time at the default widths. Here exp(-z) = 2^t, t = -z log2(e) clamped to [-126, 126]
// (2^n stays a normal float; sigmoid is 0 or 1 to float precision beyond), as 2^n 2^f with
// f = t - round(t) in [-1/2, 1/2] and 2^f a degree-5 polynomial (least squares in the relative
// error: 2.2e-7 in float arithmetic), 2^n added to the exponent bits; 1 / (1 + e) by the
// reciprocal estimate (3.7e-4) and one Newton step (~1e-7). NaN stays NaN.
void SiluInference(const float* __restrict z, float* __restrict a, Eigen::Index n) {
  const __m256 kMinusLog2e = _mm256_set1_ps(-1.44269504f), kLo = _mm256_set1_ps(-126.f), kHi = _mm256_set1_ps(126.f);
  const __m256 one = _mm256_set1_ps(1.f), two = _mm256_set1_ps(2.f);
  const float c[] = {1.0000001192092896f, 0.6931469440460205f, 0.24022121727466583f,
                     0.05550742521882057f, 0.009675469249486923f, 0.001326697994954884f};
  for (Eigen::Index i = 0; i < n; i += 8) {
    const __m256 x = _mm256_loadu_ps(z + i);
    const __m256 t = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(x, kMinusLog2e), kLo), kHi);
    const __m256 m = _mm256_round_ps(t, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    const __m256 f = _mm256_sub_ps(t, m);
    __m256 p = _mm256_set1_ps(c[5]);
    for (int k = 4; k >= 0; --k) p = _mm256_fmadd_ps(p, f, _mm256_set1_ps(c[k]));
    const __m256i scaled = _mm256_add_epi32(_mm256_castps_si256(p), _mm256_slli_epi32(_mm256_cvtps_epi32(m), 23));
    const __m256 d = _mm256_add_ps(_mm256_castsi256_ps(scaled), one);
    __m256 r = _mm256_rcp_ps(d);
    r = _mm256_mul_ps(r, _mm256_fnmadd_ps(d, r, two));
    _mm256_storeu_ps(a + i, _mm256_mul_ps(x, r));
  }
}
#endif

// The hidden layers' activation in Infer: SiLU through SiluInference where it is compiled (AVX2),
// else what Forward applies.
template <typename Scalar>
void ActivateInference(Activation act, const Scalar* z, Scalar* a, Eigen::Index n) {
#if defined(__AVX2__) && defined(__FMA__)
  if constexpr (std::is_same_v<Scalar, float>) {
    if (act == Activation::kSilu && n % 8 == 0) return SiluInference(z, a, n);
  }
#endif
  Activate(act, z, a, static_cast<Scalar*>(nullptr), n);
}

// One layer over a lane-major group of kGroup packets (kGroup * N samples): z(i, :) = b_i +
// sum_k W(i, k) a(k, :) for i < rows, k < W.cols(), with row r of a and z at r * kGroup * N.
// Four rows at a time: 4 x kGroup accumulators, each weight broadcast once per k and used for
// kGroup packets (AVX2: 8 accumulators, 2 loads and 4 broadcasts per 8 FMAs).
template <typename Scalar, int kGroup>
void LayerLanes(const Eigen::Map<const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>>& W, const Scalar* b,
                const Scalar* __restrict a, Scalar* __restrict z) {
  using namespace Eigen::internal;
  using Packet = typename packet_traits<Scalar>::type;
  constexpr int N = packet_traits<Scalar>::size, S = kGroup * N;
  const Eigen::Index rows = W.rows(), in = W.cols(), ldw = W.outerStride();
  const Scalar* w = W.data();
  Eigen::Index i = 0;
  for (; i + 4 <= rows; i += 4) {
    Packet acc[4][kGroup];
    for (int r = 0; r < 4; ++r)
      for (int g = 0; g < kGroup; ++g) acc[r][g] = pset1<Packet>(b[i + r]);
    for (Eigen::Index k = 0; k < in; ++k) {
      Packet x[kGroup];
      for (int g = 0; g < kGroup; ++g) x[g] = ploadu<Packet>(a + k * S + g * N);
      for (int r = 0; r < 4; ++r) {
        const Packet wk = pset1<Packet>(w[k * ldw + i + r]);
        for (int g = 0; g < kGroup; ++g) acc[r][g] = pmadd(wk, x[g], acc[r][g]);
      }
    }
    for (int r = 0; r < 4; ++r)
      for (int g = 0; g < kGroup; ++g) pstoreu(z + (i + r) * S + g * N, acc[r][g]);
  }
  for (; i < rows; ++i) {
    Packet acc[kGroup];
    for (int g = 0; g < kGroup; ++g) acc[g] = pset1<Packet>(b[i]);
    for (Eigen::Index k = 0; k < in; ++k) {
      const Packet wk = pset1<Packet>(w[k * ldw + i]);
      for (int g = 0; g < kGroup; ++g) acc[g] = pmadd(wk, ploadu<Packet>(a + k * S + g * N), acc[g]);
    }
    for (int g = 0; g < kGroup; ++g) pstoreu(z + i * S + g * N, acc[g]);
  }
}

}  // namespace

template <typename Scalar>
void BasicNeuralNet<Scalar>::Infer(const Scalar* p, Eigen::Index ld, const Scalar* shift, Eigen::Index count,
                                   Scalar* out, Workspace& ws) const {
  constexpr int kGroup = 2, S = kGroup * Eigen::internal::packet_traits<Scalar>::size;
  const int L = layers(), C = shape_.outputs, H0 = shape_.hidden[0];
  const int widest = std::max(C, *std::max_element(shape_.hidden.begin(), shape_.hidden.end()));
  // ws.z[0]: pre-activations, ws.a[0]: activations, each widest x S; ws.a[1]: a zero-padded copy
  // of the last, partial group's rows of p.
  ws.z.resize(1);
  ws.a.resize(2);
  ws.z[0].resize(widest, S);
  ws.a[0].resize(widest, S);
  Scalar* z = ws.z[0].data();
  Scalar* a = ws.a[0].data();
  for (Eigen::Index j0 = 0; j0 < count; j0 += S) {
    const Eigen::Index n = std::min<Eigen::Index>(S, count - j0);
    const Scalar* src = p + j0;
    Eigen::Index src_ld = ld;
    if (n < S) {
      ws.a[1].setZero(S, H0);
      for (int i = 0; i < H0; ++i) std::copy(p + i * ld + j0, p + i * ld + j0 + n, ws.a[1].data() + i * S);
      src = ws.a[1].data();
      src_ld = S;
    }
    for (int i = 0; i < H0; ++i)
      for (int j = 0; j < S; ++j) z[i * S + j] = src[i * src_ld + j] + shift[i];
    ActivateInference(shape_.activation, z, a, Eigen::Index(H0) * S);
    for (int l = 1; l < L; ++l) {
      LayerLanes<Scalar, kGroup>(weight(l), bias(l).data(), a, z);
      if (l + 1 < L) ActivateInference(shape_.activation, z, a, weight(l).rows() * S);
    }
    for (Eigen::Index j = 0; j < n; ++j)
      for (int c = 0; c < C; ++c) out[(j0 + j) * C + c] = z[c * S + j];
  }
}

template <typename Scalar>
void BasicNeuralNet<Scalar>::Backward(const Eigen::Ref<const Matrix>& X, const Eigen::Ref<const Matrix>& dY,
                                      Workspace& ws, Scalar* grad, Matrix* dX) const {
  const int L = layers();
  BTF_CHECK(int(ws.z.size()) == L && dY.rows() == shape_.outputs && dY.cols() == X.cols());
  ws.delta = dY;
  for (int l = L - 1; l >= 0; --l) {
    const auto W = weight(l);
    Eigen::Map<Matrix> gW(grad + offsets_[l], W.rows(), W.cols());
    if (l == 0)
      gW.noalias() += ws.delta * X.transpose();
    else
      gW.noalias() += ws.delta * ws.a[l - 1].transpose();
    // Bias gradient: the columns summed in column order (a fixed order, whatever the alignment).
    Eigen::Map<Vector> gb(grad + bias_offset(l), W.rows());
    for (Eigen::Index j = 0; j < ws.delta.cols(); ++j) gb += ws.delta.col(j);
    if (l > 0) {
      ws.next.noalias() = W.transpose() * ws.delta;
      ws.delta.swap(ws.next);
      ActivationBackward(shape_.activation, ws.z[l - 1].data(), ws.sig[l - 1].data(), ws.delta.data(),
                         ws.delta.size());
    } else if (dX) {
      dX->noalias() = W.transpose() * ws.delta;
    }
  }
}

template class BasicNeuralNet<float>;
template class BasicNeuralNet<double>;

void AdamOptions::Check() const {
  BTF_CHECK_OPTION(beta1 >= 0 && beta1 < 1, "beta1", fmt::format("must be in [0, 1) (given {})", beta1));
  BTF_CHECK_OPTION(beta2 >= 0 && beta2 < 1, "beta2", fmt::format("must be in [0, 1) (given {})", beta2));
  BTF_CHECK_OPTION(epsilon > 0 && std::isfinite(epsilon), "epsilon", fmt::format("must be > 0 (given {})", epsilon));
}

namespace {
// One Adam update of n values whose moments have seen t updates (this one included).
void AdamUpdate(const AdamOptions& o, std::int64_t t, double lr, float* p, const float* g, float* m, float* v,
                Eigen::Index n) {
  const float b1 = float(o.beta1), b2 = float(o.beta2);
  // lr sqrt(1 - beta2^t) / (1 - beta1^t) and epsilon sqrt(1 - beta2^t): Kingma & Ba's
  // "more efficient" order, the same update as with m_hat and v_hat.
  const double c2 = std::sqrt(1 - std::pow(o.beta2, double(t)));
  const float step = float(lr * c2 / (1 - std::pow(o.beta1, double(t))));
  const float eps = float(o.epsilon * c2);
  for (Eigen::Index i = 0; i < n; ++i) {
    m[i] = b1 * m[i] + (1 - b1) * g[i];
    v[i] = b2 * v[i] + (1 - b2) * g[i] * g[i];
    p[i] -= step * m[i] / (std::sqrt(v[i]) + eps);
  }
}
}  // namespace

Adam::Adam(Eigen::Index size, const AdamOptions& options) : o_(options), m_(size, 0.f), v_(size, 0.f) { o_.Check(); }

void Adam::Step(float* params, const float* grad, double learning_rate) {
  ++t_;
  AdamUpdate(o_, t_, learning_rate, params, grad, m_.data(), v_.data(), Eigen::Index(m_.size()));
}

LazyAdam::LazyAdam(Eigen::Index rows, int width, const AdamOptions& options)
    : o_(options), width_(width), m_(std::size_t(rows) * width, 0.f), v_(m_.size(), 0.f), t_(rows, 0) {
  o_.Check();
}

void LazyAdam::StepRow(Eigen::Index row, float* row_values, const float* grad, double learning_rate) {
  const std::size_t at = std::size_t(row) * width_;
  AdamUpdate(o_, ++t_[row], learning_rate, row_values, grad, m_.data() + at, v_.data() + at, width_);
}


void NeuralSamples::Check() const {
  const std::int64_t n = size();
  if (texels < 1 || texels > std::int64_t(INT32_MAX)) ThrowBadInput("neural samples: {} texels (need 1..2^31-1)", texels);
  if (channels < 1 || channels > 4096) ThrowBadInput("neural samples: {} channels (need 1..4096)", channels);
  if (n < 1) ThrowBadInput("neural samples: none");
  if (std::int64_t(wi.size()) != 3 * n || std::int64_t(wo.size()) != 3 * n ||
      std::int64_t(target.size()) != channels * n)
    ThrowBadInput("neural samples: {} texel indices but {} wi, {} wo and {} target values (need 3, 3 and {} per sample)",
                  n, wi.size(), wo.size(), target.size(), channels);
  for (std::int64_t i = 0; i < n; ++i) {
    if (texel[i] < 0 || texel[i] >= texels) ThrowBadInput("neural samples: sample {} has texel {} (of {})", i, texel[i], texels);
    for (const float* w : {&wi[3 * i], &wo[3 * i]}) {
      const double norm2 = double(w[0]) * w[0] + double(w[1]) * w[1] + double(w[2]) * w[2];
      // Unit vectors, to float rounding of measured data; also refuses NaN and Inf.
      if (!(std::abs(norm2 - 1) <= 1e-2))
        ThrowBadInput("neural samples: sample {} has a direction ({}, {}, {}) that is not a unit vector", i, w[0], w[1], w[2]);
    }
  }
  for (std::size_t k = 0; k < target.size(); ++k)
    if (!std::isfinite(target[k]))
      ThrowBadInput("neural samples: target value {} of sample {} is {}", k % channels, k / channels, target[k]);
}

void NeuralModel::Evaluate(const std::int32_t* texel, const float* wi, const float* wo, Eigen::Index n,
                           Eigen::MatrixXf* out) const {
  const int E = encoding.Width(), C = net.shape().outputs;
  BTF_CHECK(net.shape().inputs == latent + E && latents.rows() == latent);
  for (Eigen::Index i = 0; i < n; ++i)
    if (texel[i] < 0 || texel[i] >= latents.cols())
      ThrowBadInput("neural model: sample {} asks for texel {} (of {})", i, texel[i], latents.cols());
  out->resize(C, n);
  constexpr Eigen::Index kChunk = 1024;
  const Eigen::Index chunks = (n + kChunk - 1) / kChunk;
#pragma omp parallel
  {
    NeuralNet::Workspace ws;
    Eigen::MatrixXf X;
#pragma omp for schedule(dynamic, 1)
    for (Eigen::Index c = 0; c < chunks; ++c) {
      const Eigen::Index begin = c * kChunk, count = std::min(kChunk, n - begin);
      X.resize(latent + E, count);
      for (Eigen::Index j = 0; j < count; ++j) {
        const Eigen::Index i = begin + j;
        X.col(j).head(latent) = latents.col(texel[i]);
        EncodeDirections(encoding, wi + 3 * i, wo + 3 * i, X.col(j).data() + latent);
      }
      out->middleCols(begin, count) = net.Forward(X, ws);
    }
  }
}

void NeuralTrainOptions::Check() const {
  BTF_CHECK_OPTION(latent >= 0 && latent <= 256, "latent", fmt::format("must be 0..256 (given {})", latent));
  encoding.Check();  // before its Width() is used
  NeuralNetShape{latent + encoding.Width(), hidden, 1, activation}.Check();
  adam.Check();
  BTF_CHECK_OPTION(batch >= 1 && batch <= (1 << 24), "batch", fmt::format("must be 1..16777216 (given {})", batch));
  BTF_CHECK_OPTION(block >= 1 && block <= batch, "block", fmt::format("must be 1..batch (given {})", block));
  BTF_CHECK_OPTION(steps >= 0, "steps", fmt::format("must be >= 0 (given {})", steps));
  BTF_CHECK_OPTION(steps > 0 || (epochs > 0 && epochs <= 1e6), "epochs",
                   fmt::format("must be in (0, 1e6] when steps is 0 (given {})", epochs));
  BTF_CHECK_OPTION(learning_rate > 0 && learning_rate < 1e3, "learning_rate",
                   fmt::format("must be in (0, 1000) (given {})", learning_rate));
  BTF_CHECK_OPTION(latent_learning_rate >= 0 && latent_learning_rate < 1e3, "latent_learning_rate",
                   fmt::format("must be in [0, 1000) (given {})", latent_learning_rate));
  BTF_CHECK_OPTION(final_learning_rate > 0 && final_learning_rate <= 1, "final_learning_rate",
                   fmt::format("must be in (0, 1] (given {})", final_learning_rate));
  BTF_CHECK_OPTION(latent_init >= 0 && latent_init <= 10, "latent_init",
                   fmt::format("must be in [0, 10] (given {})", latent_init));
  BTF_CHECK_OPTION(linear_loss >= 0 && linear_loss <= 1, "linear_loss",
                   fmt::format("must be in [0, 1] (given {})", linear_loss));
}

void BlockGradient::Clear() {
  parameters.clear();
  texels.clear();
  latents.clear();
  squared_error = 0;
  values = 0;
}

StepGradient ReduceInOrder(std::span<const BlockGradient> blocks, int latent, std::vector<std::int32_t>& scratch) {
  StepGradient g;
  if (blocks.empty()) return g;
  const std::size_t P = blocks[0].parameters.size();
  std::vector<double> params(P, 0.0), lat;
  double sse = 0;
  std::int64_t values = 0;
  for (const BlockGradient& b : blocks) {
    BTF_CHECK(b.parameters.size() == P && b.latents.size() == b.texels.size() * std::size_t(latent));
    for (std::size_t k = 0; k < P; ++k) params[k] += b.parameters[k];
    sse += b.squared_error;
    values += b.values;
    for (std::size_t i = 0; i < b.texels.size(); ++i) {
      const std::int32_t t = b.texels[i];
      BTF_CHECK(t >= 0 && std::size_t(t) < scratch.size());
      if (scratch[t] < 0) {
        scratch[t] = std::int32_t(g.texels.size());
        g.texels.push_back(t);
        lat.resize(lat.size() + latent, 0.0);
      }
      double* acc = lat.data() + std::size_t(scratch[t]) * latent;
      for (int k = 0; k < latent; ++k) acc[k] += b.latents[i * latent + k];
    }
  }
  for (const std::int32_t t : g.texels) scratch[t] = -1;
  BTF_CHECK(values > 0);
  // The mean over the batch's values: its gradient is the sums' divided by their count.
  const double inv = 1.0 / double(values);
  g.values = values;
  g.loss = sse * inv;
  g.parameters.resize(P);
  for (std::size_t k = 0; k < P; ++k) g.parameters[k] = float(params[k] * inv);
  g.latents.resize(lat.size());
  for (std::size_t k = 0; k < lat.size(); ++k) g.latents[k] = float(lat[k] * inv);
  return g;
}

NeuralTrainer::NeuralTrainer(const NeuralSamples& samples, const NeuralTrainOptions& options)
    : samples_(samples), o_(options) {
  o_.Check();
  samples_.Check();
  const std::int64_t n = samples_.size();
  steps_ = o_.steps > 0 ? o_.steps : std::int64_t(std::ceil(o_.epochs * double(n) / o_.batch));
  steps_ = std::max<std::int64_t>(steps_, 1);
  model_.encoding = o_.encoding;
  model_.latent = o_.latent;
  model_.net = NeuralNet(NeuralNetShape{o_.latent + o_.encoding.Width(), o_.hidden, samples_.channels, o_.activation},
                         o_.seed);
  model_.latents.resize(o_.latent, samples_.texels);
  SplitMix64 rng{Mix(o_.seed, 0x6c6174)};
  for (Eigen::Index i = 0; i < model_.latents.size(); ++i)
    model_.latents.data()[i] = float(o_.latent_init * (2 * rng.Uniform() - 1));
  adam_ = Adam(model_.net.parameter_count(), o_.adam);
  latent_adam_ = LazyAdam(samples_.texels, o_.latent, o_.adam);
  slot_scratch_.assign(std::size_t(samples_.texels), -1);
  double square_sum = 0;
  max_target_ = -std::numeric_limits<float>::infinity();
  for (const float t : samples_.target) {
    square_sum += std::exp(2.0 * t);
    max_target_ = std::max(max_target_, t);
  }
  linear_scale_ = square_sum > 0 && std::isfinite(square_sum) ? double(samples_.target.size()) / square_sum : 0;
}

int NeuralTrainer::blocks_per_step() const { return (o_.batch + o_.block - 1) / o_.block; }

void NeuralTrainer::EnsurePermutation(std::int64_t epoch) const {
  if (epoch == perm_epoch_) return;
  const std::int64_t n = samples_.size();
  perm_.resize(n);
  for (std::int64_t i = 0; i < n; ++i) perm_[i] = i;
  SplitMix64 rng{Mix(o_.seed, 0x7065726d00000000ull + std::uint64_t(epoch))};
  for (std::int64_t i = n - 1; i > 0; --i) std::swap(perm_[i], perm_[rng.Below(std::uint64_t(i) + 1)]);
  perm_epoch_ = epoch;
}

void NeuralTrainer::StepSamples(std::int64_t s, std::vector<std::int64_t>* indices) const {
  const std::int64_t n = samples_.size();
  indices->resize(o_.batch);
  for (int j = 0; j < o_.batch; ++j) {
    const std::int64_t p = s * o_.batch + j;
    EnsurePermutation(p / n);
    (*indices)[j] = perm_[p % n];
  }
}

double NeuralTrainer::LearningRate(std::int64_t s, double initial) const {
  const double t = steps_ > 1 ? double(s) / double(steps_ - 1) : 1.0;
  const double low = initial * o_.final_learning_rate;
  return low + 0.5 * (initial - low) * (1 + std::cos(std::numbers::pi * std::min(t, 1.0)));
}

// Samples ahead whose data the gather loop asks the cache for.
constexpr int kFetchAhead = 16;

void NeuralTrainer::ComputeBlockGradients(int first, int count, std::vector<BlockGradient>* out) const {
  BTF_CHECK(first >= 0 && count >= 0 && first + count <= blocks_per_step());
  StepSamples(step_, &batch_);
  out->resize(count);
  const int L = o_.latent, E = o_.encoding.Width(), C = samples_.channels;
  const NeuralNet& net = model_.net;
  // OpenMP over blocks only: inside a parallel region Eigen runs its products on the calling
  // thread, and each block's arithmetic is the same whichever thread computes it, so the blocks
  // are handed out dynamically (a thread the OS holds back does not hold up the others).
#pragma omp parallel
  {
    NeuralNet::Workspace ws;
    Eigen::MatrixXf X, dY, dX;
#pragma omp for schedule(dynamic, 1)
    for (int k = 0; k < count; ++k) {
      const int begin = (first + k) * o_.block, nb = std::min(o_.block, o_.batch - begin);
      BlockGradient& g = (*out)[k];
      g.Clear();
      g.texels.resize(nb);
      X.resize(L + E, nb);
      for (int j = 0; j < nb; ++j) {
        // The batch visits samples (and their texels' latents) in random order: fetch ahead.
        if (j + kFetchAhead < nb) {
          const std::int64_t p = batch_[begin + j + kFetchAhead];
          __builtin_prefetch(&samples_.texel[p]);
          __builtin_prefetch(&samples_.wi[3 * p]);
          __builtin_prefetch(&samples_.wo[3 * p]);
          __builtin_prefetch(&samples_.target[std::size_t(p) * C]);
        }
        if (j + kFetchAhead / 2 < nb)
          __builtin_prefetch(model_.latents.col(samples_.texel[batch_[begin + j + kFetchAhead / 2]]).data());
        const std::int64_t i = batch_[begin + j];
        g.texels[j] = samples_.texel[i];
        X.col(j).head(L) = model_.latents.col(g.texels[j]);
        EncodeDirections(o_.encoding, &samples_.wi[3 * i], &samples_.wo[3 * i], X.col(j).data() + L);
      }
      const Eigen::MatrixXf& Y = net.Forward(X, ws);
      dY.resize(C, nb);
      double sse = 0;
      const float w_log = float(1 - o_.linear_loss), w_lin = float(o_.linear_loss * linear_scale_);
      for (int j = 0; j < nb; ++j) {
        const float* t = &samples_.target[std::size_t(batch_[begin + j]) * C];
        for (int c = 0; c < C; ++c) {
          const float r = Y(c, j) - t[c];
          float loss = w_log * r * r, d = 2 * w_log * r;  // d(r^2)/dy
          if (w_lin > 0) {
            const float ey = std::exp(std::min(Y(c, j), max_target_ + 1)), rl = ey - std::exp(t[c]);
            loss += w_lin * rl * rl;
            d += 2 * w_lin * rl * ey;  // d((e^y - e^t)^2)/dy
          }
          sse += loss;
          dY(c, j) = d;
        }
      }
      g.squared_error = sse;
      g.values = std::int64_t(nb) * C;
      g.parameters.assign(std::size_t(net.parameter_count()), 0.f);
      net.Backward(X, dY, ws, g.parameters.data(), &dX);
      g.latents.resize(std::size_t(nb) * L);
      for (int j = 0; j < nb; ++j)
        for (int l = 0; l < L; ++l) g.latents[std::size_t(j) * L + l] = dX(l, j);
    }
  }
}

double NeuralTrainer::ApplyStep(std::span<const BlockGradient> blocks) {
  BTF_CHECK(int(blocks.size()) == blocks_per_step() && step_ < steps_);
  const StepGradient g = ReduceInOrder(blocks, o_.latent, slot_scratch_);
  bool finite = std::isfinite(g.loss);
  for (const float v : g.parameters) finite = finite && std::isfinite(v);
  for (const float v : g.latents) finite = finite && std::isfinite(v);
  if (!finite)
    ThrowBadInput("neural training diverged at step {} (loss {}): lower the learning rates ({}, latents {})", step_,
                  g.loss, o_.learning_rate, o_.latent_learning_rate);
  adam_.Step(model_.net.parameters().data(), g.parameters.data(), LearningRate(step_, o_.learning_rate));
  const double lr = LearningRate(step_, o_.latent_learning_rate);
  for (std::size_t i = 0; i < g.texels.size(); ++i)
    latent_adam_.StepRow(g.texels[i], model_.latents.col(g.texels[i]).data(), &g.latents[i * o_.latent], lr);
  ++step_;
  return g.loss;
}

double NeuralTrainer::Step() {
  std::vector<BlockGradient> blocks;
  ComputeBlockGradients(0, blocks_per_step(), &blocks);
  return ApplyStep(blocks);
}

NeuralModel TrainNeural(const NeuralSamples& samples, const NeuralTrainOptions& options, const NeuralProgress& progress,
                        NeuralTrainSummary* summary) {
  NeuralTrainer trainer(samples, options);
  NeuralTrainSummary s;
  s.steps = trainer.steps();
  std::vector<BlockGradient> blocks;
  for (std::int64_t k = 0; k < trainer.steps(); ++k) {
    trainer.ComputeBlockGradients(0, trainer.blocks_per_step(), &blocks);
    const double loss = trainer.ApplyStep(blocks);
    if (k == 0) s.first_loss = loss;
    s.last_loss = loss;
    if (progress && !progress(k + 1, trainer.steps(), loss)) throw Cancelled();
  }
  if (summary) *summary = s;
  return std::move(trainer.model());
}

}  // namespace btf
