#pragma once
// LPCA with factorised Eigen-ABRDFs (`btf-compress --method lpca-tensor`; docs/btf-compress.md,
// docs/format.md "Codec file"). The LPCA clustering of compress.cpp runs first; then each
// cluster's 1 + c_k functions (its mean and its Eigen-ABRDFs), each a views x (lights x channels)
// matrix, are stored as truncated SVDs: sums of rank-1 terms u (views) x w (lights x channels).
// Which terms are kept is one global rate-distortion choice over every cluster and function:
// term r of function f costs the same bytes everywhere, and dropping it adds alpha_f s_{f,r}^2 to
// the codec's squared error (alpha = the cluster's texel count for its mean, the sum of squared
// weights of component j for Eigen-ABRDF j: PCA weights are centred and uncorrelated and the LPCA
// residual is orthogonal to both, so in exact arithmetic the errors add), so the terms are kept
// by decreasing alpha s^2 until the error target or the byte budget is met. Factors and per-texel
// weights are quantised to 8 or 16 bits with a float32 scale and bias per vector.
#include <cstdint>
#include <vector>

namespace btf {

namespace h5 {
class File;
}
struct LpcaModel;
class Codec;

// Dequantised value of a stored code q: float(double(bias) + double(scale) * q) (docs/format.md).
inline float Dequantise(float scale, float bias, std::uint32_t q) {
  return static_cast<float>(double(bias) + double(scale) * double(q));
}

// One quantised vector: q_i in [0, 2^bits - 1]; bias = min, scale = (max - min) / (2^bits - 1),
// both rounded to float, codes chosen against the rounded pair. `out` gets the dequantised
// values; returns the codes. A constant vector gets scale 0.
std::vector<std::uint16_t> QuantiseVector(const float* x, std::size_t n, int bits, float* scale, float* bias,
                                          float* out);

struct LpcaTensorModel {
  int clusters = 0, components = 0;  // K and the weight stride c
  int bits = 16;                     // 8 or 16: codes of every quantised array
  int views = 0, lights = 0, channels = 0;
  std::vector<std::int32_t> cluster_components;  // K: c_k <= c
  std::vector<std::int32_t> cluster_of;          // H*W
  // Per texel weights, dequantised (H*W x c; zero beyond c_k), their codes and per (k, j) scale/bias.
  std::vector<float> weights;
  std::vector<std::uint16_t> weight_codes;
  std::vector<float> weight_scale, weight_bias;  // K x c
  // ranks[k * (1 + c) + f]: terms of function f of cluster k (f = 0 the mean, 1 + j Eigen-ABRDF j).
  std::vector<std::int32_t> ranks;
  // Terms in (k, f, r) order: view factors (R x V) and light factors (R x L*C), dequantised, with
  // their codes and per-term scale/bias.
  std::vector<float> u, w;
  std::vector<std::uint16_t> u_codes, w_codes;
  std::vector<float> u_scale, u_bias, w_scale, w_bias;  // R
  // First term of each function (K*(1+c) + 1 entries; derived from ranks by Index()).
  std::vector<std::uint32_t> first;

  int functions_per_cluster() const { return 1 + components; }
  std::size_t terms() const { return u_scale.size(); }
  std::size_t seg() const { return std::size_t(lights) * channels; }
  // Recomputes `first` from `ranks`.
  void Index();
  // Bytes as stored: codes at bits/8 bytes, scales/biases float32, ranks/cluster tables int32.
  std::uint64_t StoredBytes() const;
  // Bytes of one term (both factors and their scale/bias).
  std::uint64_t TermBytes() const;
  // Bytes without any term (cluster tables, ranks, weights and their scales).
  std::uint64_t FixedBytes(std::size_t texels) const;

  // Decoders in the transformed domain.
  // The view-v rows of every function: K x (1+c) x (L*C) floats into `out` (resized).
  void FunctionsAtView(int view, std::vector<float>& out) const;
  // Function f of cluster k at (view, light): C floats added, times `coef`, into acc (double).
  void AddFunction(int k, int f, int view, int light, double coef, double* acc) const;
  void Sample(int view, int light, std::size_t texel, float* out) const;  // C
  void DecodeAbrdf(std::size_t texel, float* out) const;                 // V x L x C
};

// Factorises a fitted LPCA model (means, orthonormal bases, weights) into `out`. total_energy is
// the transformed input's sum of squares and lpca_residual the LPCA fit's squared residual. Keep
// terms until the predicted relative error sqrt((lpca_residual + dropped) / total) <= target_error
// (target_error > 0), or while the codec fits max_bytes (max_bytes > 0); with neither, until the
// dropped energy is at most `growth` x lpca_residual. Returns the predicted relative error.
// Threads: one cluster per task, sums in cluster order (results independent of the thread count).
struct TensorRequest {
  int bits = 16;
  double target_error = 0;
  std::uint64_t max_bytes = 0;
  double growth = 0.1;
};
double FactoriseLpca(const LpcaModel& lpca, int views, int lights, int channels, double total_energy,
                     double lpca_residual, const TensorRequest& request, LpcaTensorModel& out);

// Codec-file items (/codec/lpca_tensor/..., docs/format.md). The reader refuses wrong shapes,
// out-of-range codes, ranks and indices, and non-finite scales (bad input, naming file and item).
void WriteLpcaTensorModel(const h5::File& file, const LpcaTensorModel& m, int height, int width);
LpcaTensorModel ReadLpcaTensorModel(const h5::File& file, int views, int lights, int height, int width, int channels);

// The plain LPCA model an lpca-tensor model factorises: each cluster's mean and Eigen-ABRDFs
// expanded from their terms (a views x lights x channels vector each), the same clusters and
// weights. It decodes to the same values up to float rounding (the terms summed per value).
LpcaModel ExpandToLpca(const LpcaTensorModel& m);
// An lpca-tensor codec as that LPCA codec (samplings, conventions and transform kept), so that
// what takes LPCA codecs (the renderer export, Schneider 2004) takes it too.
Codec ExpandToLpcaCodec(const Codec& tensor);

}  // namespace btf
