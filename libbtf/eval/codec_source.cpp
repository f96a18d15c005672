#include "libbtf/eval/codec_source.h"

#include "libbtf/core/error.h"

namespace btf {

namespace {

class CodecSlotSource final : public SlotSource {
 public:
  // Either owns the codec (read from a file) or borrows one.
  CodecSlotSource(std::unique_ptr<Codec> owned, const Codec* borrowed, std::string name)
      : owned_(std::move(owned)), codec_(owned_ ? *owned_ : *borrowed), name_(std::move(name)) {}
  const std::string& name() const override { return name_; }
  std::string kind() const override { return kCodecFormat; }
  const Sampling& views() const override { return codec_.views(); }
  const Sampling& lights() const override { return codec_.lights(); }
  int height() const override { return codec_.height(); }
  int width() const override { return codec_.width(); }
  int channels() const override { return codec_.channels(); }
  DatasetInfo info() const override { return codec_.info(); }
  void ReadViewSlot(int view, float* out) const override { codec_.DecodeViewSlot(view, out); }
  void ReadImage(int view, int light, float* out) const override { codec_.DecodeImage(view, light, out); }

 private:
  std::unique_ptr<Codec> owned_;
  const Codec& codec_;
  std::string name_;
};

class CodecBtfEvaluator final : public BtfEvaluator {
 public:
  explicit CodecBtfEvaluator(const Codec& c) : c_(c) {}
  int channels() const override { return c_.channels(); }
  bool cos_theta_i_included() const override { return c_.info().cos_theta_i_included; }
  void Eval(const Vec2& uv, const Vec3& wi, const Vec3& wo, float* out) const override {
    c_.Value(uv, wi, wo, out, UvFilter::kNearest);
  }

 private:
  const Codec& c_;
};

}  // namespace

std::unique_ptr<SlotSource> OpenCodecSource(const std::filesystem::path& path) {
  return std::make_unique<CodecSlotSource>(std::make_unique<Codec>(ReadCodec(path)), nullptr, path.string());
}

std::unique_ptr<SlotSource> CodecSource(const Codec& codec, std::string name) {
  return std::make_unique<CodecSlotSource>(nullptr, &codec, std::move(name));
}

std::unique_ptr<BtfEvaluator> CodecEvaluator(const Codec& codec) { return std::make_unique<CodecBtfEvaluator>(codec); }

}  // namespace btf
