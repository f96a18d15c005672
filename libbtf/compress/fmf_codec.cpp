// Bonn's full-matrix factorisation (FMF, DFMF) as a codec: the streaming randomised SVD, the
// decoders and the codec-file items.
#include "libbtf/compress/fmf_codec.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Dense>

#include "libbtf/compress/codec.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/error.h"
#include "libbtf/core/timer.h"
#include "libbtf/io/hdf5.h"

namespace btf {

namespace {

using MatrixXd = Eigen::MatrixXd;
using RowF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// The forward BT.601 analog YUV of docs/format.md ("Colour models"), as the DFMF reader inverts it.
constexpr double kRgbToYuv[3][3] = {{0.299, 0.587, 0.114}, {-0.14713, -0.28886, 0.436}, {0.615, -0.51499, -0.10001}};

// Its exact inverse (the Bonn readers use a 5-6 digit rounding of it).
const Eigen::Matrix3d& YuvToRgb() {
  static const Eigen::Matrix3d inv = [] {
    Eigen::Matrix3d m;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) m(i, j) = kRgbToYuv[i][j];
    return Eigen::Matrix3d(m.inverse());
  }();
  return inv;
}

// Components carrying at most this fraction of a matrix's energy are dropped.
constexpr double kNullEnergyFraction = 1e-12;

// MPI tag of the per-view X^T q terms that ranks send to rank 0.
constexpr int kTermTag = 16;

// The matrices being factorised: FMF one (rows c + C(l + L v)), DFMF one per YUV channel
// (rows l + L v); columns are texels. View v contributes `rows_per_view` contiguous rows.
class Matrices {
 public:
  Matrices(const SlotSource& s, bool decorrelate, const ValueMap& transform)
      : s_(s), decorrelate_(decorrelate), transform_(transform), slot_(s.slot_size()),
        texels_(std::size_t(s.width()) * s.height()) {}
  int count() const { return decorrelate_ ? 3 : 1; }
  Eigen::Index rows_per_view() const { return decorrelate_ ? s_.lights().size() : s_.lights().size() * s_.channels(); }
  Eigen::Index rows() const { return rows_per_view() * s_.views().size(); }
  Eigen::Index cols() const { return Eigen::Index(texels_); }
  // Block of view v of every matrix (rows_per_view x texels each), in double.
  void Read(int v, std::vector<MatrixXd>& out) {
    s_.ReadViewSlot(v, slot_.data());
    CheckFiniteSlot(s_, v, slot_.data());
    transform_.Apply(s_.name(), v, slot_.data(), slot_.size());
    const int L = s_.lights().size(), C = s_.channels();
    out.resize(std::size_t(count()));
    for (auto& m : out) m.resize(rows_per_view(), cols());
    for (int l = 0; l < L; ++l)
      for (std::size_t t = 0; t < texels_; ++t) {
        const float* p = &slot_[(std::size_t(l) * texels_ + t) * C];
        if (!decorrelate_) {
          for (int c = 0; c < C; ++c) out[0](c + C * l, Eigen::Index(t)) = p[c];
        } else {
          for (int m = 0; m < 3; ++m)
            out[std::size_t(m)](l, Eigen::Index(t)) = kRgbToYuv[m][0] * p[0] + kRgbToYuv[m][1] * p[1] + kRgbToYuv[m][2] * p[2];
        }
      }
  }

