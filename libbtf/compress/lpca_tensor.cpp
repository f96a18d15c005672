// LPCA with factorised Eigen-ABRDFs (lpca_tensor.h): the rate-distortion choice of SVD terms,
// quantisation, decoders and codec-file items.
#include "libbtf/compress/lpca_tensor.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <Eigen/Core>
#include <Eigen/SVD>
#include <omp.h>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/codec_items.h"
#include "libbtf/core/error.h"
#include "libbtf/io/hdf5.h"

namespace btf {

std::vector<std::uint16_t> QuantiseVector(const float* x, std::size_t n, int bits, float* scale, float* bias,
                                          float* out) {
  BTF_CHECK(bits == 8 || bits == 16);
  std::vector<std::uint16_t> q(n, 0);
  if (n == 0) {
    *scale = 0, *bias = 0;
    return q;
  }
  double lo = x[0], hi = x[0];
  for (std::size_t i = 1; i < n; ++i) lo = std::min(lo, double(x[i])), hi = std::max(hi, double(x[i]));
  const double levels = double((1u << bits) - 1);
  *bias = static_cast<float>(lo);
  *scale = static_cast<float>((hi - lo) / levels);
  for (std::size_t i = 0; i < n; ++i) {
    double c = *scale > 0 ? std::round((double(x[i]) - double(*bias)) / double(*scale)) : 0.0;
    c = std::clamp(c, 0.0, levels);
    q[i] = static_cast<std::uint16_t>(c);
    out[i] = Dequantise(*scale, *bias, q[i]);
  }
  return q;
}

void LpcaTensorModel::Index() {
  first.assign(ranks.size() + 1, 0);
  for (std::size_t i = 0; i < ranks.size(); ++i) first[i + 1] = first[i] + static_cast<std::uint32_t>(ranks[i]);
}

std::uint64_t LpcaTensorModel::TermBytes() const {
  return std::uint64_t(views + seg()) * (bits / 8) + 4 * 4;
}

std::uint64_t LpcaTensorModel::FixedBytes(std::size_t texels) const {
  return std::uint64_t(clusters) * 4 + std::uint64_t(texels) * 4 + std::uint64_t(clusters) * (1 + components) * 4 +
         std::uint64_t(texels) * components * (bits / 8) + std::uint64_t(clusters) * components * 2 * 4;
}

std::uint64_t LpcaTensorModel::StoredBytes() const { return FixedBytes(cluster_of.size()) + terms() * TermBytes(); }

void LpcaTensorModel::FunctionsAtView(int view, std::vector<float>& out) const {
  const int F = functions_per_cluster();
  const std::size_t S = seg();
  out.assign(std::size_t(clusters) * F * S, 0.0f);
  // One cluster per iteration, terms summed in order: independent of the thread count.
#pragma omp parallel for schedule(static)
  for (int k = 0; k < clusters; ++k)
    for (int f = 0; f < F; ++f) {
      const std::size_t fi = std::size_t(k) * F + f;
      float* o = &out[fi * S];
      for (std::uint32_t t = first[fi]; t < first[fi + 1]; ++t) {
        const float a = u[std::size_t(t) * views + view];
        const float* wt = &w[std::size_t(t) * S];
        for (std::size_t i = 0; i < S; ++i) o[i] += a * wt[i];
      }
    }
}

LpcaModel ExpandToLpca(const LpcaTensorModel& m) {
  const int F = m.functions_per_cluster(), c = m.components;
  const std::size_t S = m.seg(), d = std::size_t(m.views) * S, K = std::size_t(m.clusters);
  LpcaModel l;
  l.clusters = m.clusters, l.components = c;
  l.cluster_components = m.cluster_components, l.cluster_of = m.cluster_of, l.weights = m.weights;
  l.means.assign(K * d, 0.0f);
  l.basis.assign(K * std::size_t(c) * d, 0.0f);
  std::vector<float> at_view;
  for (int v = 0; v < m.views; ++v) {
    m.FunctionsAtView(v, at_view);
    for (std::size_t k = 0; k < K; ++k) {
      const float* fk = &at_view[k * F * S];
      std::copy(fk, fk + S, &l.means[k * d + std::size_t(v) * S]);
      for (int j = 0; j < c; ++j)
        std::copy(fk + std::size_t(1 + j) * S, fk + std::size_t(2 + j) * S,
                  &l.basis[(k * std::size_t(c) + std::size_t(j)) * d + std::size_t(v) * S]);
    }
  }
  return l;
}

Codec ExpandToLpcaCodec(const Codec& t) {
  BTF_CHECK(t.method() == CodecMethod::kLpcaTensor);
  Codec out = CodecBuilder::Make(CodecMethod::kLpca, t.views(), t.lights(), t.height(), t.width(), t.channels(),
                                 t.info(), t.value_map());
  CodecBuilder::lpca(out) = ExpandToLpca(t.lpca_tensor());
  CodecBuilder::provenance(out) = t.provenance();
  return out;
}

void LpcaTensorModel::AddFunction(int k, int f, int view, int light, double coef, double* acc) const {
  const std::size_t fi = std::size_t(k) * functions_per_cluster() + f, S = seg();
  for (std::uint32_t t = first[fi]; t < first[fi + 1]; ++t) {
    const double a = coef * u[std::size_t(t) * views + view];
    const float* wt = &w[std::size_t(t) * S + std::size_t(light) * channels];
    for (int ch = 0; ch < channels; ++ch) acc[ch] += a * wt[ch];
  }
}

void LpcaTensorModel::Sample(int view, int light, std::size_t texel, float* out) const {
  double acc[64] = {};
  BTF_CHECK(channels <= 64);
  const int k = cluster_of[texel];
  AddFunction(k, 0, view, light, 1.0, acc);
  for (int j = 0; j < cluster_components[static_cast<std::size_t>(k)]; ++j)
    AddFunction(k, 1 + j, view, light, weights[texel * components + j], acc);
  for (int ch = 0; ch < channels; ++ch) out[ch] = static_cast<float>(acc[ch]);
}

void LpcaTensorModel::DecodeAbrdf(std::size_t texel, float* out) const {
  const std::size_t S = seg();
  const int k = cluster_of[texel], F = functions_per_cluster();
  std::vector<double> acc(std::size_t(views) * S, 0.0);
  for (int f = 0; f <= cluster_components[static_cast<std::size_t>(k)]; ++f) {
    const double coef = f == 0 ? 1.0 : double(weights[texel * components + (f - 1)]);
    const std::size_t fi = std::size_t(k) * F + f;
    for (std::uint32_t t = first[fi]; t < first[fi + 1]; ++t)
      for (int v = 0; v < views; ++v) {
        const double a = coef * u[std::size_t(t) * views + v];
        for (std::size_t i = 0; i < S; ++i) acc[std::size_t(v) * S + i] += a * w[std::size_t(t) * S + i];
      }
  }
  for (std::size_t i = 0; i < acc.size(); ++i) out[i] = static_cast<float>(acc[i]);
}

namespace {

struct FunctionSvd {
  Eigen::MatrixXd u;    // V x n
  Eigen::MatrixXd sv;   // n x S: singular value times right singular vector
  Eigen::VectorXd s;
};

struct Candidate {
  double gain;
  int k, f, r;
};

}  // namespace

double FactoriseLpca(const LpcaModel& lpca, int V, int L, int C, double total, double residual,
                     const TensorRequest& req, LpcaTensorModel& m) {
  BTF_CHECK(req.bits == 8 || req.bits == 16);
  const int K = lpca.clusters, c = lpca.components, F = 1 + c;
  const std::size_t S = std::size_t(L) * C, d = std::size_t(V) * S, N = lpca.cluster_of.size();
  m = LpcaTensorModel{};
  m.clusters = K, m.components = c, m.bits = req.bits, m.views = V, m.lights = L, m.channels = C;
  m.cluster_components = lpca.cluster_components;
  m.cluster_of = lpca.cluster_of;

  // Weights, quantised per (cluster, component) over the cluster's texels (texel order).
  std::vector<std::vector<std::size_t>> members(static_cast<std::size_t>(K));
  for (std::size_t i = 0; i < N; ++i) members[static_cast<std::size_t>(lpca.cluster_of[i])].push_back(i);
  m.weights.assign(N * c, 0.0f);
  m.weight_codes.assign(N * c, 0);
  m.weight_scale.assign(std::size_t(K) * c, 0.0f);
  m.weight_bias.assign(std::size_t(K) * c, 0.0f);
  std::vector<double> alpha(std::size_t(K) * F, 0.0);
  std::vector<float> x, y;
  for (int k = 0; k < K; ++k) {
    const auto& mem = members[static_cast<std::size_t>(k)];
    alpha[std::size_t(k) * F] = double(mem.size());
    for (int j = 0; j < lpca.cluster_components[static_cast<std::size_t>(k)]; ++j) {
      x.resize(mem.size()), y.resize(mem.size());
      for (std::size_t i = 0; i < mem.size(); ++i) x[i] = lpca.weights[mem[i] * c + j];
      const std::size_t kj = std::size_t(k) * c + j;
      const auto q = QuantiseVector(x.data(), x.size(), req.bits, &m.weight_scale[kj], &m.weight_bias[kj], y.data());
      double a = 0;
      for (std::size_t i = 0; i < mem.size(); ++i) {
        m.weights[mem[i] * c + j] = y[i];
        m.weight_codes[mem[i] * c + j] = q[i];
        a += double(y[i]) * y[i];
      }
      alpha[std::size_t(k) * F + 1 + j] = a;
    }
  }

  // SVD of every function (one cluster per task, Eigen sequential inside).
  std::vector<FunctionSvd> svd(std::size_t(K) * F);
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < K; ++k) {
    omp_set_num_threads(1);
    for (int f = 0; f <= lpca.cluster_components[static_cast<std::size_t>(k)]; ++f) {
      const float* src = f == 0 ? &lpca.means[std::size_t(k) * d] : &lpca.basis[(std::size_t(k) * c + (f - 1)) * d];
      const Eigen::MatrixXd M =
          Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(src, V,
                                                                                                   Eigen::Index(S))
              .cast<double>();
      Eigen::BDCSVD<Eigen::MatrixXd> sv(M, Eigen::ComputeThinU | Eigen::ComputeThinV);
      FunctionSvd& o = svd[std::size_t(k) * F + f];
      o.s = sv.singularValues();
      o.u = sv.matrixU();
      o.sv = (sv.matrixV() * o.s.asDiagonal()).transpose();
    }
  }

