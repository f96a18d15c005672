#include "libbtf/compress/codec.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Core>

#include "libbtf/core/error.h"

namespace btf {

namespace {
using RowMajorF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// LPCA's view-slot loop: per block of kTexels texels, their L*C values of this view into a
// per-thread buffer (mean + weighted basis rows, contiguous; mean(k) and basis(k, j) point at the
// view's L*C values), then written out light by light (contiguous runs of kTexels*C values). No
// allocation per texel.
template <typename Mean, typename Basis>
void ClusterTexelLoop(const std::vector<std::int32_t>& cluster_of, const std::vector<std::int32_t>& cluster_components,
                      const std::vector<float>& weights, int stride, std::size_t T, int L, int C, const Mean& mean,
                      const Basis& basis, float* out) {
  const std::size_t seg = std::size_t(L) * C;
  constexpr std::size_t kTexels = 64;
  const std::ptrdiff_t blocks = static_cast<std::ptrdiff_t>((T + kTexels - 1) / kTexels);
#pragma omp parallel
  {
    // Eigen-aligned: Eigen peels to the destination's alignment, so the values do not depend
    // on where malloc put the buffer.
    Eigen::VectorXf buf(static_cast<Eigen::Index>(kTexels * seg));
#pragma omp for schedule(static)
    for (std::ptrdiff_t b = 0; b < blocks; ++b) {
      const std::size_t t0 = std::size_t(b) * kTexels, nt = std::min(kTexels, T - t0);
      for (std::size_t i = 0; i < nt; ++i) {
        const std::size_t t = t0 + i;
        const int k = cluster_of[t];
        auto v = buf.segment(static_cast<Eigen::Index>(i * seg), static_cast<Eigen::Index>(seg));
        v = Eigen::Map<const Eigen::VectorXf>(mean(k), static_cast<Eigen::Index>(seg));
        for (int j = 0; j < cluster_components[static_cast<std::size_t>(k)]; ++j)
          v += weights[t * stride + j] * Eigen::Map<const Eigen::VectorXf>(basis(k, j), static_cast<Eigen::Index>(seg));
      }
      for (int l = 0; l < L; ++l) {
        float* o = out + (std::size_t(l) * T + t0) * C;
        for (std::size_t i = 0; i < nt; ++i)
          for (int ch = 0; ch < C; ++ch) o[i * C + ch] = buf[static_cast<Eigen::Index>(i * seg + std::size_t(l) * C + ch)];
      }
    }
  }
}

std::array<float, 3> ToFloat3(const Vec3& d) {
  const Vec3 n = d.normalized();
  return {float(n.x()), float(n.y()), float(n.z())};
}

// Texel taps (texel, weight) of texture coordinates uv: continuous texel coordinates (texel
// centres at integers), wrapped.
std::vector<std::pair<std::size_t, double>> UvTaps(const Vec2& uv, int width, int height, UvFilter filter) {
  std::vector<std::pair<std::size_t, double>> taps;
  const double fx = uv.x() * width - 0.5, fy = (1.0 - uv.y()) * height - 0.5;
  auto wrap = [](long long i, int n) { return static_cast<int>(((i % n) + n) % n); };
  if (filter == UvFilter::kNearest) {
    const int x = wrap(std::llround(fx), width), y = wrap(std::llround(fy), height);
    taps.emplace_back(std::size_t(y) * width + x, 1.0);
    return taps;
  }
  const double x0 = std::floor(fx), y0 = std::floor(fy), ax = fx - x0, ay = fy - y0;
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      const double w = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay);
      if (w <= 0) continue;
      const int x = wrap(static_cast<long long>(x0) + dx, width), y = wrap(static_cast<long long>(y0) + dy, height);
      taps.emplace_back(std::size_t(y) * width + x, w);
    }
  return taps;
}
}  // namespace

std::string MethodName(CodecMethod method) {
  switch (method) {
    case CodecMethod::kPcaView: return "pca-view";
    case CodecMethod::kLpca: return "lpca";
    case CodecMethod::kFmf: return "fmf";
    case CodecMethod::kDfmf: return "dfmf";
    case CodecMethod::kLpcaTensor: return "lpca-tensor";
    case CodecMethod::kNeural: return "neural";
  }
  return "unknown";
}

CodecMethod ParseMethod(const std::string& name) {
  if (name == "pca-view") return CodecMethod::kPcaView;
  if (name == "lpca") return CodecMethod::kLpca;
  if (name == "fmf") return CodecMethod::kFmf;
  if (name == "dfmf") return CodecMethod::kDfmf;
  if (name == "lpca-tensor") return CodecMethod::kLpcaTensor;
  if (name == "neural") return CodecMethod::kNeural;
  ThrowUsage("unknown compression method '{}' (use pca-view, lpca, lpca-tensor, fmf, dfmf or neural)", name);
}

