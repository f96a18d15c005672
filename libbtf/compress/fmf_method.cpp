// Bonn's full-matrix factorisations as a method (fmf_codec.h): the streaming SVD of the whole
// BTF, then the errors of the decoded codec.
#include <algorithm>

#include "libbtf/compress/fmf_codec.h"
#include "libbtf/compress/method.h"
#include "libbtf/core/timer.h"

namespace btf {

std::uint64_t CompressFmf(const MethodContext& ctx, Codec& codec, CompressSummary& sum) {
  const SlotSource& in = ctx.input;
  const CompressOptions& o = ctx.options;
  FmfSvdOptions so;
  so.decorrelate = o.method == CodecMethod::kDfmf;
  so.components = o.components;
  so.seed = o.seed;
  so.target_error = o.target_error;
  so.retained_energy = o.retained_energy;
  const double rows = double(in.views().size()) * in.lights().size() * (so.decorrelate ? 1 : in.channels());
  const double rank = std::min(rows, double(in.width()) * in.height());
  if (o.components > rank)
    ctx.Warn(sum, fmt::format("components {} clamped to {} (the rank bound min(directions{}, texels))", o.components,
                              rank, so.decorrelate ? "" : " x channels"));
  Timer t;
  int dropped = 0;
  FmfModel& model = CodecBuilder::fmf(codec);
  model = FactoriseFmf(so, in, ctx.transform, ctx.reporter, &dropped, ctx.ranks);
  sum.times.Add("factorise", t.Seconds());
  for (const auto& m : model.matrices) sum.slot_components.push_back(m.components);
  if (dropped > 0) {
    sum.warnings.push_back(fmt::format("{} components with ~0 singular value dropped (rank-deficient data)", dropped));
    ctx.reporter.Info("{}", sum.warnings.back());
  }
  t.Restart();
  FillErrors(MeasureErrors(in, codec, ctx.ranks), sum);
  sum.times.Add("evaluate", t.Seconds());
  return 0;
}

}  // namespace btf
