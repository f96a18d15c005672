#include "libbtf/register/tile_reconstruct.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <opencv2/calib3d.hpp>

#include "libbtf/core/error.h"

namespace btf {

void TileReconstructOptions::Check() const {
  BTF_CHECK_OPTION(std::isfinite(samples_per_texel) && samples_per_texel >= 1 && samples_per_texel <= 16,
                   "samples_per_texel", "1..16");
  BTF_CHECK_OPTION(pixel_samples >= 1 && pixel_samples <= 16, "pixel_samples", "1..16");
  BTF_CHECK_OPTION(std::isfinite(smoothness) && smoothness > 0 && smoothness <= 1, "smoothness", "0 < value <= 1");
}

namespace {

// Photo pixel -> plate point: Newton iterations on the plate -> pixel map from a start point.
class InverseMap {
 public:
  InverseMap(const PlateToPixel& project, double s) : project_(project) {
    // Start points from the least-squares homography pixel -> plate of a 17 x 17 grid on the sample.
    std::vector<cv::Point2d> px, plate;
    for (int j = 0; j <= 16; ++j)
      for (int i = 0; i <= 16; ++i) {
        const Vec2 p(-s / 2 + i * s / 16, -s / 2 + j * s / 16);
        Vec2 q;
        if (!project(p, &q)) continue;
        px.emplace_back(q.x(), q.y());
        plate.emplace_back(p.x(), p.y());
      }
    if (px.size() < 4) ThrowBadInput("tile reconstruction: the sample does not project into the photo");
    const cv::Mat H = cv::findHomography(px, plate, 0);
    if (H.empty()) ThrowBadInput("tile reconstruction: degenerate photo -> plate map");
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) start_(r, c) = H.at<double>(r, c);
  }

  // Plate point of pixel q and the Jacobian d pixel / d plate there; false if it does not converge.
  bool Invert(const Vec2& q, Vec2* p, Eigen::Matrix2d* jac) const {
    const Vec3 h = start_ * Vec3(q.x(), q.y(), 1);
    if (!(std::abs(h.z()) > 0)) return false;
    *p = h.head<2>() / h.z();
    const double d = 1e-4;  // mm
    for (int it = 0; it < 20; ++it) {
      Vec2 f, fx, fy;
      if (!project_(*p, &f) || !project_(*p + Vec2(d, 0), &fx) || !project_(*p + Vec2(0, d), &fy)) return false;
      jac->col(0) = (fx - f) / d;
      jac->col(1) = (fy - f) / d;
      const Vec2 r = f - q;
      if (r.norm() < 1e-7) return true;
      *p -= jac->inverse() * r;
    }
    return false;
  }

  // Refines p (near the answer) to the plate point of pixel q with a fixed inverse Jacobian from nearby.
  bool Refine(const Vec2& q, const Eigen::Matrix2d& jac_inv, Vec2* p) const {
    for (int it = 0; it < 20; ++it) {
      Vec2 f;
      if (!project_(*p, &f)) return false;
      const Vec2 r = f - q;
      if (r.norm() < 1e-7) return true;
      *p -= jac_inv * r;
    }
    return false;
  }

 private:
  const PlateToPixel& project_;
  Eigen::Matrix3d start_;
};

// Bilinear basis on the periodic T x T grid: the 4 nodes around (u, v) and their weights.
void PeriodicBilinear(const Vec2& uv, int T, int idx[4], double w[4]) {
  const int i0 = static_cast<int>(std::floor(uv.x())), j0 = static_cast<int>(std::floor(uv.y()));
  const double fu = uv.x() - i0, fv = uv.y() - j0;
  const int i1 = (i0 + 1 + T) % T, j1 = (j0 + 1 + T) % T, ia = (i0 + T) % T, ja = (j0 + T) % T;
  idx[0] = ja * T + ia, idx[1] = ja * T + i1, idx[2] = j1 * T + ia, idx[3] = j1 * T + i1;
  w[0] = (1 - fu) * (1 - fv), w[1] = fu * (1 - fv), w[2] = (1 - fu) * fv, w[3] = fu * fv;
}

// Plate (mm) -> tile grid coordinates (u, v) in [0, T), the sample of node i at u = i.
struct PlateToGrid {
  Eigen::Matrix2d Ainv;  // texels -> lattice coordinates
  Vec2 origin;           // a lattice node (texels)
  double S = 0, texel = 0;  // sample size and texel size (mm)
  int T = 0;