std::string StorageName(CodecStorage storage) { return storage == CodecStorage::kHalf ? "half" : "float"; }

CodecStorage ParseStorage(const std::string& name) {
  if (name == "float") return CodecStorage::kFloat;
  if (name == "half") return CodecStorage::kHalf;
  ThrowUsage("unknown coefficient storage '{}' (use float or half)", name);
}

Codec CodecBuilder::Make(CodecMethod method, Sampling views, Sampling lights, int height, int width, int channels,
                         DatasetInfo info, const ValueMap& transform) {
  Codec c;
  c.method_ = method;
  c.views_ = std::move(views);
  c.lights_ = std::move(lights);
  c.height_ = height;
  c.width_ = width;
  c.channels_ = channels;
  c.info_ = std::move(info);
  c.value_map_ = transform;
  return c;
}

std::uint64_t Codec::StoredBytes() const {
  std::uint64_t floats = 0, ints = 0;
  if (method_ == CodecMethod::kLpcaTensor) return tensor_.StoredBytes();
  if (method_ == CodecMethod::kNeural) return neural_.StoredBytes();
  if (method_ == CodecMethod::kPcaView) {
    for (const auto& s : slots_) floats += s.mean.size() + s.basis.size() + s.weights.size();
  } else if (IsFullMatrixFactorisation(method_)) {
    floats = fmf_.StoredValues();
  } else {
    floats = lpca_.means.size() + lpca_.basis.size() + lpca_.weights.size();
    ints = lpca_.cluster_of.size() + lpca_.cluster_components.size();
  }
  return floats * (storage_ == CodecStorage::kHalf ? 2 : 4) + ints * 4;
}

std::uint64_t Codec::RawBytes(int bytes_per_value) const {
  return std::uint64_t(num_views()) * num_lights() * image_size() * std::uint64_t(bytes_per_value);
}

void Codec::SampleTransformed(int view, int light, std::size_t texel, float* out) const {
  if (IsFullMatrixFactorisation(method_)) return fmf_.Sample(view, light, texel, out);
  if (method_ == CodecMethod::kLpcaTensor) return tensor_.Sample(view, light, texel, out);
  if (method_ == CodecMethod::kNeural) {
    const auto wi = ToFloat3(lights_[light]), wo = ToFloat3(views_[view]);
    return neural_.Evaluate(
        1, [&](Eigen::Index) { return neural_.latents.col(Eigen::Index(texel)).data(); },
        [&](Eigen::Index) { return wi.data(); }, [&](Eigen::Index) { return wo.data(); }, out);
  }
  const int C = channels_;
  if (method_ == CodecMethod::kPcaView) {
    const PcaViewSlot& s = slots_[static_cast<std::size_t>(view)];
    const std::size_t D = image_size();
    for (int ch = 0; ch < C; ++ch) {
      const std::size_t t = texel * C + ch;
      double v = s.mean[t];
      for (int k = 0; k < s.components; ++k)
        v += double(s.weights[std::size_t(light) * s.components + k]) * s.basis[std::size_t(k) * D + t];
      out[ch] = static_cast<float>(v);
    }
  } else {
    const LpcaModel& m = lpca_;
    const std::size_t d = abrdf_size();
    const int k = m.cluster_of[texel];
    const std::size_t base = (std::size_t(view) * num_lights() + light) * C;
    for (int ch = 0; ch < C; ++ch) {
      double v = m.means[std::size_t(k) * d + base + ch];
      for (int j = 0; j < m.cluster_components[static_cast<std::size_t>(k)]; ++j)
        v += double(m.weights[texel * m.components + j]) *
             m.basis[(std::size_t(k) * m.components + j) * d + base + ch];
      out[ch] = static_cast<float>(v);
    }
  }
}

