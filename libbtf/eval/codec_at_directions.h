#pragma once
// A codec decoded at another BTF's directions (docs/btf-eval.md, "compare"): what btf-eval compare
// measures when the test is a codec whose view and light samplings differ from the reference's,
// e.g. a codec trained on a subset of the directions compared with the ground truth at the others.
#include <memory>
#include <string>

#include "libbtf/compress/codec.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// View slot v, light l, texel (y, x) is Codec::Value at the centre of texel (y, x) with the nearest
// uv filter (so texels map 1:1), light direction lights[l] and view direction views[v]: for the
// neural codec its decoder at those directions; for the linear codecs the barycentric blend of
// the three nearest sampled view and light directions (9 pairs) that Value makes. Decoded one
// view slot at a time (neural: every texel and light in one batch; linear: the sampled view slots
// the blend needs, decoded whole), so a slot costs about what Codec::DecodeViewSlot does.
// The codec must outlive the source.
class CodecAtDirections final : public SlotSource {
 public:
  CodecAtDirections(const Codec& codec, Sampling views, Sampling lights, std::string name);

  const std::string& name() const override { return name_; }
  std::string kind() const override { return kCodecFormat; }
  const Sampling& views() const override { return views_; }
  const Sampling& lights() const override { return lights_; }
  int height() const override { return codec_.height(); }
  int width() const override { return codec_.width(); }
  int channels() const override { return codec_.channels(); }
  DatasetInfo info() const override { return codec_.info(); }
  void ReadViewSlot(int view, float* out) const override;

 private:
  const Codec& codec_;
  Sampling views_, lights_;
  std::string name_;
};

// True when both samplings hold the same directions (to 1e-6, CheckCompatible's tolerance).
bool SameDirections(const Sampling& a, const Sampling& b);

// When `test` is a codec (CodecSource) with the reference's shape (texels, channels) but other
// view or light directions: the codec decoded at the reference's directions (CodecAtDirections,
// named like `test`). Otherwise nullptr (compare `test` as it is; Compare refuses other samplings).
std::unique_ptr<SlotSource> CodecAtReferenceDirections(const SlotSource& reference, const SlotSource& test);

}  // namespace btf