 private:
  const SlotSource& s_;
  bool decorrelate_;
  const ValueMap& transform_;
  std::vector<float> slot_;
  std::size_t texels_;
};

MatrixXd Orthonormal(const MatrixXd& a) {
  Eigen::HouseholderQR<MatrixXd> qr(a);
  return qr.householderQ() * MatrixXd::Identity(a.rows(), a.cols());
}

// The number of components kept of singular values s (descending) of a matrix of energy e.
int ChooseComponents(const FmfSvdOptions& o, const Eigen::VectorXd& s, int most, double e, int* dropped) {
  int k = most;
  double captured = 0;
  for (int i = 0; i <= most && (o.target_error > 0 || o.retained_energy > 0); ++i) {
    const bool enough = o.target_error > 0 ? e - captured <= o.target_error * o.target_error * e
                                           : captured >= o.retained_energy * e;
    if (enough) {
      k = i;
      break;
    }
    if (i < most) captured += s[i] * s[i];
  }
  while (k > 0 && !(s[k - 1] * s[k - 1] > kNullEnergyFraction * e)) --k, ++*dropped;
  return k;
}

std::string MatrixName(const char* what, std::size_t m) { return fmt::format("/codec/fmf/{}_{}", what, m); }

}  // namespace

void FmfSvdOptions::Check() const {
  BTF_CHECK_OPTION(components >= 1, "components", "must be at least 1");
  BTF_CHECK_OPTION(oversampling >= 0, "oversampling", "must be >= 0");
  BTF_CHECK_OPTION(power_iterations >= 0 && power_iterations <= 10, "power_iterations", "must be 0 to 10");
  BTF_CHECK_OPTION(target_error >= 0 && target_error < 1, "error", "a relative RMS error in [0, 1)");
  BTF_CHECK_OPTION(retained_energy >= 0 && retained_energy <= 1, "energy", "a fraction in [0, 1]");
  BTF_CHECK_OPTION(!(target_error > 0 && retained_energy > 0), "error/energy", "give at most one of the two");
}

std::uint64_t FmfModel::StoredValues() const {
  std::uint64_t n = 0;
  for (const auto& m : matrices) n += m.singular_values.size() + m.u.size() + m.sxv.size();
  return n;
}

void FmfModel::DecodeImage(int view, int light, float* out) const {
  const Eigen::Index T = Eigen::Index(texels);
  const std::size_t row = std::size_t(view) * rows_per_view() + std::size_t(light) * (decorrelated ? 1 : channels);
  if (!decorrelated) {
    const FmfMatrix& m = matrices[0];
    Eigen::Map<RowF> o(out, T, channels);
    if (m.components == 0) {
      o.setZero();
      return;
    }
    const Eigen::Map<const RowF> sxv(m.sxv.data(), T, m.components);
    const Eigen::Map<const RowF> u(m.u.data() + row * m.components, channels, m.components);
    o.noalias() = sxv * u.transpose();
    return;
  }
  RowF yuv = RowF::Zero(T, 3);
  for (int c = 0; c < 3; ++c) {
    const FmfMatrix& m = matrices[std::size_t(c)];
    if (m.components == 0) continue;
    const Eigen::Map<const RowF> sxv(m.sxv.data(), T, m.components);
    const Eigen::Map<const Eigen::RowVectorXf> u(m.u.data() + row * m.components, m.components);
    yuv.col(c).noalias() = sxv * u.transpose();
  }
  Eigen::Map<RowF>(out, T, 3).noalias() = yuv * YuvToRgb().transpose().cast<float>();
}

void FmfModel::DecodeViewSlot(int view, float* out) const {
  const std::size_t image = texels * std::size_t(channels);
#pragma omp parallel for schedule(static)
  for (int l = 0; l < lights; ++l) DecodeImage(view, l, out + std::size_t(l) * image);
}

void FmfModel::Sample(int view, int light, std::size_t texel, float* out) const {
  const std::size_t row = std::size_t(view) * rows_per_view() + std::size_t(light) * (decorrelated ? 1 : channels);
  auto dot = [&](const FmfMatrix& m, std::size_t r) {
    double v = 0;
    for (int j = 0; j < m.components; ++j)
      v += double(m.u[r * m.components + j]) * m.sxv[texel * m.components + std::size_t(j)];
    return v;
  };
  if (!decorrelated) {
    for (int c = 0; c < channels; ++c) out[c] = float(dot(matrices[0], row + std::size_t(c)));
    return;
  }
  const Eigen::Vector3d yuv(dot(matrices[0], row), dot(matrices[1], row), dot(matrices[2], row));
  const Eigen::Vector3d rgb = YuvToRgb() * yuv;
  for (int c = 0; c < 3; ++c) out[c] = float(rgb[c]);
}

