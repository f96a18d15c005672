// A UBO2014-size DFMF (151 x 151 directions, 400 x 400 texels, 3 channels, 4 half components per
// channel), hand-built: btf-info's header pass and one decoded view slot, timed.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>

#include "libbtf/io/bonn.h"
#include "tests/io/bonn_test.h"
#include "tests/test_util.h"

namespace btf {
namespace {

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(BonnSlow, Ubo2014SizeDfmfHeaderInUnderASecondAndOneSlotAtATime) {
  const Sampling dome = Sampling::Ubo151();
  const int n = dome.size(), w = 400, h = 400, k = 4;
  test::Layout L;
  test::Bytes f;
  f.Text("!DFMF08FCR").Append(test::Meta(L)).U32(std::uint32_t(n));
  for (int v = 0; v < n; ++v) {
    const Angles a = dome.angles(v);
    f.F32(float(a.theta)).F32(float(a.phi)).U32(std::uint32_t(n));
    for (int l = 0; l < n; ++l) f.F32(float(dome.angles(l).theta)).F32(float(dome.angles(l).phi));
  }
  f.U32(w).U32(h).U32(0).U32(k).I32(11);
  for (int i = 0; i < 12; ++i) f.F32(i < 3 ? 0.0f : float(i % 4 == 3));
  for (int c = 0; c < 3; ++c) {
    f.U8(2).U32(k).U32(std::uint32_t(n * n)).U32(std::uint32_t(w * h));
    for (int i = 0; i < k; ++i) f.U16(0x3c00);
    for (int i = 0; i < n * n * k; ++i) f.U16(0x2e66);  // 0.1
    for (int i = 0; i < w * h * k; ++i) f.U16(0x3400);  // 0.25
  }
  const auto path = test::TempDir() / "ubo.btf";
  f.Save(path);
  auto t0 = std::chrono::steady_clock::now();
  const auto j = DescribeBonnFile(path, /*with_stats=*/false);
  const double describe = Seconds(t0);
  EXPECT_EQ(j["shape"]["views"], 151);
  EXPECT_LT(describe, 1.0);
  t0 = std::chrono::steady_clock::now();
  const auto src = OpenBonnSource(path);
  const double open = Seconds(t0);
  std::vector<float> slot(src->slot_size());
  t0 = std::chrono::steady_clock::now();
  src->ReadViewSlot(150, slot.data());
  const double decode = Seconds(t0);
  // Y' = 4 * 0.1 * 0.25 = 0.1 at every texel; U' = V' = 0.1 as well.
  const double y = std::exp(0.1) - 1e-5;
  EXPECT_NEAR(slot[0], y + 1.13983 * 0.1 * (y + 1e-5), 2e-3);  // half factors: 0.1 is 0.0999756
  std::printf("file %zu bytes; describe (header only) %.3f s; open (factors loaded) %.3f s; one view slot "
              "(%zu floats, %.0f MiB) %.3f s\n",
              f.size(), describe, open, slot.size(), double(slot.size()) * 4 / (1 << 20), decode);
}

}  // namespace
}  // namespace btf
