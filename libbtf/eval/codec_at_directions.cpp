#include "libbtf/eval/codec_at_directions.h"

#include <array>
#include <map>
#include <vector>

#include "libbtf/compress/codec_source.h"
#include "libbtf/core/error.h"

namespace btf {

namespace {

// A direction as the codec's decoders take it (Codec::Value: normalised in double, then float).
std::array<float, 3> Float3(const Vec3& d) {
  const Vec3 n = d.normalized();
  return {float(n.x()), float(n.y()), float(n.z())};
}

}  // namespace

CodecAtDirections::CodecAtDirections(const Codec& codec, Sampling views, Sampling lights, std::string name)
    : codec_(codec), views_(std::move(views)), lights_(std::move(lights)), name_(std::move(name)) {
  if (views_.size() < 1 || lights_.size() < 1) ThrowUsage("CodecAtDirections needs at least one view and one light");
}

void CodecAtDirections::ReadViewSlot(int view, float* out) const {
  BTF_CHECK(view >= 0 && view < views_.size());
  const int L = lights_.size(), C = channels();
  const std::size_t image = image_size(), T = std::size_t(height()) * width();
  if (codec_.method() == CodecMethod::kNeural) {
    // Texel centres with the nearest filter: each texel's own latent, as Codec::Value takes it.
    std::vector<float> wi, wo;
    const auto o3 = Float3(views_[view]);
    for (int l = 0; l < L; ++l) {
      const auto i3 = Float3(lights_[l]);
      wi.insert(wi.end(), i3.begin(), i3.end());
      wo.insert(wo.end(), o3.begin(), o3.end());
    }
    codec_.neural().DecodeImages(L, wi.data(), wo.data(), out);
    const ValueMap& map = codec_.value_map();
    const std::size_t n = std::size_t(L) * image;
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i) out[i] = map.Inverse(out[i]);
    return;
  }
  // Linear codecs: Codec::Value's blend, sum over the view's and the light's barycentric
  // neighbours of w_view w_light x (decoded value), in double, in Value's order.
  const Interpolant iv = codec_.views().Barycentric(views_[view]);
  std::map<int, std::vector<float>> slots;  // the sampled view slots the blend needs
  for (int a = 0; a < iv.count; ++a) {
    auto& s = slots[iv.index[std::size_t(a)]];
    if (!s.empty()) continue;
    s.resize(std::size_t(codec_.num_lights()) * image);
    codec_.DecodeViewSlot(iv.index[std::size_t(a)], s.data());
  }
  for (int l = 0; l < L; ++l) {
    const Interpolant il = codec_.lights().Barycentric(lights_[l]);
    float* o = out + std::size_t(l) * image;
#pragma omp parallel for schedule(static)
    for (std::size_t t = 0; t < T; ++t)
      for (int ch = 0; ch < C; ++ch) {
        double acc = 0;
        for (int a = 0; a < iv.count; ++a)
          for (int b = 0; b < il.count; ++b) {
            const double w = iv.weight[std::size_t(a)] * il.weight[std::size_t(b)];
            if (w <= 0) continue;
            const std::vector<float>& s = slots.at(iv.index[std::size_t(a)]);
            acc += w * s[std::size_t(il.index[std::size_t(b)]) * image + t * C + ch];
          }
        o[t * C + ch] = float(acc);
      }
  }
}

bool SameDirections(const Sampling& a, const Sampling& b) {
  if (a.size() != b.size()) return false;
  for (int i = 0; i < a.size(); ++i)
    if ((a[i] - b[i]).norm() > 1e-6) return false;
  return true;
}

std::unique_ptr<SlotSource> CodecAtReferenceDirections(const SlotSource& reference, const SlotSource& test) {
  const auto* codec = dynamic_cast<const CodecSource*>(&test);
  if (!codec || reference.height() != test.height() || reference.width() != test.width() ||
      reference.channels() != test.channels())
    return nullptr;
  if (SameDirections(reference.views(), test.views()) && SameDirections(reference.lights(), test.lights()))
    return nullptr;
  return std::make_unique<CodecAtDirections>(codec->codec(), reference.views(), reference.lights(), test.name());
}

}  // namespace btf