  std::vector<Candidate> cand;
  for (int k = 0; k < K; ++k)
    for (int f = 0; f < F; ++f) {
      const FunctionSvd& o = svd[std::size_t(k) * F + f];
      for (Eigen::Index r = 0; r < o.s.size(); ++r) {
        const double g = alpha[std::size_t(k) * F + f] * o.s[r] * o.s[r];
        if (g > 0) cand.push_back({g, k, f, static_cast<int>(r)});
      }
    }
  std::stable_sort(cand.begin(), cand.end(), [](const Candidate& a, const Candidate& b) { return a.gain > b.gain; });
  // dropped[n] = energy of the candidates not kept when the first n are.
  std::vector<double> dropped(cand.size() + 1, 0.0);
  for (std::size_t i = cand.size(); i-- > 0;) dropped[i] = dropped[i + 1] + cand[i].gain;
  std::size_t keep = cand.size();
  auto smallest_within = [&](double allowed) {
    std::size_t n = 0;
    while (n < cand.size() && dropped[n] > allowed) ++n;
    return n;
  };
  if (req.max_bytes > 0) {
    const std::uint64_t fixed = m.FixedBytes(N);
    if (req.max_bytes < fixed)
      ThrowUsage("--bytes {} is below the {} bytes lpca-tensor needs before any factor term ({} clusters, {} weights "
                 "per texel at {} bits); lower --components or --clusters",
                 req.max_bytes, fixed, K, c, req.bits);
    keep = std::min<std::size_t>(cand.size(), (req.max_bytes - fixed) / m.TermBytes());
  } else if (req.target_error > 0) {
    keep = smallest_within(std::max(0.0, req.target_error * req.target_error * total - residual));
  } else {
    keep = smallest_within(req.growth * residual);
  }

