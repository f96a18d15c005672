// Issue 5 "done when": codecs on a btf-synth twill BTF (bonn81 x bonn81, 64 x 64 texels).
// Slow (the generation alone takes about a minute on 2 cores): label "slow".
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <random>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/compress.h"
#include "libbtf/export/schneider.h"
#include "libbtf/export/schneider_reference_decoder.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/synth/btf_generator.h"
#include "libbtf/synth/model.h"
#include "tests/codec_util.h"
#include "tests/synth_util.h"
#include "tests/test_util.h"

namespace btf {
namespace {

const Dataset& Twill() {
  static const Dataset d = [] {
    const auto model = MakeModel("irawan2006", "twill", nlohmann::json::object());
    BtfOptions o;
    o.resolution = 64;
    o.samples = 2;  // 2 x 2 supersampling keeps generation near a minute
    return test::GenerateDataset(*model, o);
  }();
  return d;
}

double RelErr(const Dataset& a, const Dataset& b) {
  double e = 0, n = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double d = double(b.data()[i]) - a.data()[i];
    e += d * d, n += double(a.data()[i]) * a.data()[i];
  }
  return std::sqrt(e / n);
}

TEST(TwillDoneWhen, PerViewPca16RoundTripsAndMoreComponentsNeverHurt) {
  const Dataset& d = Twill();
  const auto path = test::TempDir() / "pv.h5";
  double previous = 1e9;
  for (int c : {4, 8, 16}) {
    CompressOptions o;
    o.components = c;
    CompressSummary s;
    const Codec codec = test::CompressDataset(d, o, &s);
    EXPECT_LE(s.relative_error, previous * (1 + 1e-9)) << "c = " << c;
    previous = s.relative_error;
    if (c != 16) continue;
    WriteCodec(path, codec);
    const double e = RelErr(d, ReadCodec(path).DecodeAll());
    EXPECT_NEAR(e, s.relative_error, 1e-6);
    // Measured 0.0514 on this twill (btf-compress on a 4x4-supersampled twill64: 0.05136, docs);
    // bound with ~2x margin. Ratio: 81 x (17 x 12288 + 81 x 16) floats vs 81 x 81 x 12288.
    EXPECT_LT(e, 0.10);
    EXPECT_GT(s.ratio_float32, 4.5);
  }
}

TEST(TwillDoneWhen, Lpca32x8RoundTripsAndMoreComponentsNeverHurt) {
  const Dataset& d = Twill();
  const auto path = test::TempDir() / "lpca.h5";
  double previous = 1e9;
  for (int c : {2, 4, 8}) {
    CompressOptions o;
    o.method = CodecMethod::kLpca;
    o.clusters = 32;
    o.components = c;
    o.lpca.max_iterations = 6;
    CompressSummary s;
    const Codec codec = test::CompressDataset(d, o, &s);
    EXPECT_LE(s.relative_error, previous * (1 + 1e-6)) << "c = " << c;
    previous = s.relative_error;
    // Each recorded round is no worse than the first (the kept fit is the best one).
    for (double e : s.iteration_errors) EXPECT_GT(e, 0);
    if (c != 8) continue;
    WriteCodec(path, codec);
    const Codec back = ReadCodec(path);
    const double e = RelErr(d, back.DecodeAll());
    EXPECT_NEAR(e, s.relative_error, 1e-6);
    EXPECT_LT(e, 0.15);  // bound with margin over the measured value (docs/btf-compress.md)
    // Export and reference decoder agree at grid nodes to the quantization bound.
    const auto dir = test::TempDir() / "export";
    SchneiderExportOptions eo;
    eo.view_grid = 8;
    eo.light_grid = 8;
    ExportSchneider(eo, back, dir);
    const SchneiderReferenceDecoder ref(dir);
    for (int y = 0; y < 64; y += 9)
      for (int x = 0; x < 64; x += 7) {
        const Vec3 wo = HemisphereFromSquare(Vec2(GridCoordinate(3, 8), GridCoordinate(5, 8)));
        const Vec3 wi = HemisphereFromSquare(Vec2(GridCoordinate(6, 8), GridCoordinate(2, 8)));
        float a[3], b[3];
        ref.Value(x, y, wi, wo, a);
        back.Value(Vec2((x + 0.5) / 64, 1 - (y + 0.5) / 64), wi, wo, b, UvFilter::kNearest);
        const double bound = ref.ErrorBound(x, y);
        for (int ch = 0; ch < 3; ++ch) EXPECT_LE(std::abs(a[ch] - b[ch]), bound + 1e-5);
      }
  }
}

// Issue 15 "done when": the reference written plainly, all in double. Texel-major matrix A
// (N x d), k-means++ seeds (seed 1), Lloyd k-means until no texel moves (distances
// ||x||^2 - 2 x.c + ||c||^2 by one product per round), then Kambhatla & Leen's local PCA (VQPCA):
// per cluster the eigen-decomposition of the centred members' Gram matrix (the top c
// eigenvectors span the best c-dimensional affine subspace), each texel to the cluster whose
// subspace reconstructs it best, until no texel moves or the error stops falling. Returns the
// relative error sqrt(sum residual^2 / sum x^2).
double PlainLloydThenLocalPca(const Dataset& d, int K, int c) {
  using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const int N = d.height() * d.width(), D = static_cast<int>(d.abrdf_size());
  RowMatrixXd A(N, D);
  for (int y = 0; y < d.height(); ++y)
    for (int x = 0; x < d.width(); ++x) {
      const auto a = d.Abrdf(y, x);
      for (int i = 0; i < D; ++i) A(y * d.width() + x, i) = a[static_cast<std::size_t>(i)];
    }
  const Eigen::VectorXd norms = A.rowwise().squaredNorm();
  const double energy = norms.sum();
  std::mt19937_64 rng(1);
  RowMatrixXd centers(K, D);
  std::vector<double> nearest(static_cast<std::size_t>(N), std::numeric_limits<double>::infinity());
  int pick = static_cast<int>(rng() % std::uint64_t(N));
  for (int k = 0; k < K; ++k) {
    centers.row(k) = A.row(pick);
    double sum = 0;
    for (int i = 0; i < N; ++i) sum += nearest[i] = std::min(nearest[i], (A.row(i) - centers.row(k)).squaredNorm());
    double u = std::uniform_real_distribution<double>(0, sum)(rng);
    for (pick = 0; pick + 1 < N && (u -= nearest[pick]) > 0; ++pick) {
    }
  }
  std::vector<int> assign(static_cast<std::size_t>(N), -1);
  for (bool moved = true; moved;) {
    moved = false;
    const Eigen::MatrixXd P = A * centers.transpose();
    const Eigen::VectorXd cn = centers.rowwise().squaredNorm();
    for (int i = 0; i < N; ++i) {
      int best = 0;
      for (int k = 1; k < K; ++k)
        if (cn[k] - 2 * P(i, k) < cn[best] - 2 * P(i, best)) best = k;
      moved |= best != assign[i];
      assign[i] = best;
    }
    RowMatrixXd sums = RowMatrixXd::Zero(K, D);
    std::vector<int> count(static_cast<std::size_t>(K), 0);
    for (int i = 0; i < N; ++i) sums.row(assign[i]) += A.row(i), ++count[assign[i]];
    for (int k = 0; k < K; ++k)
      if (count[k]) centers.row(k) = sums.row(k) / count[k];
  }
  double error = std::numeric_limits<double>::infinity();
  for (int round = 0; round < 100; ++round) {
    // Rows: the K means, then K x c basis vectors (zero where a cluster has fewer).
    RowMatrixXd B = RowMatrixXd::Zero(K * (c + 1), D);
    double residual = 0;
    for (int k = 0; k < K; ++k) {
      std::vector<int> m;
      for (int i = 0; i < N; ++i)
        if (assign[i] == k) m.push_back(i);
      if (m.empty()) continue;
      RowMatrixXd X(static_cast<Eigen::Index>(m.size()), D);
      for (std::size_t i = 0; i < m.size(); ++i) X.row(Eigen::Index(i)) = A.row(m[i]);
      B.row(k) = X.colwise().mean();
      X.rowwise() -= B.row(k);
      const Eigen::MatrixXd G = X * X.transpose();
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(G);  // eigenvalues ascending
      const int n = static_cast<int>(m.size()), ck = std::min(c, n - 1);
      double kept = 0;
      for (int j = 0; j < ck; ++j) {
        const double lambda = es.eigenvalues()[n - 1 - j];
        if (!(lambda > 1e-12 * G.trace())) break;
        kept += lambda;
        B.row(K + k * c + j) = (es.eigenvectors().col(n - 1 - j).transpose() * X) / std::sqrt(lambda);
      }
      residual += G.trace() - kept;
    }
    const double e = std::sqrt(std::max(residual, 0.0) / energy);
    if (!(e < error * (1 - 1e-6))) return std::min(e, error);
    error = e;
    const Eigen::MatrixXd P = A * B.transpose();
    bool moved = false;
    for (int i = 0; i < N; ++i) {
      double best = std::numeric_limits<double>::infinity();
      int arg = assign[i];
      for (int k = 0; k < K; ++k) {
        if (B.row(k).squaredNorm() == 0) continue;  // empty cluster
        double r = norms[i] - 2 * P(i, k) + B.row(k).squaredNorm();
        for (int j = 0; j < c; ++j) {
          const double proj = P(i, K + k * c + j) - B.row(K + k * c + j).dot(B.row(k));
          r -= proj * proj;
        }
        if (r < best) best = r, arg = k;
      }
      moved |= arg != assign[i];
      assign[i] = arg;
    }
    if (!moved) return error;
  }
  return error;
}

TEST(TwillDoneWhen, Lpca32x8IsNoWorseThanConvergedLloydPlusLocalPca) {
  const Dataset& d = Twill();
  CompressOptions o;
  o.method = CodecMethod::kLpca;
  o.clusters = 32;
  o.components = 8;
  CompressSummary s;
  test::CompressDataset(d, o, &s);
  const double reference = PlainLloydThenLocalPca(d, 32, 8);
  RecordProperty("lpca_relative_error", std::to_string(s.relative_error));
  RecordProperty("reference_relative_error", std::to_string(reference));
  std::printf("lpca k 32 c 8: ours %.6f, plain Lloyd + Kambhatla-Leen %.6f\n", s.relative_error, reference);
  // Ours is a float codec measured after decoding, the reference exact double arithmetic: the
  // float rounding of a ~1 value is ~1e-7 relative, far below 1e-4; so "no worse" within 1e-4.
  EXPECT_LE(s.relative_error, reference + 1e-4);
  // The same with mini-batch local-PCA rounds on a 2048-texel sample (half the texels) before
  // the rounds over all texels (--lpca-sample 2048); the same bound.
  o.lpca.sample = 2048;
  CompressSummary m;
  test::CompressDataset(d, o, &m);
  RecordProperty("lpca_sample_2048_relative_error", std::to_string(m.relative_error));
  std::printf("lpca k 32 c 8, --lpca-sample 2048: %.6f after %zu sample rounds and %zu full fits\n", m.relative_error,
              m.sample_errors.size(), m.iteration_errors.size());
  EXPECT_GE(m.sample_errors.size(), 2u);
  EXPECT_LE(m.relative_error, reference + 1e-4);
}

}  // namespace
}  // namespace btf
