#pragma once
// Test shorthands for the compression entry point (Compress writes the codec to an out-parameter).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/io/slot_source.h"

namespace btf::test {

// The stored arrays of two codecs are equal bit for bit (files also hold provenance and run
// times, so their bytes are not compared). `what` names the comparison in failures.
inline void ExpectSameCodec(const Codec& a, const Codec& b, const std::string& what = "") {
  ASSERT_EQ(a.method(), b.method()) << what;
  ASSERT_EQ(a.pca_view().size(), b.pca_view().size()) << what;
  for (std::size_t v = 0; v < a.pca_view().size(); ++v) {
    const PcaViewSlot &x = a.pca_view()[v], &y = b.pca_view()[v];
    EXPECT_EQ(x.components, y.components) << what << " slot " << v;
    EXPECT_TRUE(x.mean == y.mean && x.basis == y.basis && x.weights == y.weights && x.eigenvalues == y.eigenvalues)
        << what << " slot " << v;
  }
  const LpcaModel &x = a.lpca(), &y = b.lpca();
  EXPECT_EQ(x.clusters, y.clusters) << what;
  EXPECT_EQ(x.components, y.components) << what;
  EXPECT_TRUE(x.cluster_of == y.cluster_of) << what;
  EXPECT_TRUE(x.cluster_components == y.cluster_components) << what;
  EXPECT_TRUE(x.means == y.means && x.basis == y.basis && x.weights == y.weights) << what;
  const FmfModel &f = a.fmf(), &g = b.fmf();
  ASSERT_EQ(f.matrices.size(), g.matrices.size()) << what;
  for (std::size_t m = 0; m < f.matrices.size(); ++m) {
    const FmfMatrix &p = f.matrices[m], &q = g.matrices[m];
    EXPECT_EQ(p.components, q.components) << what << " matrix " << m;
    EXPECT_TRUE(p.singular_values == q.singular_values && p.u == q.u && p.sxv == q.sxv) << what << " matrix " << m;
  }
}

// max |a - b| / max |a| over every value of two view-slot sources.
inline double MaxRelativeError(const SlotSource& a, const SlotSource& b) {
  std::vector<float> x(a.slot_size()), y(b.slot_size());
  double err = 0, peak = 0;
  for (int v = 0; v < a.views().size(); ++v) {
    a.ReadViewSlot(v, x.data());
    b.ReadViewSlot(v, y.data());
    for (std::size_t i = 0; i < x.size(); ++i) {
      err = std::max(err, double(std::abs(x[i] - y[i])));
      peak = std::max(peak, double(std::abs(x[i])));
    }
  }
  return err / peak;
}

inline Codec CompressDataset(const Dataset& d, const CompressOptions& o, CompressSummary* summary = nullptr) {
  Codec codec;
  const CompressSummary s = Compress(o, *MemorySource(d), &codec);
  if (summary) *summary = s;
  return codec;
}

inline Codec CompressPath(const std::filesystem::path& path, const CompressOptions& o,
                          CompressSummary* summary = nullptr) {
  Codec codec;
  const CompressSummary s = Compress(o, *OpenDatasetSource(path), &codec);
  if (summary) *summary = s;
  return codec;
}

// Every decoder of a 3-channel codec against DecodeViewSlot: DecodeImage within image_tol (0 =
// bit-identical), DecodeAbrdf and Value (nearest texel, light 2, at the sampled directions) at
// the texels (x, y) of `texels` within tol.
inline void ExpectDecodersAgreeWithViewSlot(const Codec& c, double image_tol, double tol,
                                            const std::vector<std::pair<int, int>>& texels) {
  const int L = c.num_lights(), C = 3;
  const std::size_t image = c.image_size(), T = image / C;
  std::vector<float> slot(image * L), img(image);
  for (int v = 0; v < c.num_views(); ++v) {
    c.DecodeViewSlot(v, slot.data());
    for (int l = 0; l < L; ++l) {
      c.DecodeImage(v, l, img.data());
      for (std::size_t i = 0; i < image; ++i) ASSERT_NEAR(img[i], slot[l * image + i], image_tol) << v << " " << l;
    }
    for (const auto& [x, y] : texels) {
      const std::vector<float> a = c.DecodeAbrdf(y, x);
      for (int l = 0; l < L; ++l)
        for (int ch = 0; ch < C; ++ch)
          EXPECT_NEAR(a[(std::size_t(v) * L + l) * C + ch], slot[(l * T + std::size_t(y) * c.width() + x) * C + ch], tol);
      // At a sampled (wi, wo) and a texel centre, Value is that sample.
      const Vec2 uv((x + 0.5) / c.width(), 1.0 - (y + 0.5) / c.height());
      float out[3];
      c.Value(uv, c.lights()[2], c.views()[v], out, UvFilter::kNearest);
      for (int ch = 0; ch < C; ++ch) EXPECT_NEAR(out[ch], slot[(2 * T + std::size_t(y) * c.width() + x) * C + ch], tol);
    }
  }
}

}  // namespace btf::test
