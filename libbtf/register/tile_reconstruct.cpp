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
  const int M = T * T, C = im.channels, K = o.pixel_samples;
  if (M > 4096)
    ThrowBadInput("tile reconstruction: a {} x {} tile grid ({} unknowns, the unit tile is {:.1f} x {:.1f} texels) is "
                  "over the limit of 4096 unknowns: lower --tile-samples-per-texel (now {})",
                  T, T, M, L.a1.norm(), L.a2.norm(), o.samples_per_texel);
  const double S = in.sample_size_mm, texel = S / in.resolution;
  // Plate (mm) -> tile grid coordinates (u, v) in [0, T), the sample of node i at u = i.
  auto grid = [&](const Vec2& p) {
    const Vec2 x((p.x() + S / 2) / texel - 0.5, (S / 2 - p.y()) / texel - 0.5);  // texel (col, row)
    Vec2 st = Ainv * (x - L.origin);
    st -= Vec2(st.array().floor());
    return Vec2(st.x() * T - 0.5, st.y() * T - 0.5);
  };
  // Bilinear basis on the periodic grid: the 4 nodes around (u, v) and their weights.
  auto basis = [&](const Vec2& uv, int idx[4], double w[4]) {
    const int i0 = static_cast<int>(std::floor(uv.x())), j0 = static_cast<int>(std::floor(uv.y()));
    const double fu = uv.x() - i0, fv = uv.y() - j0;
    const int i1 = (i0 + 1 + T) % T, j1 = (j0 + 1 + T) % T, ia = (i0 + T) % T, ja = (j0 + T) % T;
    idx[0] = ja * T + ia, idx[1] = ja * T + i1, idx[2] = j1 * T + ia, idx[3] = j1 * T + i1;
    w[0] = (1 - fu) * (1 - fv), w[1] = fu * (1 - fv), w[2] = (1 - fu) * fv, w[3] = fu * fv;
  };

  // Pixels to visit: the bounding box of the sample's projected border.
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (int k = 0; k < 4 * 64; ++k) {
    const double t = (k % 64) / 64.0 * S - S / 2;
    const Vec2 q = k < 64 ? Vec2(t, -S / 2) : k < 128 ? Vec2(S / 2, t) : k < 192 ? Vec2(-t, S / 2) : Vec2(-S / 2, -t);
    Vec2 px;
    if (!in.project(q, &px)) continue;
    xmin = std::min(xmin, px.x()), xmax = std::max(xmax, px.x()), ymin = std::min(ymin, px.y()), ymax = std::max(ymax, px.y());
  }
  const int x0 = std::max(0, static_cast<int>(std::floor(xmin))), x1 = std::min(im.width - 1, static_cast<int>(std::ceil(xmax)));
  const int y0 = std::max(0, static_cast<int>(std::floor(ymin))), y1 = std::min(im.height - 1, static_cast<int>(std::ceil(ymax)));
  const InverseMap inverse(in.project, S);

  Eigen::MatrixXd AtA = Eigen::MatrixXd::Zero(M, M), Atb = Eigen::MatrixXd::Zero(M, C);
  double btb = 0;
  ReconstructedTile out;
  std::vector<double> row(static_cast<std::size_t>(M), 0.0);
  std::vector<int> touched;
  std::vector<Vec2> sub(static_cast<std::size_t>(K) * K);
  auto on_sample = [&](const Vec2& p) { return std::abs(p.x()) <= S / 2 && std::abs(p.y()) <= S / 2; };
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
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
        ++out.pixels_masked;
        continue;
      }
      const double scale = in.scale ? in.scale(pc) : 1.0;
      if (!(std::isfinite(scale) && scale > 0)) ThrowBadInput("tile reconstruction: pixel ({}, {}) has no valid radiometric factor ({})", x, y, scale);
      touched.clear();
      for (const Vec2& p : sub) {
        int idx[4];
        double w[4];
        basis(grid(p), idx, w);
        for (int k = 0; k < 4; ++k) {
          if (row[static_cast<std::size_t>(idx[k])] == 0 && w[k] != 0) touched.push_back(idx[k]);
          row[static_cast<std::size_t>(idx[k])] += w[k] / (K * K);
        }
      }
      for (int a : touched) {
        const double wa = row[static_cast<std::size_t>(a)];
        for (int b : touched) AtA(a, b) += wa * row[static_cast<std::size_t>(b)];
        for (int c = 0; c < C; ++c) Atb(a, c) += wa * scale * im.at(x, y, c);
      }
      for (int c = 0; c < C; ++c) btb += std::pow(scale * im.at(x, y, c), 2);
      for (int a : touched) row[static_cast<std::size_t>(a)] = 0;
      ++out.pixels_used;
    }
  if (out.pixels_used < M)
    ThrowBadInput("tile reconstruction: {} usable pixels on the sample ({} masked) for a {} x {} tile grid ({} unknowns): "
                  "lower --tile-samples-per-texel (now {}) or use --tile-method average",
                  out.pixels_used, out.pixels_masked, T, T, M, o.samples_per_texel);

  // Periodic 5-point Laplacian rows on the grid (neighbours merged where T < 3 folds them
  // together); lambda L^T L is added to the normal matrix with the relative weight.
  std::vector<std::map<int, double>> lap(static_cast<std::size_t>(M));
  double trace_l = 0;
  for (int j = 0; j < T; ++j)
    for (int i = 0; i < T; ++i) {
      auto& r = lap[static_cast<std::size_t>(j * T + i)];
      r[j * T + i] += 4;
      for (const int n : {j * T + (i + 1) % T, j * T + (i + T - 1) % T, ((j + 1) % T) * T + i, ((j + T - 1) % T) * T + i})
        r[n] -= 1;
      for (const auto& [n, w] : r) trace_l += w * w;
    }
  const double lambda = o.smoothness * AtA.trace() / trace_l;
  for (const auto& r : lap)
    for (const auto& [a, wa] : r)
      for (const auto& [b, wb] : r) AtA(a, b) += lambda * wa * wb;
  const Eigen::LLT<Eigen::MatrixXd> llt(AtA);
  if (llt.info() != Eigen::Success)
    ThrowBadInput("tile reconstruction: the normal equations are singular ({} pixels, {} unknowns): raise "
                  "--tile-smoothness (now {}) or use --tile-method average",
                  out.pixels_used, M, o.smoothness);
  const Eigen::MatrixXd f = llt.solve(Atb);
  if (!f.allFinite()) ThrowBadInput("tile reconstruction: the solution is not finite: raise --tile-smoothness");
  // |A f - b|^2 = b^T b - 2 f^T A^T b + f^T (A^T A + lambda L^T L) f - lambda |L f|^2, per channel.
  double rr = btb;
  for (int c = 0; c < C; ++c) {
    rr += -2 * f.col(c).dot(Atb.col(c)) + f.col(c).dot(AtA * f.col(c));
    for (const auto& r : lap) {
      double lf = 0;
      for (const auto& [n, w] : r) lf += w * f(n, c);
      rr -= lambda * lf * lf;
    }
  }
  out.residual_rms = std::sqrt(std::max(0.0, rr) / (double(out.pixels_used) * C));

  // Each tile sample: the reconstructed function averaged over the texel box around its node
  // (16 x 16 midpoints), what a normtexture texel holds.
  constexpr int B = 16;
  out.tile.tile = Image(T, T, C);
  for (int j = 0; j < T; ++j)
    for (int i = 0; i < T; ++i) {
      const Vec2 node((i + 0.5) / T, (j + 0.5) / T);
      std::vector<double> acc(static_cast<std::size_t>(C), 0.0);
      for (int b = 0; b < B * B; ++b) {
        Vec2 st = node + Ainv * Vec2((b % B + 0.5) / B - 0.5, (b / B + 0.5) / B - 0.5);
        st -= Vec2(st.array().floor());
        int idx[4];
        double w[4];
        basis(Vec2(st.x() * T - 0.5, st.y() * T - 0.5), idx, w);
        for (int k = 0; k < 4; ++k)
          for (int c = 0; c < C; ++c) acc[static_cast<std::size_t>(c)] += w[k] * f(idx[k], c);
      }
      for (int c = 0; c < C; ++c) out.tile.tile.at(i, j, c) = static_cast<float>(std::max(0.0, acc[static_cast<std::size_t>(c)] / (B * B)));
    }
  return out;
}

}  // namespace btf
