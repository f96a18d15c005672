#pragma once
// The neural codec as stored (`btf-compress --method neural`; docs/format.md "Codec file",
// "Neural"): per texel a latent vector of `latent` values, quantised (8-bit codes with a float32
// scale and bias per latent channel, or IEEE half), and one decoder MLP shared by all texels
// (neural_net.h, weights float32): (latent, encoded wi, wo) -> C values in the codec's transformed
// domain. It decodes at any direction pair, not only the sampled ones. The decoders evaluate the
// MLP in batches of kNeuralChunk columns (one GEMM per layer, a thread per batch), the same
// batches for any thread count.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "libbtf/compress/neural_net.h"

namespace btf {

namespace h5 {
class File;
}

// How the latents are stored: 8-bit codes (scale and bias per latent channel) or IEEE binary16.
enum class LatentStorage { kUint8, kHalf };
// "uint8" / "half".
std::string LatentStorageName(LatentStorage s);
// Throws btf::Error (usage) for other names.
LatentStorage ParseLatentStorage(const std::string& name);

inline constexpr Eigen::Index kNeuralChunk = 1024;

struct NeuralCodecModel {
  DirectionEncoding encoding;
  int latent = 0;                     // values per texel
  LatentStorage storage = LatentStorage::kUint8;
  std::vector<std::uint16_t> codes;   // uint8: texels x latent codes (texel-major, [H, W, latent])
  std::vector<float> scale, bias;     // uint8: per latent channel, value = Dequantise(scale, bias, code)
  Eigen::MatrixXf latents;            // latent x texels: the stored latents as float (what decodes)
  NeuralNet net;                      // inputs latent + encoding.Width(), outputs C

  // The stored form of a trained model: its latents quantised (latents then holds the stored
  // values), its decoder as is.
  static NeuralCodecModel FromTrained(const NeuralModel& trained, LatentStorage storage);

  std::int64_t texels() const { return latents.cols(); }
  int channels() const { return net.shape().outputs; }
  // Latent codes or halves, scales and biases, decoder parameters at 4 bytes.
  std::uint64_t StoredBytes() const;

  // Transformed values (C x n, column-major) for n inputs: latent column i = z(i) (latent values),
  // directions wi(i), wo(i) (unit, tangent frame; 3 floats each).
  template <typename Latent, typename Wi, typename Wo>
  void Evaluate(Eigen::Index n, const Latent& z, const Wi& wi, const Wo& wo, float* out) const;

  // Every texel at n direction pairs (3 n floats each): out n x T x C, transformed domain. The first
  // layer's latent part is computed once per texel, not per pair (Evaluate's values to rounding).
  void DecodeImages(Eigen::Index n, const float* wi, const float* wo, float* out) const;
};

template <typename Latent, typename Wi, typename Wo>
void NeuralCodecModel::Evaluate(Eigen::Index n, const Latent& z, const Wi& wi, const Wo& wo, float* out) const {
  const int E = encoding.Width(), C = channels();
  const Eigen::Index chunks = (n + kNeuralChunk - 1) / kNeuralChunk;
  // Always inside a parallel region when there is a GEMM (n > 1): Eigen then runs each product
  // on its thread alone, instead of opening a region of its own per product.
#pragma omp parallel if (n > 1)
  {
    NeuralNet::Workspace ws;
    Eigen::MatrixXf X;
#pragma omp for schedule(static)
    for (Eigen::Index c = 0; c < chunks; ++c) {
      const Eigen::Index begin = c * kNeuralChunk, count = std::min(kNeuralChunk, n - begin);
      X.resize(latent + E, count);
      for (Eigen::Index j = 0; j < count; ++j) {
        const float* zj = z(begin + j);
        std::copy(zj, zj + latent, X.col(j).data());
        EncodeDirections(encoding, wi(begin + j), wo(begin + j), X.col(j).data() + latent);
      }
      Eigen::Map<Eigen::MatrixXf>(out + begin * C, C, count) = net.Forward(X, ws);
    }
  }
}

// Codec-file items under /codec/neural (docs/format.md).
void WriteNeuralModel(const h5::File& file, const NeuralCodecModel& m, int height, int width);
// Refuses (bad input, naming the file and the item) wrong shapes, out-of-range sizes, non-finite
// weights, scales or biases.
NeuralCodecModel ReadNeuralModel(const h5::File& file, int height, int width, int channels);

}  // namespace btf
