// LPCA with factorised Eigen-ABRDFs (lpca_tensor.h): LPCA, then FactoriseLpca. With --error (and
// no log transform) the codec's measured error is held to the target: quantisation adds error the
// prediction leaves out, so while the measured error is above the target the prediction's target
// is lowered by the gap (at most kTensorRounds factorisations).
#include <cmath>

#include "libbtf/compress/lpca_internal.h"
#include "libbtf/core/timer.h"

namespace btf {

std::uint64_t CompressLpcaTensor(const MethodContext& ctx, Codec& codec, CompressSummary& sum) {
  constexpr int kTensorRounds = 4;
  const SlotSource& in = ctx.input;
  const CompressOptions& o = ctx.options;
  CompressOptions lo = o;
  lo.method = CodecMethod::kLpca;
  lo.target_error = 0, lo.retained_energy = 0, lo.max_bytes = 0;
  Codec stage = CodecBuilder::Make(CodecMethod::kLpca, in.views(), in.lights(), in.height(), in.width(), in.channels(),
                                   in.info(), codec.value_map());
  const MethodContext stage_ctx{in, lo, ctx.transform, ctx.ranks, ctx.reporter, nullptr};
  const lpca::LpcaEnergies energies = lpca::RunLpca(stage_ctx, stage, sum, false);
  const double total = energies.total, residual = energies.residual;
  sum.lpca_stage_error = total > 0 ? std::sqrt(residual / total) : 0;
  sum.quant_bits = o.tensor.quant_bits;
  TensorRequest q;
  q.bits = o.tensor.quant_bits, q.target_error = o.target_error, q.max_bytes = o.max_bytes, q.growth = o.tensor.growth;
  LpcaTensorModel& m = CodecBuilder::lpca_tensor(codec);
  ErrorStats e;
  bool all_kept = false;
  for (int round = 0; round < kTensorRounds; ++round) {
    Timer t;
    sum.predicted_error = FactoriseLpca(stage.lpca(), in.views().size(), in.lights().size(), in.channels(), total,
                                        residual, q, m);
    sum.times.Add("factorise", t.Seconds());
    t.Restart();
    e = MeasureErrors(in, codec, ctx.ranks);
    sum.times.Add("evaluate", t.Seconds());
    const double measured = e.RelativeL2().value_or(0.0);
    ctx.reporter.Info("lpca-tensor: {} terms, predicted relative error {:.6g}, measured {:.6g}", m.terms(),
                      sum.predicted_error, measured);
    if (!(o.target_error > 0) || ctx.transform.log() || measured <= o.target_error || all_kept) break;
    const double gap = std::max(0.0, measured * measured - sum.predicted_error * sum.predicted_error);
    const double t2 = o.target_error * o.target_error - gap;
    // At or below the LPCA stage's error: every term (a tiny positive target keeps them all).
    all_kept = !(t2 > residual / total);
    q.target_error = all_kept ? 1e-150 : std::sqrt(t2);
  }
  if (o.target_error > 0 && !ctx.transform.log() && e.RelativeL2().value_or(0.0) > o.target_error) {
    sum.warnings.push_back(fmt::format("lpca-tensor: relative error {:.6g} above --error {} (the LPCA stage alone has "
                                       "{:.6g}; raise --components or --clusters)",
                                       e.RelativeL2().value_or(0.0), o.target_error, sum.lpca_stage_error));
    ctx.reporter.Warn("{}", sum.warnings.back());
  }
  sum.tensor_terms = static_cast<int>(m.terms());
  FillErrors(e, sum);
  return 0;
}

}  // namespace btf