void Codec::DecodeViewSlot(int view, float* out) const {
  if (view < 0 || view >= num_views()) ThrowUsage("view {} out of range (codec has {} views)", view, num_views());
  const int L = num_lights(), C = channels_;
  const std::size_t D = image_size(), T = std::size_t(height_) * width_;
  if (method_ == CodecMethod::kPcaView) {
    const PcaViewSlot& s = slots_[static_cast<std::size_t>(view)];
    Eigen::Map<RowMajorF> o(out, L, static_cast<Eigen::Index>(D));
    const Eigen::Map<const Eigen::VectorXf> mean(s.mean.data(), static_cast<Eigen::Index>(D));
    if (s.components > 0) {
      const Eigen::Map<const RowMajorF> w(s.weights.data(), L, s.components);
      const Eigen::Map<const RowMajorF> b(s.basis.data(), s.components, static_cast<Eigen::Index>(D));
      o.noalias() = w * b;
      o.rowwise() += mean.transpose();
    } else {
      o.rowwise() = mean.transpose();
    }
  } else if (IsFullMatrixFactorisation(method_)) {
    fmf_.DecodeViewSlot(view, out);
  } else if (method_ == CodecMethod::kNeural) {
    std::vector<float> wi, wo;  // per light
    for (int l = 0; l < L; ++l) {
      const auto i3 = ToFloat3(lights_[l]), o3 = ToFloat3(views_[view]);
      wi.insert(wi.end(), i3.begin(), i3.end());
      wo.insert(wo.end(), o3.begin(), o3.end());
    }
    neural_.DecodeImages(L, wi.data(), wo.data(), out);
  } else if (method_ == CodecMethod::kLpcaTensor) {
    // The view's rows of every cluster function (K (1 + c) L C floats), then LPCA's texel loop.
    const LpcaTensorModel& m = tensor_;
    std::vector<float> rows;
    m.FunctionsAtView(view, rows);
    const std::size_t S = m.seg(), F = static_cast<std::size_t>(m.functions_per_cluster());
    ClusterTexelLoop(m.cluster_of, m.cluster_components, m.weights, m.components, T, L, C,
                     [&](int k) { return &rows[std::size_t(k) * F * S]; },
                     [&](int k, int j) { return &rows[(std::size_t(k) * F + 1 + j) * S]; }, out);
  } else {
    const LpcaModel& m = lpca_;
    const std::size_t d = abrdf_size(), base = std::size_t(view) * std::size_t(L) * C;
    ClusterTexelLoop(m.cluster_of, m.cluster_components, m.weights, m.components, T, L, C,
                     [&](int k) { return &m.means[std::size_t(k) * d + base]; },
                     [&](int k, int j) { return &m.basis[(std::size_t(k) * m.components + j) * d + base]; }, out);
  }
  if (value_map_.kind != ValueTransform::kNone) {
    const std::size_t n = std::size_t(L) * D;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) out[i] = Untransform(out[i]);
  }
}

void Codec::DecodeImage(int view, int light, float* out) const {
  if (view < 0 || view >= num_views() || light < 0 || light >= num_lights())
    ThrowUsage("image (view {}, light {}) out of range (codec has {} views, {} lights)", view, light, num_views(),
               num_lights());
  const std::size_t D = image_size(), T = std::size_t(height_) * width_;
  if (method_ == CodecMethod::kPcaView) {
    const PcaViewSlot& s = slots_[static_cast<std::size_t>(view)];
    Eigen::Map<Eigen::VectorXf> o(out, static_cast<Eigen::Index>(D));
    o = Eigen::Map<const Eigen::VectorXf>(s.mean.data(), static_cast<Eigen::Index>(D));
    if (s.components > 0) {
      const Eigen::Map<const RowMajorF> b(s.basis.data(), s.components, static_cast<Eigen::Index>(D));
      const Eigen::Map<const Eigen::VectorXf> w(&s.weights[std::size_t(light) * s.components], s.components);
      o.noalias() += b.transpose() * w;
    }
    if (value_map_.kind != ValueTransform::kNone)
      for (std::size_t i = 0; i < D; ++i) out[i] = Untransform(out[i]);
  } else if (IsFullMatrixFactorisation(method_) || method_ == CodecMethod::kNeural) {
    if (method_ == CodecMethod::kNeural)
      neural_.DecodeImages(1, ToFloat3(lights_[light]).data(), ToFloat3(views_[view]).data(), out);
    else
      fmf_.DecodeImage(view, light, out);
    if (value_map_.kind != ValueTransform::kNone)
      for (std::size_t i = 0; i < D; ++i) out[i] = Untransform(out[i]);
  } else if (method_ == CodecMethod::kLpcaTensor) {
    // Every cluster function at (view, light) first (K (1 + c) C values), then per texel.
    const LpcaTensorModel& m = tensor_;
    const int F = m.functions_per_cluster(), C = channels_;
    std::vector<double> at(std::size_t(m.clusters) * F * C, 0.0);
    for (int k = 0; k < m.clusters; ++k)
      for (int f = 0; f <= m.cluster_components[static_cast<std::size_t>(k)]; ++f)
        m.AddFunction(k, f, view, light, 1.0, &at[(std::size_t(k) * F + f) * C]);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t t = 0; t < static_cast<std::ptrdiff_t>(T); ++t) {
      const int k = m.cluster_of[static_cast<std::size_t>(t)];
      for (int ch = 0; ch < C; ++ch) {
        double v = at[std::size_t(k) * F * C + ch];
        for (int j = 0; j < m.cluster_components[static_cast<std::size_t>(k)]; ++j)
          v += double(m.weights[std::size_t(t) * m.components + j]) * at[(std::size_t(k) * F + 1 + j) * C + ch];
        out[t * C + ch] = Untransform(static_cast<float>(v));
      }
    }
  } else {
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t t = 0; t < static_cast<std::ptrdiff_t>(T); ++t) {
      SampleTransformed(view, light, static_cast<std::size_t>(t), out + t * channels_);
      for (int ch = 0; ch < channels_; ++ch) out[t * channels_ + ch] = Untransform(out[t * channels_ + ch]);
    }
  }
}

