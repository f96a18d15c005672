#include "libbtf/io/slot_source.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"

namespace btf {

void SlotSource::ReadImage(int view, int light, float* out) const {
  std::vector<float> slot(slot_size());
  ReadViewSlot(view, slot.data());
  std::copy_n(slot.data() + std::size_t(light) * image_size(), image_size(), out);
}

namespace {

class MemorySlotSource final : public SlotSource {
 public:
  MemorySlotSource(const Dataset& d, std::string name) : d_(d), name_(std::move(name)) {}
  const std::string& name() const override { return name_; }
  std::string kind() const override { return "memory"; }
  const Sampling& views() const override { return d_.views(); }
  const Sampling& lights() const override { return d_.lights(); }
  int height() const override { return d_.height(); }
  int width() const override { return d_.width(); }
  int channels() const override { return d_.channels(); }
  DatasetInfo info() const override { return d_.info(); }
  void ReadViewSlot(int view, float* out) const override {
    const auto s = d_.view_slot(view);
    std::copy(s.begin(), s.end(), out);
  }
  const float* ViewSlotData(int view) const override { return d_.view_slot(view).data(); }
  void ReadImage(int view, int light, float* out) const override {
    const auto s = d_.image(view, light);
    std::copy(s.begin(), s.end(), out);
  }

 private:
  const Dataset& d_;
  std::string name_;
};

class FileSlotSource final : public SlotSource {
 public:
  FileSlotSource(const std::filesystem::path& path, const DatasetReadOptions& options)
      : reader_(path, options), name_(path.string()) {}
  const std::string& name() const override { return name_; }
  std::string kind() const override { return kDatasetFormat; }
  const Sampling& views() const override { return reader_.header().views; }
  const Sampling& lights() const override { return reader_.header().lights; }
  int height() const override { return reader_.header().height; }
  int width() const override { return reader_.header().width; }
  int channels() const override { return reader_.header().channels; }
  DatasetInfo info() const override { return reader_.header().info; }
  void ReadViewSlot(int view, float* out) const override { reader_.ReadViewSlot(view, out); }
  void ReadImage(int view, int light, float* out) const override { reader_.ReadImage(view, light, out); }
  std::vector<std::pair<int, int>> missing() const override { return reader_.header().missing; }

 private:
  DatasetReader reader_;
  std::string name_;
};

void CheckSamplingsEqual(const SlotSource& a, const SlotSource& b, const Sampling& sa, const Sampling& sb,
                         const char* what) {
  if (sa.size() != sb.size())
    ThrowBadInput("'{}' has {} {} directions but '{}' has {}: compare BTFs sampled on the same directions",
                  b.name(), sb.size(), what, a.name(), sa.size());
  for (int i = 0; i < sa.size(); ++i)
    if ((sa[i] - sb[i]).norm() > 1e-6) {
      const Angles pa = sa.angles(i), pb = sb.angles(i);
      ThrowBadInput(
          "{} direction {} differs: '{}' has (theta {:.4f}, phi {:.4f}) deg, '{}' has (theta {:.4f}, phi {:.4f}) deg; "
          "compare BTFs sampled on the same directions",
          what, i, a.name(), RadToDeg(pa.theta), RadToDeg(pa.phi), b.name(), RadToDeg(pb.theta), RadToDeg(pb.phi));
    }
}

}  // namespace

std::unique_ptr<SlotSource> MemorySource(const Dataset& dataset, std::string name) {
  return std::make_unique<MemorySlotSource>(dataset, std::move(name));
}

std::unique_ptr<SlotSource> OpenDatasetSource(const std::filesystem::path& path, const DatasetReadOptions& options) {
  return std::make_unique<FileSlotSource>(path, options);
}

void CheckCompatible(const SlotSource& ref, const SlotSource& test) {
  if (ref.height() != test.height() || ref.width() != test.width() || ref.channels() != test.channels())
    ThrowBadInput("'{}' has {}x{} texels x {} channels but '{}' has {}x{} x {}: shapes must match", test.name(),
                  test.width(), test.height(), test.channels(), ref.name(), ref.width(), ref.height(), ref.channels());
  CheckSamplingsEqual(ref, test, ref.views(), test.views(), "view");
  CheckSamplingsEqual(ref, test, ref.lights(), test.lights(), "light");
}

void CheckFiniteSlot(const SlotSource& source, int view, const float* slot) {
  const std::size_t n = source.slot_size();
  for (std::size_t i = 0; i < n; ++i) {
    if (std::isfinite(slot[i])) continue;
    const std::size_t c = i % source.channels();
    const std::size_t x = (i / source.channels()) % source.width();
    const std::size_t y = (i / (std::size_t(source.channels()) * source.width())) % source.height();
    const std::size_t l = i / source.image_size();
    ThrowBadInput("'{}' holds {} at view {}, light {}, texel (y {}, x {}), channel {}: values must be finite; fix or "
                  "regenerate this input",
                  source.name(), std::isnan(slot[i]) ? "NaN" : "Inf", view, l, y, x, c);
  }
}

}  // namespace btf