  m.ranks.assign(std::size_t(K) * F, 0);
  for (std::size_t i = 0; i < keep; ++i) ++m.ranks[std::size_t(cand[i].k) * F + cand[i].f];
  m.Index();
  const std::size_t R = m.first.back();
  m.u.assign(R * V, 0.0f), m.w.assign(R * S, 0.0f);
  m.u_codes.assign(R * V, 0), m.w_codes.assign(R * S, 0);
  m.u_scale.assign(R, 0.0f), m.u_bias.assign(R, 0.0f), m.w_scale.assign(R, 0.0f), m.w_bias.assign(R, 0.0f);
  std::vector<float> uf(static_cast<std::size_t>(V)), wf(S);
  for (std::size_t fi = 0; fi < std::size_t(K) * F; ++fi) {
    const FunctionSvd& o = svd[fi];
    for (std::uint32_t t = m.first[fi]; t < m.first[fi + 1]; ++t) {
      const Eigen::Index r = t - m.first[fi];
      // Sign: the view factor's largest-magnitude entry (the first on ties) is positive.
      Eigen::Index arg = 0;
      for (Eigen::Index v = 1; v < V; ++v)
        if (std::abs(o.u(v, r)) > std::abs(o.u(arg, r))) arg = v;
      const double sign = o.u(arg, r) < 0 ? -1.0 : 1.0;
      for (int v = 0; v < V; ++v) uf[static_cast<std::size_t>(v)] = static_cast<float>(sign * o.u(v, r));
      for (std::size_t i = 0; i < S; ++i) wf[i] = static_cast<float>(sign * o.sv(r, Eigen::Index(i)));
      auto qu = QuantiseVector(uf.data(), uf.size(), m.bits, &m.u_scale[t], &m.u_bias[t], &m.u[std::size_t(t) * V]);
      auto qw = QuantiseVector(wf.data(), S, m.bits, &m.w_scale[t], &m.w_bias[t], &m.w[std::size_t(t) * S]);
      std::copy(qu.begin(), qu.end(), m.u_codes.begin() + std::ptrdiff_t(t) * V);
      std::copy(qw.begin(), qw.end(), m.w_codes.begin() + std::ptrdiff_t(t * S));
    }
  }
  return total > 0 ? std::sqrt((residual + dropped[keep]) / total) : 0.0;
}