std::vector<float> Codec::DecodeAbrdf(int y, int x) const {
  if (y < 0 || y >= height_ || x < 0 || x >= width_)
    ThrowUsage("texel (x {}, y {}) out of range ({} x {})", x, y, width_, height_);
  const std::size_t t = std::size_t(y) * width_ + x;
  std::vector<float> out(abrdf_size());
  const int C = channels_;
  if (method_ == CodecMethod::kLpca) {
    const LpcaModel& m = lpca_;
    const std::size_t d = abrdf_size();
    const int k = m.cluster_of[t];
    Eigen::Map<Eigen::VectorXf> o(out.data(), static_cast<Eigen::Index>(d));
    o = Eigen::Map<const Eigen::VectorXf>(&m.means[std::size_t(k) * d], static_cast<Eigen::Index>(d));
    for (int j = 0; j < m.cluster_components[static_cast<std::size_t>(k)]; ++j)
      o += m.weights[t * m.components + j] *
           Eigen::Map<const Eigen::VectorXf>(&m.basis[(std::size_t(k) * m.components + j) * d],
                                             static_cast<Eigen::Index>(d));
    for (auto& v : out) v = Untransform(v);
  } else if (method_ == CodecMethod::kLpcaTensor) {
    tensor_.DecodeAbrdf(t, out.data());
    for (auto& v : out) v = Untransform(v);
  } else if (method_ == CodecMethod::kNeural) {  // one batch: every (view, light) pair, [v][l][ch]
    const int L = num_lights();
    std::vector<std::array<float, 3>> wi(static_cast<std::size_t>(L)), wo(static_cast<std::size_t>(num_views()));
    for (int l = 0; l < L; ++l) wi[std::size_t(l)] = ToFloat3(lights_[l]);
    for (int v = 0; v < num_views(); ++v) wo[std::size_t(v)] = ToFloat3(views_[v]);
    neural_.Evaluate(
        Eigen::Index(num_views()) * L, [&](Eigen::Index) { return neural_.latents.col(Eigen::Index(t)).data(); },
        [&](Eigen::Index i) { return wi[std::size_t(i % L)].data(); },
        [&](Eigen::Index i) { return wo[std::size_t(i / L)].data(); }, out.data());
    for (auto& v : out) v = Untransform(v);
  } else {
    for (int v = 0; v < num_views(); ++v)
      for (int l = 0; l < num_lights(); ++l) {
        float* o = &out[(std::size_t(v) * num_lights() + l) * C];
        SampleTransformed(v, l, t, o);
        for (int ch = 0; ch < C; ++ch) o[ch] = Untransform(o[ch]);
      }
  }
  return out;
}

Dataset Codec::DecodeAll() const {
  CheckAllocation(4.0 * num_views() * num_lights() * height() * width() * channels(), "decoded BTF");
  Dataset d(views_, lights_, height_, width_, channels_, info_);
  for (int v = 0; v < num_views(); ++v) DecodeViewSlot(v, d.view_slot(v).data());
  return d;
}

