// A UBO2014-size DFMF (151 x 151 directions, 400 x 400 texels, 3 channels) made by our writer
// (WriteFmf of a dfmf codec with known factors): btf-info's header pass, the decoded values, and
// the memory pca-view needs per view slot of it (ru_maxrss), printed for docs/format.md.
#include <gtest/gtest.h>
#include <omp.h>
#include <sys/resource.h>

#include <chrono>
#include <cstdio>

#include "libbtf/compress/bonn_fmf.h"
#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/io/bonn.h"
#include "tests/test_util.h"

namespace btf {
namespace {

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double PeakMiB() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024;  // kB on Linux
}

// The first `n` view slots of a source (pca-view's memory per slot does not depend on V).
class FirstViews final : public SlotSource {
 public:
  FirstViews(const SlotSource& in, int n) : in_(in), views_(in.views()) {
    std::vector<int> keep(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) keep[std::size_t(i)] = i;
    views_ = in.views().Subset(keep);
  }
  const std::string& name() const override { return in_.name(); }
  std::string kind() const override { return in_.kind(); }
  const Sampling& views() const override { return views_; }
  const Sampling& lights() const override { return in_.lights(); }
  int height() const override { return in_.height(); }
  int width() const override { return in_.width(); }
  int channels() const override { return in_.channels(); }
  DatasetInfo info() const override { return in_.info(); }
  void ReadViewSlot(int v, float* out) const override { in_.ReadViewSlot(v, out); }

 private:
  const SlotSource& in_;
  Sampling views_;
};

TEST(FmfSlow, Ubo2014SizeDfmfByOurWriterInBtfInfoAndPcaViewPerSlotMemory) {
  const Sampling dome = Sampling::Ubo151();
  const int n = dome.size(), w = 400, h = 400, k = 4;
  Codec codec = CodecBuilder::Make(CodecMethod::kDfmf, dome, dome, h, w, 3, DatasetInfo{}, ValueMap{});
  FmfModel& m = CodecBuilder::fmf(codec);
  m.decorrelated = true;
  m.lights = n;
  m.channels = 3;
  m.texels = std::size_t(w) * h;
  for (int c = 0; c < 3; ++c) {
    FmfMatrix f;
    f.components = k;
    f.singular_values.assign(k, 1.0f);
    for (std::size_t r = 0; r < std::size_t(n) * n; ++r)
      for (int j = 0; j < k; ++j) f.u.push_back(0.01f * float(1 + (r + std::size_t(j + c)) % 7));
    for (std::size_t t = 0; t < m.texels; ++t)
      for (int j = 0; j < k; ++j) f.sxv.push_back(0.25f * float(1 + (3 * t + std::size_t(j)) % 5));
    m.matrices.push_back(std::move(f));
  }
  const auto path = test::TempDir() / "ubo2014.btf";
  auto t0 = std::chrono::steady_clock::now();
  const ConvertSummary written = WriteFmf(codec, "synthetic UBO2014-size dfmf codec", path);
  const double write = Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  const auto j = DescribeBonnFile(path, /*with_stats=*/false);
  const double describe = Seconds(t0);
  EXPECT_EQ(j["format"], "bonn-dfmf");
  EXPECT_EQ(j["shape"]["views"], 151);
  EXPECT_EQ(j["shape"]["width"], 400);
  EXPECT_LT(describe, 1.0);  // the bound: btf-info reads it in under a second
  const auto src = OpenBonnSource(path);
  // pca-view of its first 3 view slots on one thread (P = 1): the peak resident memory above
  // what the process held with the file open (its factors loaded), in view slots (276 MiB).
  omp_set_num_threads(1);
  const double slot_mib = double(src->slot_size()) * 4 / (1 << 20), before = PeakMiB();
  CompressOptions o;
  o.components = 4;
  Codec pca;
  t0 = std::chrono::steady_clock::now();
  const CompressSummary s = Compress(o, FirstViews(*src, 3), &pca);
  const double compress = Seconds(t0);
  const double after = PeakMiB();
  EXPECT_EQ(s.views, 3);
  // Every light's image combines 12 fixed images (4 per YUV channel): 4 centred components of
  // smooth, positive data leave a small error (printed; the bound is loose on purpose).
  EXPECT_LT(s.relative_error, 0.05);
  // The file decodes like the codec (the reader's YUV inverse has 5-6 digits: 1e-4 of ~0.5).
  std::vector<float> a(src->slot_size()), b(src->slot_size());
  src->ReadViewSlot(150, a.data());
  codec.DecodeViewSlot(150, b.data());
  double err = 0;
  for (std::size_t i = 0; i < a.size(); ++i) err = std::max(err, double(std::abs(a[i] - b[i])));
  EXPECT_LT(err, 1e-4);
  std::printf("file %llu bytes, written in %.2f s; describe (header only) %.3f s; one view slot %.0f MiB; pca-view of "
              "3 slots on 1 thread %.1f s (relative error %.3g); peak RSS %.0f MiB before, %.0f MiB after (+%.0f MiB = %.2f slots)\n",
              static_cast<unsigned long long>(written.bytes_written), write, describe, slot_mib, compress, s.relative_error,
              before, after,
              after - before, (after - before) / slot_mib);
  // The bound, one view slot plus the factors: a source that computes its slots is read
  // in turn (no slot read ahead) and decoded a block of texels at a time (no per-channel
  // product), so pca-view holds the slot it decomposes plus its models (mean, 4 basis images
  // and weights per slot: 0.03 slot each) and the decode's 4096-texel blocks. Measured 1.10.
  EXPECT_LT(after - before, 1.25 * slot_mib);
}

}  // namespace
}  // namespace btf