namespace {

// The factors from the sketch: per matrix m, the SVD of B^T = z[m] = X^T Q (T x r), with
// q[m] = Q; components chosen by the options against the matrix's energy (z and q are freed).
FmfModel FactorsFromSketch(const FmfSvdOptions& options, const SlotSource& input, Eigen::Index k,
                           const std::vector<double>& energy, std::vector<MatrixXd>& z, std::vector<MatrixXd>& q,
                           int* dropped) {
  const int M = static_cast<int>(z.size());
  FmfModel model;
  model.decorrelated = options.decorrelate;
  model.lights = input.lights().size();
  model.channels = input.channels();
  model.texels = std::size_t(input.height()) * input.width();
  int drops = 0;
  for (int m = 0; m < M; ++m) {
    // B^T = V S W^T  =>  B = W S V^T, X ~ (Q W) S V^T: U = Q W, SxV = V S.
    Eigen::BDCSVD<MatrixXd> svd(z[std::size_t(m)], Eigen::ComputeThinU | Eigen::ComputeThinV);
    const int km = ChooseComponents(options, svd.singularValues(), int(k), energy[std::size_t(m)], &drops);
    const MatrixXd u = q[std::size_t(m)] * svd.matrixV().leftCols(km);
    const MatrixXd sxv = svd.matrixU().leftCols(km) * svd.singularValues().head(km).asDiagonal();
    FmfMatrix f;
    f.components = km;
    for (int i = 0; i < km; ++i) f.singular_values.push_back(float(svd.singularValues()[i]));
    f.u.resize(std::size_t(u.size()));
    f.sxv.resize(std::size_t(sxv.size()));
    Eigen::Map<RowF>(f.u.data(), u.rows(), km) = u.cast<float>();
    Eigen::Map<RowF>(f.sxv.data(), sxv.rows(), km) = sxv.cast<float>();
    model.matrices.push_back(std::move(f));
    z[std::size_t(m)].resize(0, 0);
    q[std::size_t(m)].resize(0, 0);
  }
  if (dropped) *dropped = drops;
  return model;
}

}  // namespace

