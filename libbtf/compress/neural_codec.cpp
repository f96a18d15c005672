#include "libbtf/compress/neural_codec.h"

#include <cmath>

#include "libbtf/compress/codec_items.h"
#include "libbtf/compress/lpca_tensor.h"
#include "libbtf/core/dataset.h"
#include "libbtf/core/error.h"
#include "libbtf/io/half.h"
#include "libbtf/io/hdf5.h"

namespace btf {

std::string LatentStorageName(LatentStorage s) { return s == LatentStorage::kHalf ? "half" : "uint8"; }

LatentStorage ParseLatentStorage(const std::string& name) {
  if (name == "uint8") return LatentStorage::kUint8;
  if (name == "half") return LatentStorage::kHalf;
  ThrowUsage("unknown latent storage '{}' (use uint8 or half)", name);
}

NeuralCodecModel NeuralCodecModel::FromTrained(const NeuralModel& trained, LatentStorage storage) {
  NeuralCodecModel m;
  m.encoding = trained.encoding;
  m.latent = trained.latent;
  m.storage = storage;
  m.net = trained.net;
  m.latents = trained.latents;
  const Eigen::Index T = m.latents.cols();
  if (storage == LatentStorage::kHalf) {
    RoundToHalves(m.latents.data(), std::size_t(m.latents.size()));
    return m;
  }
  m.codes.assign(std::size_t(T) * m.latent, 0);
  m.scale.assign(std::size_t(m.latent), 0.f);
  m.bias.assign(std::size_t(m.latent), 0.f);
  std::vector<float> row(static_cast<std::size_t>(T)), deq(static_cast<std::size_t>(T));
  for (int j = 0; j < m.latent; ++j) {
    for (Eigen::Index t = 0; t < T; ++t) row[std::size_t(t)] = m.latents(j, t);
    const auto q = QuantiseVector(row.data(), row.size(), 8, &m.scale[std::size_t(j)], &m.bias[std::size_t(j)],
                                  deq.data());
    for (Eigen::Index t = 0; t < T; ++t) {
      m.codes[std::size_t(t) * m.latent + j] = q[std::size_t(t)];
      m.latents(j, t) = deq[std::size_t(t)];
    }
  }
  return m;
}

std::uint64_t NeuralCodecModel::StoredBytes() const {
  const std::uint64_t values = std::uint64_t(latents.size());
  const std::uint64_t latent_bytes =
      storage == LatentStorage::kHalf ? 2 * values : values + 8 * std::uint64_t(latent);
  return latent_bytes + 4 * std::uint64_t(net.parameter_count());
}

void NeuralCodecModel::DecodeImages(Eigen::Index n, const float* wi, const float* wo, float* out) const {
  const Eigen::Index T = texels();
  const int E = encoding.Width(), C = channels();
  const auto W0 = net.weight(0);
  // Columns per work item: 256 keeps a hidden layer's activations (H x 256 floats, 32 KB at H = 32)
  // in the L1/L2 caches between the layers' products.
  constexpr Eigen::Index kChunk = 256;
  const Eigen::Index H = W0.rows(), per_pair = (T + kChunk - 1) / kChunk;
  // Layer 0 is W_0 [z; e] + b_0 = W_z z + (W_e e + b_0): the latent part once per texel (P), the
  // direction part once per pair. Both loops hand out the same chunks for any thread count, and
  // Eigen runs each product on its thread alone inside the parallel region.
  // P row-major: a chunk's rows are contiguous runs of texels, the lane-major layout Infer takes.
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> P(H, T);
#pragma omp parallel
  {
#pragma omp for schedule(static)
    for (Eigen::Index c = 0; c < per_pair; ++c) {
      const Eigen::Index begin = c * kChunk, count = std::min(kChunk, T - begin);
      P.middleCols(begin, count).noalias() = W0.leftCols(latent) * latents.middleCols(begin, count);
    }
    NeuralNet::Workspace ws;
    Eigen::VectorXf e(E), d(H);
#pragma omp for schedule(static)
    for (Eigen::Index k = 0; k < n * per_pair; ++k) {
      const Eigen::Index pair = k / per_pair, begin = (k % per_pair) * kChunk, count = std::min(kChunk, T - begin);
      EncodeDirections(encoding, wi + 3 * pair, wo + 3 * pair, e.data());
      d.noalias() = W0.rightCols(E) * e;
      d += net.bias(0);
      net.Infer(P.data() + begin, T, d.data(), count, out + (pair * T + begin) * C, ws);
    }
  }
}

// ---- Codec-file items ----

namespace {

constexpr const char* kGroup = "/codec/neural";

std::string Item(const std::string& name) { return fmt::format("{}/{}", kGroup, name); }
std::string WeightName(int l) { return fmt::format("weight_{}", l); }
std::string BiasName(int l) { return fmt::format("bias_{}", l); }

using codec_items::CheckDims;
using codec_items::Floats;
using codec_items::Shape;

std::int64_t Attr(const h5::File& f, const char* name, std::int64_t lo, std::int64_t hi) {
  const std::int64_t v = f.GetInt(kGroup, name);
  if (v < lo || v > hi) ThrowBadInput("'{}': '{}@{}' = {} is outside [{}, {}]", f.path(), kGroup, name, v, lo, hi);
  return v;
}

Activation ReadActivation(const h5::File& f) {
  const std::string a = f.GetString(kGroup, "activation");
  for (Activation x : {Activation::kRelu, Activation::kLeakyRelu, Activation::kSoftplus, Activation::kSilu})
    if (a == ActivationName(x)) return x;
  ThrowBadInput("'{}': '{}@activation' = '{}' (relu, leaky_relu, softplus or silu)", f.path(), kGroup, a);
}

// The decoder: layer l's weight [out, in] (row-major) and bias [out]; widths chained from
// `inputs` to `outputs`.
NeuralNet ReadNet(const h5::File& f, int layers, int inputs, int outputs, Activation activation) {
  NeuralNetShape shape;
  shape.inputs = inputs, shape.outputs = outputs, shape.activation = activation;
  shape.hidden.clear();
  for (int l = 0; l + 1 < layers; ++l) {
    const std::string name = Item(WeightName(l));
    if (!f.Exists(name)) ThrowBadInput("'{}': required item '{}' is missing", f.path(), name);
    const auto dims = f.Dims(name);
    if (dims.size() != 2 || dims[0] < 1 || dims[0] > 4096)
      ThrowBadInput("'{}': '{}' has shape {}, expected [hidden width 1..4096, inputs]", f.path(), name, Shape(dims));
    shape.hidden.push_back(int(dims[0]));
  }
  double params = 0;
  for (int l = 0, in = inputs; l < layers; ++l) {
    const int out = l + 1 < layers ? shape.hidden[std::size_t(l)] : outputs;
    params += double(out) * (in + 1);
    in = out;
  }
  CheckAllocation(4.0 * params, fmt::format("'{}' neural decoder", f.path()));
  NeuralNet net(shape, 0);
  auto& p = net.parameters();
  for (int l = 0, in = inputs; l < layers; ++l) {
    const int out = l + 1 < layers ? shape.hidden[std::size_t(l)] : outputs;
    const auto w = Floats(f, Item(WeightName(l)), {hsize_t(out), hsize_t(in)});
    const auto b = Floats(f, Item(BiasName(l)), {hsize_t(out)});
    for (int o = 0; o < out; ++o)
      for (int i = 0; i < in; ++i) p[std::size_t(net.weight_offset(l) + Eigen::Index(i) * out + o)] = w[std::size_t(o) * in + i];
    std::copy(b.begin(), b.end(), p.begin() + net.bias_offset(l));
    in = out;
  }
  return net;
}

}  // namespace

void WriteNeuralModel(const h5::File& f, const NeuralCodecModel& m, int H, int W) {
  f.CreateGroup(kGroup);
  f.SetAttr(kGroup, "latent", std::int64_t(m.latent));
  f.SetAttr(kGroup, "latent_storage", std::string(m.storage == LatentStorage::kHalf ? "float16" : "uint8"));
  f.SetAttr(kGroup, "layers", std::int64_t(m.net.layers()));
  f.SetAttr(kGroup, "activation", std::string(ActivationName(m.net.shape().activation)));
  f.SetAttr(kGroup, "half_vector", std::int64_t(m.encoding.half_vector ? 1 : 0));
  f.SetAttr(kGroup, "fourier", std::int64_t(m.encoding.fourier));
  const hsize_t c = m.latent;
  if (c > 0 && m.storage == LatentStorage::kHalf) {
    f.WriteFloats(Item("latents"), {hsize_t(H), hsize_t(W), c}, m.latents.data(), h5::Storage::kFloat16);
  } else if (c > 0) {
    f.WriteCodes(Item("latents"), {hsize_t(H), hsize_t(W), c}, m.codes.data(), 8);
    f.WriteFloats(Item("latent_scale"), {c}, m.scale.data());
    f.WriteFloats(Item("latent_bias"), {c}, m.bias.data());
  }
  for (int l = 0; l < m.net.layers(); ++l) {
    const auto w = m.net.weight(l);
    const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = w;
    f.WriteFloats(Item(WeightName(l)), {hsize_t(w.rows()), hsize_t(w.cols())}, rows.data());
    f.WriteFloats(Item(BiasName(l)), {hsize_t(w.rows())}, m.net.bias(l).data());
  }
}

NeuralCodecModel ReadNeuralModel(const h5::File& f, int H, int W, int C) {
  if (!f.Exists(kGroup)) ThrowBadInput("'{}': required group '{}' is missing", f.path(), kGroup);
  NeuralCodecModel m;
  m.latent = int(Attr(f, "latent", 0, 256));
  const std::string storage = f.GetString(kGroup, "latent_storage");
  if (storage != "uint8" && storage != "float16")
    ThrowBadInput("'{}': '{}@latent_storage' = '{}' (uint8 or float16)", f.path(), kGroup, storage);
  m.storage = storage == "float16" ? LatentStorage::kHalf : LatentStorage::kUint8;
  const int layers = int(Attr(f, "layers", 1, 17));
  m.encoding.half_vector = Attr(f, "half_vector", 0, 1) == 1;
  m.encoding.fourier = int(Attr(f, "fourier", 0, 8));
  const Activation activation = ReadActivation(f);
  const std::size_t T = std::size_t(H) * W;
  const hsize_t c = m.latent;
  CheckAllocation(4.0 * double(T) * double(c + 1), fmt::format("'{}' neural latents", f.path()));
  m.latents.resize(m.latent, Eigen::Index(T));
  if (c > 0 && m.storage == LatentStorage::kHalf) {
    if (f.Exists(Item("latents")) && f.StorageOf(Item("latents")) != "float16")
      ThrowBadInput("'{}': '{}' is not float16 (latent_storage float16)", f.path(), Item("latents"));
    const auto v = Floats(f, Item("latents"), {hsize_t(H), hsize_t(W), c});
    std::copy(v.begin(), v.end(), m.latents.data());
  } else if (c > 0) {
    CheckDims(f, Item("latents"), {hsize_t(H), hsize_t(W), c});
    const auto q = f.ReadInts(Item("latents"));
    m.scale = Floats(f, Item("latent_scale"), {c});
    m.bias = Floats(f, Item("latent_bias"), {c});
    m.codes.resize(q.size());
    for (std::size_t i = 0; i < q.size(); ++i) {
      if (q[i] < 0 || q[i] > 255)
        ThrowBadInput("'{}': '{}' element {} is {}, outside [0, 255]", f.path(), Item("latents"), i, q[i]);
      m.codes[i] = std::uint16_t(q[i]);
      const float x = Dequantise(m.scale[i % c], m.bias[i % c], m.codes[i]);
      if (!std::isfinite(x)) ThrowBadInput("'{}': '{}' element {} dequantises to a non-finite value", f.path(), Item("latents"), i);
      m.latents.data()[i] = x;
    }
  }
  m.net = ReadNet(f, layers, m.latent + m.encoding.Width(), C, activation);
  return m;
}

}  // namespace btf