  Vec2 operator()(const Vec2& p) const {
    const Vec2 x((p.x() + S / 2) / texel - 0.5, (S / 2 - p.y()) / texel - 0.5);  // texel (col, row)
    Vec2 st = Ainv * (x - origin);
    st -= Vec2(st.array().floor());
    return Vec2(st.x() * T - 0.5, st.y() * T - 0.5);
  }
};

struct PixelBox {
  int x0 = 0, x1 = 0, y0 = 0, y1 = 0;  // inclusive
};

// Pixels to visit: the bounding box of the sample's projected border, clipped to the photo.
PixelBox SampleBoundingBox(const TilePhoto& in, const Image& im, double S) {
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (int k = 0; k < 4 * 64; ++k) {
    const double t = (k % 64) / 64.0 * S - S / 2;
    const Vec2 q = k < 64 ? Vec2(t, -S / 2) : k < 128 ? Vec2(S / 2, t) : k < 192 ? Vec2(-t, S / 2) : Vec2(-S / 2, -t);
    Vec2 px;
    if (!in.project(q, &px)) continue;
    xmin = std::min(xmin, px.x()), xmax = std::max(xmax, px.x()), ymin = std::min(ymin, px.y()), ymax = std::max(ymax, px.y());
  }
  PixelBox b;
  b.x0 = std::max(0, static_cast<int>(std::floor(xmin))), b.x1 = std::min(im.width - 1, static_cast<int>(std::ceil(xmax)));
  b.y0 = std::max(0, static_cast<int>(std::floor(ymin))), b.y1 = std::min(im.height - 1, static_cast<int>(std::ceil(ymax)));
  return b;
}

// The least-squares system of the tile's node values: A^T A, A^T b (per channel) and b^T b.
struct NormalEquations {
  Eigen::MatrixXd AtA, Atb;
  double btb = 0;
};

// One row per usable pixel on the sample: the pixel's footprint (K x K sub-samples mapped back to
// the plate) spread over the grid nodes, against its scaled value. Counts the pixels used and
// masked in *out.
NormalEquations AccumulatePixels(const TilePhoto& in, const PlateToGrid& grid, int K, const PixelBox& box,
                                 ReconstructedTile* out) {
  const Image& im = *in.photo;
  const int T = grid.T, M = T * T, C = im.channels;
  const double S = grid.S;
  const InverseMap inverse(in.project, S);
  NormalEquations ne{Eigen::MatrixXd::Zero(M, M), Eigen::MatrixXd::Zero(M, C), 0};
  std::vector<double> row(static_cast<std::size_t>(M), 0.0);
  std::vector<int> touched;
  std::vector<Vec2> sub(static_cast<std::size_t>(K) * K);
  auto on_sample = [&](const Vec2& p) { return std::abs(p.x()) <= S / 2 && std::abs(p.y()) <= S / 2; };
  for (int y = box.y0; y <= box.y1; ++y)
    for (int x = box.x0; x <= box.x1; ++x) {
      Vec2 pc;
      Eigen::Matrix2d jac;
      if (!inverse.Invert(Vec2(x, y), &pc, &jac) || !on_sample(pc)) continue;
      const Eigen::Matrix2d jinv = jac.inverse();
      bool usable = !(in.pixel_mask && (*in.pixel_mask)[std::size_t(y) * im.width + x]);
      bool inside = true;
      for (int k = 0; k < K * K && inside; ++k) {
        const Vec2 d((k % K + 0.5) / K - 0.5, (k / K + 0.5) / K - 0.5);  // offset in the pixel box, px
        Vec2 p = pc + jinv * d;
        inside = inverse.Refine(Vec2(x, y) + d, jinv, &p) && on_sample(p);
        usable = usable && !(in.hidden && in.hidden(p));
        sub[static_cast<std::size_t>(k)] = p;
      }
      if (!inside) continue;  // the footprint leaves the sample
      if (!usable) {
        ++out->pixels_masked;
        continue;
      }
      const double scale = in.scale ? in.scale(pc) : 1.0;
      if (!(std::isfinite(scale) && scale > 0)) ThrowBadInput("tile reconstruction: pixel ({}, {}) has no valid radiometric factor ({})", x, y, scale);
      touched.clear();
      for (const Vec2& p : sub) {
        int idx[4];
        double w[4];
        PeriodicBilinear(grid(p), T, idx, w);
        for (int k = 0; k < 4; ++k) {
          if (row[static_cast<std::size_t>(idx[k])] == 0 && w[k] != 0) touched.push_back(idx[k]);
          row[static_cast<std::size_t>(idx[k])] += w[k] / (K * K);
        }
      }
      for (int a : touched) {
        const double wa = row[static_cast<std::size_t>(a)];
        for (int b : touched) ne.AtA(a, b) += wa * row[static_cast<std::size_t>(b)];
        for (int c = 0; c < C; ++c) ne.Atb(a, c) += wa * scale * im.at(x, y, c);
      }
      for (int c = 0; c < C; ++c) ne.btb += std::pow(scale * im.at(x, y, c), 2);
      for (int a : touched) row[static_cast<std::size_t>(a)] = 0;
      ++out->pixels_used;
    }
  return ne;
}

// Periodic 5-point Laplacian rows on the T x T grid (neighbours merged where T < 3 folds them
// together), and the sum of their squared entries in *trace (the trace of L^T L).
std::vector<std::map<int, double>> PeriodicLaplacian(int T, double* trace) {
  std::vector<std::map<int, double>> lap(static_cast<std::size_t>(T) * T);
  *trace = 0;
  for (int j = 0; j < T; ++j)
    for (int i = 0; i < T; ++i) {
      auto& r = lap[static_cast<std::size_t>(j * T + i)];
      r[j * T + i] += 4;
      for (const int n : {j * T + (i + 1) % T, j * T + (i + T - 1) % T, ((j + 1) % T) * T + i, ((j + T - 1) % T) * T + i})
        r[n] -= 1;
      for (const auto& [n, w] : r) *trace += w * w;
    }
  return lap;
}

// The data residual of solution f: |A f - b|^2 = b^T b - 2 f^T A^T b + f^T (A^T A + lambda L^T L) f
// - lambda |L f|^2 per channel (ne.AtA holding the regularised matrix), summed over the channels.
double DataResidual(const NormalEquations& ne, const Eigen::MatrixXd& f, const std::vector<std::map<int, double>>& lap,
                    double lambda) {
  double rr = ne.btb;
  for (int c = 0; c < f.cols(); ++c) {
    rr += -2 * f.col(c).dot(ne.Atb.col(c)) + f.col(c).dot(ne.AtA * f.col(c));
    for (const auto& r : lap) {
      double lf = 0;
      for (const auto& [n, w] : r) lf += w * f(n, c);
      rr -= lambda * lf * lf;
    }
  }
  return rr;
}

// Each tile sample: the reconstructed function f (node values) averaged over the texel box around
// its node (16 x 16 midpoints), what a normtexture texel holds.
Image AverageOverTexels(const Eigen::MatrixXd& f, const Eigen::Matrix2d& Ainv, int T) {
  constexpr int B = 16;
  const int C = static_cast<int>(f.cols());
  Image tile(T, T, C);
  for (int j = 0; j < T; ++j)
    for (int i = 0; i < T; ++i) {
      const Vec2 node((i + 0.5) / T, (j + 0.5) / T);
      std::vector<double> acc(static_cast<std::size_t>(C), 0.0);
      for (int b = 0; b < B * B; ++b) {
        Vec2 st = node + Ainv * Vec2((b % B + 0.5) / B - 0.5, (b / B + 0.5) / B - 0.5);
        st -= Vec2(st.array().floor());
        int idx[4];
        double w[4];
        PeriodicBilinear(Vec2(st.x() * T - 0.5, st.y() * T - 0.5), T, idx, w);
        for (int k = 0; k < 4; ++k)
          for (int c = 0; c < C; ++c) acc[static_cast<std::size_t>(c)] += w[k] * f(idx[k], c);
      }
      for (int c = 0; c < C; ++c) tile.at(i, j, c) = static_cast<float>(std::max(0.0, acc[static_cast<std::size_t>(c)] / (B * B)));
    }
  return tile;
}

}  // namespace