// ---- Codec-file items ----

namespace {

constexpr const char* kGroup = "/codec/lpca_tensor";

std::string Item(const char* name) { return fmt::format("{}/{}", kGroup, name); }

using codec_items::Floats;
using codec_items::Ints;

std::vector<std::uint16_t> Codes(const h5::File& f, const std::string& name, const std::vector<hsize_t>& dims, int bits) {
  const auto v = Ints(f, name, dims, 0, (1 << bits) - 1);
  return std::vector<std::uint16_t>(v.begin(), v.end());
}

// Dequantises codes (n per vector) with per-vector scale/bias; refuses values that overflow float.
void DequantiseAll(const h5::File& f, const std::string& name, const std::vector<std::uint16_t>& codes, std::size_t n,
                const std::vector<float>& scale, const std::vector<float>& bias, std::vector<float>& out) {
  out.resize(codes.size());
  for (std::size_t i = 0; i < codes.size(); ++i) {
    out[i] = btf::Dequantise(scale[i / n], bias[i / n], codes[i]);
    if (!std::isfinite(out[i]))
      ThrowBadInput("'{}': '{}' element {} dequantises to a non-finite value", f.path(), name, i);
  }
}

}  // namespace

void WriteLpcaTensorModel(const h5::File& f, const LpcaTensorModel& m, int H, int W) {
  const hsize_t K = m.clusters, c = m.components, V = m.views, L = m.lights, C = m.channels, R = m.terms();
  f.CreateGroup(kGroup);
  f.SetAttr(kGroup, "clusters", std::int64_t(K));
  f.SetAttr(kGroup, "components", std::int64_t(c));
  f.SetAttr(kGroup, "bits", std::int64_t(m.bits));
  f.WriteInts(Item("cluster_components"), {K}, m.cluster_components.data());
  f.WriteInts(Item("cluster_index"), {hsize_t(H), hsize_t(W)}, m.cluster_of.data());
  f.WriteInts(Item("ranks"), {K, 1 + c}, m.ranks.data());
  if (R > 0) {
    f.WriteCodes(Item("view_factors"), {R, V}, m.u_codes.data(), m.bits);
    f.WriteFloats(Item("view_scale"), {R}, m.u_scale.data());
    f.WriteFloats(Item("view_bias"), {R}, m.u_bias.data());
    f.WriteCodes(Item("light_factors"), {R, L, C}, m.w_codes.data(), m.bits);
    f.WriteFloats(Item("light_scale"), {R}, m.w_scale.data());
    f.WriteFloats(Item("light_bias"), {R}, m.w_bias.data());
  }
  if (c > 0) {
    f.WriteCodes(Item("weights"), {hsize_t(H), hsize_t(W), c}, m.weight_codes.data(), m.bits);
    f.WriteFloats(Item("weight_scale"), {K, c}, m.weight_scale.data());
    f.WriteFloats(Item("weight_bias"), {K, c}, m.weight_bias.data());
  }
}