FmfModel FactoriseFmf(const FmfSvdOptions& options, const SlotSource& input, const ValueMap& transform,
                      const Reporter& reporter, int* dropped, const dist::Context& ranks) {
  options.Check();
  if (options.decorrelate && input.channels() != 3)
    ThrowUsage("'{}' has {} channels; DFMF's YUV decorrelation needs 3: use FMF instead", input.name(),
               input.channels());
  Matrices x(input, options.decorrelate, transform);
  const int nv = input.views().size(), M = x.count();
  const Eigen::Index R = x.rows_per_view(), D = x.rows(), T = x.cols();
  const Eigen::Index full = std::min(D, T);
  const Eigen::Index k = std::min<Eigen::Index>(options.components, full);
  const Eigen::Index r = std::min<Eigen::Index>(k + options.oversampling, full);
  // z and q, one view block, and one view's X^T q term (received by rank 0 in a distributed run).
  CheckAllocation(8.0 * M * double(r) * double(D + 2 * T) + 8.0 * double(R) * double(T) * M,
                  ranks.distributed() ? fmt::format("'{}': factorisation (on this rank)", input.name())
                                      : fmt::format("'{}': factorisation", input.name()));
  // Randomised range finder (Halko et al. 2011) streamed over view slots: Y = X Omega, then
  // power iterations Y = X (X^T Q), then B = Q^T X and the SVD of the small B.
  // Distributed (docs/scaling.md): rank r reads and multiplies only the view slots it owns
  // (round robin). A view's rows of X z depend on that view alone and are shared by every rank;
  // X^T q is a sum of one term per view, which rank 0 adds in view order as one process does and
  // broadcasts. Every other step is computed by every rank from the same values, so the factors
  // are bit-identical for any number of ranks.
  std::mt19937_64 rng(options.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<MatrixXd> z(std::size_t(M), MatrixXd(T, r)), q(std::size_t(M), MatrixXd(D, r));
  for (auto& zm : z)
    for (Eigen::Index i = 0; i < zm.size(); ++i) zm.data()[i] = normal(rng);
  std::vector<double> energy(std::size_t(M), 0.0);
  std::vector<MatrixXd> block, term(static_cast<std::size_t>(M));
  const int passes = 2 + 2 * options.power_iterations;
  int pass = 0;
  auto progress = [&] { reporter.Progress(std::size_t(++pass), std::size_t(passes), "factorising"); };
  auto range = [&](bool first) {  // q = orth(X z)
    std::vector<double> view_energy(std::size_t(M) * nv, 0.0);  // [m * nv + v]
    for (int v = 0; v < nv; ++v) {
      if (!ranks.Owns(v)) continue;
      x.Read(v, block);
      for (int m = 0; m < M; ++m) {
        q[std::size_t(m)].middleRows(R * v, R) = block[std::size_t(m)] * z[std::size_t(m)];
        if (first) view_energy[std::size_t(m) * nv + v] = block[std::size_t(m)].squaredNorm();
      }
    }
    if (ranks.distributed()) {  // every rank gets every view's rows (and energies)
      std::vector<double> mine;
      for (int v = ranks.rank(); v < nv; v += ranks.size())
        for (int m = 0; m < M; ++m) {
          const MatrixXd rows = q[std::size_t(m)].middleRows(R * v, R);
          mine.insert(mine.end(), rows.data(), rows.data() + rows.size());
          mine.push_back(view_energy[std::size_t(m) * nv + v]);
        }
      const std::vector<double> all = ranks.AllGatherConcat(mine);
      std::size_t at = 0;
      for (int rank = 0; rank < ranks.size(); ++rank)
        for (int v = rank; v < nv; v += ranks.size())
          for (int m = 0; m < M; ++m) {
            q[std::size_t(m)].middleRows(R * v, R) = Eigen::Map<const MatrixXd>(all.data() + at, R, r);
            at += std::size_t(R * r);
            view_energy[std::size_t(m) * nv + v] = all[at++];
          }
      BTF_CHECK(at == all.size());
    }
    if (first)  // summed in view order
      for (int m = 0; m < M; ++m)
        for (int v = 0; v < nv; ++v) energy[std::size_t(m)] += view_energy[std::size_t(m) * nv + v];
    for (auto& qm : q) qm = Orthonormal(qm);
    progress();
  };
  auto project = [&] {  // z = X^T q = sum over views v of X_v^T q_v, added in view order
    for (auto& zm : z) zm.setZero();
    const std::size_t bytes = sizeof(double) * std::size_t(T) * std::size_t(r);
    for (int v = 0; v < nv; ++v) {
      const int owner = ranks.Owner(v);
      if (ranks.rank() == owner) {
        x.Read(v, block);
        for (int m = 0; m < M; ++m)
          term[std::size_t(m)].noalias() = block[std::size_t(m)].transpose() * q[std::size_t(m)].middleRows(R * v, R);
        if (owner != 0) {  // rank 0 receives the views in order; messages from one rank keep their order
          for (const auto& tm : term) ranks.Send(0, kTermTag, tm.data(), bytes);
          continue;
        }
      } else if (ranks.rank() == 0) {
        for (auto& tm : term) {
          tm.resize(T, r);
          ranks.Recv(owner, kTermTag, tm.data(), bytes);
        }
      } else {
        continue;
      }
      for (int m = 0; m < M; ++m) z[std::size_t(m)] += term[std::size_t(m)];
    }
    for (auto& zm : z) ranks.Broadcast(0, zm.data(), bytes);
    progress();
  };
  range(true);
  for (int it = 0; it < options.power_iterations; ++it) {
    project();
    for (auto& zm : z) zm = Orthonormal(zm);
    range(false);
  }
  project();  // B^T = X^T Q (T x r)
  return FactorsFromSketch(options, input, k, energy, z, q, dropped);
}

void WriteFmfModel(const h5::File& f, const FmfModel& model, int views, int height, int width) {
  f.CreateGroup("/codec/fmf");
  std::vector<std::int32_t> comps;
  for (const auto& m : model.matrices) comps.push_back(m.components);
  f.WriteInts("/codec/fmf/components", {hsize_t(comps.size())}, comps.data());
  const hsize_t V = hsize_t(views), L = hsize_t(model.lights), C = hsize_t(model.channels);
  for (std::size_t i = 0; i < model.matrices.size(); ++i) {
    const FmfMatrix& m = model.matrices[i];
    if (m.components == 0) continue;
    const hsize_t k = hsize_t(m.components);
    f.WriteFloats(MatrixName("singular_values", i), {k}, m.singular_values.data());
    if (model.decorrelated)
      f.WriteFloats(MatrixName("u", i), {V, L, k}, m.u.data());
    else
      f.WriteFloats(MatrixName("u", i), {V, L, C, k}, m.u.data());
    f.WriteFloats(MatrixName("sxv", i), {hsize_t(height), hsize_t(width), k}, m.sxv.data());
  }
}

FmfModel ReadFmfModel(const h5::File& f, bool decorrelated, int views, int lights, int height, int width,
                      int channels) {
  const std::string& path = f.path();
  if (decorrelated && channels != 3)
    ThrowBadInput("'{}': a dfmf codec needs 3 channels (YUV), but '/codec@channels' is {}", path, channels);
  auto read = [&](const std::string& name, const std::vector<hsize_t>& dims) {
    if (!f.Exists(name)) ThrowBadInput("'{}': required dataset '{}' is missing", path, name);
    if (f.Dims(name) != dims) ThrowBadInput("'{}': '{}' has an unexpected shape", path, name);
    std::vector<float> v = f.ReadFloats(name);
    for (std::size_t i = 0; i < v.size(); ++i)
      if (!std::isfinite(v[i])) ThrowBadInput("'{}': '{}' holds a non-finite value at element {}", path, name, i);
    return v;
  };
  FmfModel model;
  model.decorrelated = decorrelated;
  model.lights = lights;
  model.channels = channels;
  model.texels = std::size_t(height) * width;
  const hsize_t M = decorrelated ? 3 : 1, V = hsize_t(views), L = hsize_t(lights), C = hsize_t(channels);
  if (!f.Exists("/codec/fmf/components") || f.Dims("/codec/fmf/components") != std::vector<hsize_t>{M})
    ThrowBadInput("'{}': '/codec/fmf/components' is missing or does not hold {} counts", path, M);
  const std::vector<std::int32_t> comps = f.ReadInts("/codec/fmf/components");
  const double rows = double(V) * L * (decorrelated ? 1 : C), rank = std::min(rows, double(model.texels));
  for (std::size_t i = 0; i < M; ++i) {
    FmfMatrix m;
    m.components = comps[i];
    if (m.components < 0 || m.components > rank)
      ThrowBadInput("'{}': matrix {} claims {} components (at most min(rows, texels) = {})", path, i, m.components,
                    rank);
    model.matrices.push_back(m);
    if (m.components == 0) continue;
    const hsize_t k = hsize_t(m.components);
    CheckAllocation(4.0 * double(k) * (rows + double(model.texels) + 1), fmt::format("'{}' matrix {}", path, i));
    FmfMatrix& s = model.matrices.back();
    s.singular_values = read(MatrixName("singular_values", i), {k});
    s.u = decorrelated ? read(MatrixName("u", i), {V, L, k}) : read(MatrixName("u", i), {V, L, C, k});
    s.sxv = read(MatrixName("sxv", i), {hsize_t(height), hsize_t(width), k});
  }
  return model;
}

}  // namespace btf