ReconstructedTile ReconstructTile(const TilePhoto& in, const Lattice& L, const TileReconstructOptions& o) {
  o.Check();
  BTF_CHECK(in.photo && in.resolution > 0 && in.sample_size_mm > 0);
  const Image& im = *in.photo;
  BTF_CHECK(!in.pixel_mask || in.pixel_mask->size() == std::size_t(im.width) * im.height);
  Eigen::Matrix2d A;
  A << L.a1, L.a2;
  if (!(std::abs(A.determinant()) > 1)) ThrowBadInput("tile reconstruction: the unit tile is smaller than a texel");
  const Eigen::Matrix2d Ainv = A.inverse();
  const int T = static_cast<int>(std::ceil(o.samples_per_texel * std::max(L.a1.norm(), L.a2.norm())));
  const int M = T * T, C = im.channels;
  if (M > 4096)
    ThrowBadInput("tile reconstruction: a {} x {} tile grid ({} unknowns, the unit tile is {:.1f} x {:.1f} texels) is "
                  "over the limit of 4096 unknowns: lower --tile-samples-per-texel (now {})",
                  T, T, M, L.a1.norm(), L.a2.norm(), o.samples_per_texel);
  const double S = in.sample_size_mm;
  const PlateToGrid grid{Ainv, L.origin, S, S / in.resolution, T};

  ReconstructedTile out;
  NormalEquations ne = AccumulatePixels(in, grid, o.pixel_samples, SampleBoundingBox(in, im, S), &out);
  if (out.pixels_used < M)
    ThrowBadInput("tile reconstruction: {} usable pixels on the sample ({} masked) for a {} x {} tile grid ({} unknowns): "
                  "lower --tile-samples-per-texel (now {}) or use --tile-method average",
                  out.pixels_used, out.pixels_masked, T, T, M, o.samples_per_texel);

  // lambda L^T L is added to the normal matrix with the relative weight.
  double trace_l = 0;
  const std::vector<std::map<int, double>> lap = PeriodicLaplacian(T, &trace_l);
  const double lambda = o.smoothness * ne.AtA.trace() / trace_l;
  for (const auto& r : lap)
    for (const auto& [a, wa] : r)
      for (const auto& [b, wb] : r) ne.AtA(a, b) += lambda * wa * wb;
  const Eigen::LLT<Eigen::MatrixXd> llt(ne.AtA);
  if (llt.info() != Eigen::Success)
    ThrowBadInput("tile reconstruction: the normal equations are singular ({} pixels, {} unknowns): raise "
                  "--tile-smoothness (now {}) or use --tile-method average",
                  out.pixels_used, M, o.smoothness);
  const Eigen::MatrixXd f = llt.solve(ne.Atb);
  if (!f.allFinite()) ThrowBadInput("tile reconstruction: the solution is not finite: raise --tile-smoothness");
  const double rr = DataResidual(ne, f, lap, lambda);
  out.residual_rms = std::sqrt(std::max(0.0, rr) / (double(out.pixels_used) * C));
  out.tile.tile = AverageOverTexels(f, Ainv, T);
  return out;
}

}  // namespace btf
