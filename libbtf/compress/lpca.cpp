// Local PCA's driver (lpca_internal.h): read, cluster a sample, rounds over every texel, store,
// measure; and the lpca method.
#include <cmath>
#include <numeric>

#include "libbtf/compress/lpca_internal.h"
#include "libbtf/core/error.h"
#include "libbtf/core/timer.h"

namespace btf {
namespace lpca {

namespace {

class LpcaRun : public LpcaPhase {
 public:
  LpcaRun(const LpcaSetup& s)
      : LpcaPhase(s), setup_(s), K_(Clusters(s)), rows_(s), fitter_(s, rows_, K_) {}

  // measure = false: no error pass (lpca-tensor measures its own codec).
  LpcaEnergies Run(Codec& codec, bool measure) {
    Timer t;
    if (rows_.ooc_) {
      std::vector<double> all(N_);
      rows_.ForChunks([&] {
        std::copy(rows_.chunk_norms_.begin(), rows_.chunk_norms_.end(), all.begin() + std::ptrdiff_t(rows_.t0_));
      });
      rows_.SetNorms(all);
    } else {
      rows_.ReadTexelMajor();
    }
    sum_.times.Add("read", t.Seconds());
    ClusterFit fit = InitialClustering();
    t.Restart();
    fitter_.Iterate(fit);
    sum_.times.Add("iterate", t.Seconds());
    rows_.A_.Clear();  // the evaluation decodes the codec; the texel matrix is no longer needed
    fitter_.StoreModel(fit, codec);
    const LpcaEnergies energies{rows_.total_, fit.error * fit.error * rows_.total_};
    sum_.peak_rss_bytes = dist::PeakResidentBytes();
    if (!measure) return energies;
    t.Restart();
    FillErrors(MeasureErrors(in_, codec, ranks_), sum_);
    ++sum_.lpca_passes;
    sum_.times.Add("evaluate", t.Seconds());
    sum_.peak_rss_bytes = dist::PeakResidentBytes();
    return energies;
  }

 private:
  // The clusters k, clamped (with a warning) to the number of texels.
  int Clusters(const LpcaSetup& s) const {
    if (std::size_t(o_.clusters) <= s.N) return o_.clusters;
    Warn(fmt::format("clusters {} clamped to the number of texels {}", o_.clusters, s.N));
    return static_cast<int>(s.N);
  }

