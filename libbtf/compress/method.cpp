#include "libbtf/compress/method.h"

#include <algorithm>
#include <limits>

#include "libbtf/core/error.h"

namespace btf {

namespace {

// Stored bytes at c components (Codec::StoredBytes' count at the unclamped c).
double PcaViewBytes(const CompressOptions& o, const SlotSource& in, double c) {
  const double V = in.views().size(), L = in.lights().size(), D = double(in.height()) * in.width() * in.channels();
  c = std::min(c, std::max(L - 1, 0.0));
  return V * (D + c * (D + L)) * (o.storage == CodecStorage::kHalf ? 2 : 4);
}

double LpcaBytes(const CompressOptions& o, const SlotSource& in, double c) {
  const double T = double(in.height()) * in.width(), K = std::min<double>(o.clusters, T);
  const double d = double(in.views().size()) * in.lights().size() * in.channels();
  return (K * (c + 1) * d + T * c) * (o.storage == CodecStorage::kHalf ? 2 : 4) + (T + K) * 4;
}

double FmfBytes(const CompressOptions& o, const SlotSource& in, double c) {
  const double T = double(in.height()) * in.width(), M = o.method == CodecMethod::kDfmf ? 3 : 1;
  const double rows = double(in.views().size()) * in.lights().size() * in.channels() / M;
  c = std::min({c, rows, T});
  return M * c * (rows + T + 1) * 4;
}

// Latent codes (or halves) at c values per texel, their scales and biases, the decoder at float32.
double NeuralBytes(const CompressOptions& o, const SlotSource& in, double c) {
  const double T = double(in.height()) * in.width();
  double params = 0, width = c + DirectionEncoding{true, o.neural.fourier}.Width();
  for (const int h : o.neural.hidden) params += double(h) * (width + 1), width = h;
  params += double(in.channels()) * (width + 1);
  const double latents = o.neural.latent_storage == "half" ? 2 * T * c : T * c + 8 * c;
  return latents + 4 * params;
}

const MethodEntry kMethods[] = {
    {CodecMethod::kPcaView, &CompressPcaView, &PcaViewBytes, true},
    {CodecMethod::kLpca, &CompressLpca, &LpcaBytes, false},
    {CodecMethod::kLpcaTensor, &CompressLpcaTensor, nullptr, false},
    {CodecMethod::kFmf, &CompressFmf, &FmfBytes, false},
    {CodecMethod::kDfmf, &CompressFmf, &FmfBytes, false},
    {CodecMethod::kNeural, &CompressNeural, &NeuralBytes, false},
};

}  // namespace

void MethodContext::Warn(CompressSummary& summary, const std::string& warning) const {
  // Once: a method that starts again (LPCA on a float matrix) meets its early warnings twice.
  if (std::find(summary.warnings.begin(), summary.warnings.end(), warning) != summary.warnings.end()) return;
  summary.warnings.push_back(warning);
  if (ranks.rank() == 0) reporter.Warn("{}", warning);  // the same on every rank: reported once
}

const MethodEntry& FindMethod(CodecMethod method) {
  for (const MethodEntry& e : kMethods)
    if (e.method == method) return e;
  BTF_CHECK(false && "every CodecMethod has an entry");
  return kMethods[0];
}

void FillErrors(const ErrorStats& e, CompressSummary& s) {
  s.rmse = e.Rmse();
  s.relative_error = e.RelativeL2().value_or(0.0);
  s.max_abs_error = e.max_abs_error;
  s.psnr_peak = e.max_abs_reference;
  s.psnr_db = e.PsnrDb(e.max_abs_reference).value_or(std::numeric_limits<double>::infinity());
  if (const std::string w = e.PeakDominance(); !w.empty()) s.warnings.push_back(w);
}

ErrorStats MeasureErrors(const SlotSource& in, const Codec& codec, const dist::Context& ranks) {
  const int V = in.views().size(), L = in.lights().size();
  const std::size_t image = in.image_size();
  std::vector<ErrorStats> per_image(std::size_t(V) * L);
  std::vector<float> ref(in.slot_size()), dec(in.slot_size());
  for (int v = 0; v < V; ++v) {
    if (!ranks.Owns(v)) continue;
    in.ReadViewSlot(v, ref.data());
    codec.DecodeViewSlot(v, dec.data());
#pragma omp parallel for schedule(static)
    for (int l = 0; l < L; ++l)
      per_image[std::size_t(v) * L + l].Add(ref.data() + l * image, dec.data() + l * image, image);
  }
  if (ranks.distributed()) {
    std::vector<ErrorStats> mine;
    for (int v = ranks.rank(); v < V; v += ranks.size())
      mine.insert(mine.end(), per_image.begin() + std::ptrdiff_t(v) * L, per_image.begin() + std::ptrdiff_t(v + 1) * L);
    const std::vector<ErrorStats> all = ranks.AllGatherConcat(mine);
    std::size_t at = 0;
    for (int r = 0; r < ranks.size(); ++r)
      for (int v = r; v < V; v += ranks.size())
        for (int l = 0; l < L; ++l) per_image[std::size_t(v) * L + l] = all[at++];
    BTF_CHECK(at == all.size());
  }
  ErrorStats err;
  for (const auto& e : per_image) err.Merge(e);
  return err;
}

PcaRequest MakeRequest(const CompressOptions& o, std::uint64_t seed_offset) {
  PcaRequest q;
  q.max_components = o.components;
  q.target_error = o.target_error;
  q.retained_energy = o.retained_energy;
  q.gram_limit = o.lpca.gram_limit;
  q.seed = o.seed * 0x9E3779B97F4A7C15ull + seed_offset;
  return q;
}

}  // namespace btf