void Codec::Value(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out, UvFilter filter) const {
  if (!uv.allFinite() || !wi.allFinite() || !wo.allFinite() || wi.norm() == 0 || wo.norm() == 0)
    ThrowUsage("Codec::Value needs finite uv and non-zero finite directions");
  const auto taps = UvTaps(uv, width_, height_, filter);
  if (method_ == CodecMethod::kNeural) return NeuralValue(taps, wi, wo, out);
  const Interpolant iv = views_.Barycentric(wo), il = lights_.Barycentric(wi);
  std::vector<double> acc(static_cast<std::size_t>(channels_), 0.0);
  std::vector<float> s(static_cast<std::size_t>(channels_));
  for (const auto& [texel, weight] : taps)
    for (int a = 0; a < iv.count; ++a)
      for (int b = 0; b < il.count; ++b) {
        const double w = weight * iv.weight[static_cast<std::size_t>(a)] * il.weight[static_cast<std::size_t>(b)];
        if (w <= 0) continue;
        SampleTransformed(iv.index[static_cast<std::size_t>(a)], il.index[static_cast<std::size_t>(b)], texel,
                          s.data());
        for (int ch = 0; ch < channels_; ++ch) acc[static_cast<std::size_t>(ch)] += w * Untransform(s[static_cast<std::size_t>(ch)]);
      }
  for (int ch = 0; ch < channels_; ++ch) out[ch] = static_cast<float>(acc[static_cast<std::size_t>(ch)]);
}

void Codec::NeuralValue(const std::vector<std::pair<std::size_t, double>>& taps, const Vec3& wi, const Vec3& wo,
                        float* out) const {
  const NeuralCodecModel& m = neural_;
  std::vector<float> z(static_cast<std::size_t>(m.latent), 0.f);
  for (int j = 0; j < m.latent; ++j) {
    double v = 0;
    for (const auto& [texel, weight] : taps) v += weight * m.latents(j, Eigen::Index(texel));
    z[static_cast<std::size_t>(j)] = static_cast<float>(v);
  }
  const auto i3 = ToFloat3(wi), o3 = ToFloat3(wo);
  m.Evaluate(
      1, [&](Eigen::Index) { return z.data(); }, [&](Eigen::Index) { return i3.data(); },
      [&](Eigen::Index) { return o3.data(); }, out);
  for (int ch = 0; ch < channels_; ++ch) out[ch] = Untransform(out[ch]);
}

nlohmann::json Codec::Describe() const {
  nlohmann::json j;
  j["format"] = kCodecFormat;
  j["method"] = MethodName(method_);
  j["shape"] = {{"views", num_views()}, {"lights", num_lights()}, {"height", height_}, {"width", width_},
                {"channels", channels_}};
  j["view_sampling"] = {{"name", views_.name()}, {"count", views_.size()}};
  j["light_sampling"] = {{"name", lights_.name()}, {"count", lights_.size()}};
  if (method_ == CodecMethod::kPcaView) {
    int lo = 1 << 30, hi = 0;
    for (const auto& s : slots_) lo = std::min(lo, s.components), hi = std::max(hi, s.components);
    j["components_per_slot"] = {{"min", slots_.empty() ? 0 : lo}, {"max", hi}};
  } else if (IsFullMatrixFactorisation(method_)) {
    for (const auto& m : fmf_.matrices) j["components_per_matrix"].push_back(m.components);
  } else if (method_ == CodecMethod::kLpcaTensor) {
    j["clusters"] = tensor_.clusters;
    j["components"] = tensor_.components;
    j["factor_terms"] = tensor_.terms();
    j["quant_bits"] = tensor_.bits;
  } else if (method_ == CodecMethod::kNeural) {
    j["latent"] = neural_.latent;
    j["hidden"] = neural_.net.shape().hidden;
    j["activation"] = std::string(ActivationName(neural_.net.shape().activation));
    j["encoding"] = {{"half_vector", neural_.encoding.half_vector}, {"fourier", neural_.encoding.fourier}};
    j["decoder_parameters"] = neural_.net.parameter_count();
  } else {
    j["clusters"] = lpca_.clusters;
    j["components"] = lpca_.components;
  }
  j["storage"] = method_ == CodecMethod::kLpcaTensor ? fmt::format("uint{}", tensor_.bits)
                 : method_ == CodecMethod::kNeural     ? LatentStorageName(neural_.storage)
                                                       : StorageName(storage_);
  j["stored_bytes"] = StoredBytes();
  j["raw_float32_bytes"] = RawBytes(4);
  j["raw_half_bytes"] = RawBytes(2);
  j["ratio_vs_float32"] = StoredBytes() ? double(RawBytes(4)) / double(StoredBytes()) : 0.0;
  j["ratio_vs_half"] = StoredBytes() ? double(RawBytes(2)) / double(StoredBytes()) : 0.0;
  j["transform"] = value_map_.log() ? nlohmann::json{{"kind", "log"}, {"epsilon", value_map_.epsilon}}
                                                      : nlohmann::json{{"kind", "none"}};
  j["color_space"] = info_.color_space;
  j["units"] = info_.units;
  j["cos_theta_i_included"] = info_.cos_theta_i_included;
  j["channel_names"] = info_.channel_names;
  return j;
}

}  // namespace btf