  // k-means on a sample: k-means++ seeds, then Lloyd rounds (means in double, summed in sample
  // order) until no sample texel moves, the k-means objective improves by less than
  // kLloydTolerance (relative) or kLloydRounds. Then local-PCA rounds and split/merge steps on the
  // sample alone (SampleRounds; the sample is every texel when there are no more than
  // lpca_sample), all in the sample's principal subspace where LpcaOptions::subspace applies (the
  // models then lifted to the full dimension), every texel to the cluster whose sample model
  // reconstructs it best, and the first per-cluster PCA of all texels.
  ClusterFit InitialClustering() {
    std::mt19937_64 rng(o_.seed);
    const LpcaSampler sampler(setup_, K_);
    const std::vector<std::size_t> sample = sampler.Sample(rng);
    const std::size_t S = sample.size();
    int rounds = 0;
    std::vector<PcaResult> models;  // the sample rounds' per-cluster models (no scores)
    std::vector<double> sample_errors, split_errors;
    // Phases: subspace (where LpcaOptions::subspace applies: the sample's coordinates, in which
    // k-means and the sample rounds then run), kmeans (the sample, seeds and Lloyd; on ranks other
    // than 0 also the wait for rank 0's sample rounds), sample_rounds, first_fit (the first
    // assignment of all texels and their PCA).
    Timer t;
    double kmeans_s = 0, subspace_s = 0;
    auto on_sample = [&](const auto& M, const double* norms, const std::vector<std::size_t>& rows) {
      std::vector<std::int32_t> assign;
      const int dims = o_.lpca.subspace;
      if (dims > 0 && 2 * std::size_t(dims) <= std::min(d_, rows.size())) {
        const SampleSubspace sub = sampler.Subspace(M, norms, rows, dims);
        if (sub.pca.components() > 0) {  // else no centred energy: the full dimension
          subspace_s = t.Seconds();
          LpcaSampler inner({setup_.ctx, setup_.sum, N_, std::size_t(sub.pca.components())}, K_);
          inner.SetOutside(sub.outside, sub.energy);
          std::vector<std::size_t> index(rows.size());
          std::iota(index.begin(), index.end(), std::size_t(0));
          rounds = inner.Lloyd(sub.Z, sub.norms.data(), index, rng, assign);
          kmeans_s = t.Seconds();
          models = inner.SampleRounds(sub.Z, sub.norms.data(), index, std::move(assign), sample_errors, split_errors);
          for (PcaResult& m : models) m = sub.Lift(m);
          return;
        }
      }
      rounds = sampler.Lloyd(M, norms, rows, rng, assign);
      kmeans_s = t.Seconds();
      models = sampler.SampleRounds(M, norms, rows, std::move(assign), sample_errors, split_errors);
    };
    if (R_ == 1 && !rows_.ooc_) {
      rows_.A_.Visit([&](const auto& M) { on_sample(M, rows_.norms_.data(), sample); });
    } else {  // the sample's rows gathered (by rank 0, or in one pass out of core): the same Lloyd
      const RowMatrixXf rows = rows_.ooc_ ? rows_.ReadSampleRows(sample) : rows_.GatherSampleRows(sample);
      if (rank_ == 0) {
        std::vector<std::size_t> index(S);
        std::iota(index.begin(), index.end(), std::size_t(0));
        std::vector<double> norms(S);
        for (std::size_t i = 0; i < S; ++i) norms[i] = rows_.norms_[static_cast<Eigen::Index>(sample[i])];
        on_sample(rows, norms.data(), index);
      }
      ranks_.Broadcast(0, &rounds, sizeof rounds);
      if (R_ > 1) {  // every rank reassigns its texels with the sample models
        models.resize(static_cast<std::size_t>(K_));
        for (int k = 0; k < K_; ++k) {
          auto bytes = ranks_.BroadcastBytes(0, rank_ == 0 ? PackPca(models[std::size_t(k)]) : std::vector<std::uint8_t>());
          if (rank_ != 0) models[std::size_t(k)] = UnpackPca(bytes);
        }
        dist::Packer pe;
        pe.PutVector(sample_errors);
        pe.PutVector(split_errors);
        const std::vector<std::uint8_t> errors = ranks_.BroadcastBytes(0, rank_ == 0 ? std::move(pe.bytes) : std::vector<std::uint8_t>());
        dist::Unpacker u(errors);  // holds a reference to the bytes
        sample_errors = u.GetVector<double>();
        split_errors = u.GetVector<double>();
      }
    }
    if (kmeans_s == 0) kmeans_s = t.Seconds();
    ReleaseFreeHeap();  // the sample's working arrays (core/memory.h)
    if (subspace_s > 0) sum_.times.Add("subspace", subspace_s);
    sum_.times.Add("kmeans", kmeans_s - subspace_s);
    sum_.times.Add("sample_rounds", t.Seconds() - kmeans_s);
    t.Restart();
    ClusterFit fit;
    fit.assign.assign(N_, 0);
    fitter_.Reassign(models, fit.assign);
    fitter_.FitClusters(fit, true, nullptr, &models, true);  // the sample's models, freed as they start fits
    sum_.times.Add("first_fit", t.Seconds());
    sum_.sample_errors = sample_errors;
    sum_.split_errors = split_errors;
    sum_.iteration_errors.push_back(fit.error);
    sum_.iteration_changes.push_back(0);
    rep_.Info("lpca: k-means on {} texels ({} Lloyd rounds), {} local-PCA rounds and {} split/merge trials on them, "
              "relative error {:.5f}",
              S, rounds, sample_errors.size() - 1, split_errors.size(), fit.error);
    return fit;
  }

  const LpcaSetup& setup_;
  const int K_;
  LpcaRows rows_;
  LpcaFitter fitter_;
};

}  // namespace

LpcaEnergies RunLpca(const MethodContext& ctx, Codec& codec, CompressSummary& sum, bool measure) {
  const SlotSource& in = ctx.input;
  const LpcaSetup setup{ctx, sum, std::size_t(in.height()) * in.width(),
                        std::size_t(in.views().size()) * in.lights().size() * in.channels()};
  try {
    return LpcaRun(setup).Run(codec, measure);
  } catch (const LpcaRows::HalfUnderflow& u) {
    // Before any phase's work but the first read: the run starts again on a float matrix.
    ctx.Warn(sum, fmt::format("{:.3g} of the data's energy lies below the half range's normal values (|x| < 6.1e-5, "
                              "after the transform) and would lose precision in a half texel matrix: used "
                              "--lpca-matrix float (4 bytes a value instead of 2; scale the data or use --log to keep half)",
                              u.share));
    CompressOptions o = ctx.options;
    o.lpca.matrix = "float";
    const MethodContext float_ctx{in, o, ctx.transform, ctx.ranks, ctx.reporter, ctx.writer};
    const LpcaSetup again{float_ctx, sum, setup.N, setup.d};
    return LpcaRun(again).Run(codec, measure);
  }
}

}  // namespace lpca

std::uint64_t CompressLpca(const MethodContext& ctx, Codec& codec, CompressSummary& sum) {
  lpca::RunLpca(ctx, codec, sum, true);
  return 0;
}

}  // namespace btf