LpcaTensorModel ReadLpcaTensorModel(const h5::File& f, int V, int L, int H, int W, int C) {
  if (!f.Exists(kGroup)) ThrowBadInput("'{}': required group '{}' is missing", f.path(), kGroup);
  LpcaTensorModel m;
  const std::int64_t K = f.GetInt(kGroup, "clusters"), c = f.GetInt(kGroup, "components"), bits = f.GetInt(kGroup, "bits");
  const std::size_t N = std::size_t(H) * W, S = std::size_t(L) * C;
  if (K < 1 || K > std::int64_t(N)) ThrowBadInput("'{}': '{}@clusters' = {} is outside [1, {}]", f.path(), kGroup, K, N);
  if (c < 0 || c > 4096) ThrowBadInput("'{}': '{}@components' = {} is outside [0, 4096]", f.path(), kGroup, c);
  if (bits != 8 && bits != 16) ThrowBadInput("'{}': '{}@bits' = {} (8 or 16)", f.path(), kGroup, bits);
  m.clusters = int(K), m.components = int(c), m.bits = int(bits), m.views = V, m.lights = L, m.channels = C;
  const hsize_t hK = hsize_t(K), hc = hsize_t(c);
  m.cluster_components = Ints(f, Item("cluster_components"), {hK}, 0, c);
  m.cluster_of = Ints(f, Item("cluster_index"), {hsize_t(H), hsize_t(W)}, 0, K - 1);
  const std::int64_t max_rank = std::min<std::int64_t>(V, std::int64_t(S));
  m.ranks = Ints(f, Item("ranks"), {hK, 1 + hc}, 0, max_rank);
  for (std::int64_t k = 0; k < K; ++k)
    for (std::int64_t j = m.cluster_components[std::size_t(k)]; j < c; ++j)
      if (m.ranks[std::size_t(k * (1 + c) + 1 + j)] != 0)
        ThrowBadInput("'{}': '{}' gives Eigen-ABRDF {} of cluster {} a rank, but the cluster has {} components",
                      f.path(), Item("ranks"), j, k, m.cluster_components[std::size_t(k)]);
  m.Index();
  const std::size_t R = m.first.back();
  CheckAllocation(6.0 * double(R) * double(V + S) + 6.0 * double(N) * double(c),
                  fmt::format("'{}' lpca-tensor model", f.path()));
  if (R > 0) {
    const hsize_t hR = R;
    m.u_codes = Codes(f, Item("view_factors"), {hR, hsize_t(V)}, m.bits);
    m.u_scale = Floats(f, Item("view_scale"), {hR});
    m.u_bias = Floats(f, Item("view_bias"), {hR});
    m.w_codes = Codes(f, Item("light_factors"), {hR, hsize_t(L), hsize_t(C)}, m.bits);
    m.w_scale = Floats(f, Item("light_scale"), {hR});
    m.w_bias = Floats(f, Item("light_bias"), {hR});
    DequantiseAll(f, Item("view_factors"), m.u_codes, std::size_t(V), m.u_scale, m.u_bias, m.u);
    DequantiseAll(f, Item("light_factors"), m.w_codes, S, m.w_scale, m.w_bias, m.w);
  }
  m.weights.assign(N * c, 0.0f);
  m.weight_codes.assign(N * c, 0);
  m.weight_scale.assign(std::size_t(K) * c, 0.0f);
  m.weight_bias.assign(std::size_t(K) * c, 0.0f);
  if (c > 0) {
    m.weight_codes = Codes(f, Item("weights"), {hsize_t(H), hsize_t(W), hc}, m.bits);
    m.weight_scale = Floats(f, Item("weight_scale"), {hK, hc});
    m.weight_bias = Floats(f, Item("weight_bias"), {hK, hc});
    for (std::size_t i = 0; i < N; ++i) {
      const int k = m.cluster_of[i];
      for (int j = 0; j < m.cluster_components[std::size_t(k)]; ++j) {
        const std::size_t kj = std::size_t(k) * c + j;
        m.weights[i * c + j] = btf::Dequantise(m.weight_scale[kj], m.weight_bias[kj], m.weight_codes[i * c + j]);
        if (!std::isfinite(m.weights[i * c + j]))
          ThrowBadInput("'{}': '{}' element {} dequantises to a non-finite value", f.path(), Item("weights"), i * c + j);
      }
    }
  }
  return m;
}

}  // namespace btf
