#include "libbtf/compress/bonn_fmf.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"

namespace btf {

namespace {

using MatrixXd = Eigen::MatrixXd;

template <typename T>
void Put(std::string& b, T v) {
  char bytes[sizeof v];
  std::memcpy(bytes, &v, sizeof v);
  b.append(bytes, sizeof v);
}

// The forward BT.601 analog YUV the DFMF reader inverts (docs/format.md, "Colour models").
constexpr double kRgbToYuv[3][3] = {{0.299, 0.587, 0.114}, {-0.14713, -0.28886, 0.436}, {0.615, -0.51499, -0.10001}};

// The matrices being factorised: FMF one (rows c + C(l + L v)), DFMF one per YUV channel
// (rows l + L v); columns are texels. View v contributes `rows_per_view` contiguous rows.
class Matrices {
 public:
  Matrices(const SlotSource& s, bool decorrelate)
      : s_(s), decorrelate_(decorrelate), slot_(s.slot_size()), texels_(std::size_t(s.width()) * s.height()) {}
  int count() const { return decorrelate_ ? 3 : 1; }
  Eigen::Index rows_per_view() const { return decorrelate_ ? s_.lights().size() : s_.lights().size() * s_.channels(); }
  Eigen::Index rows() const { return rows_per_view() * s_.views().size(); }
  Eigen::Index cols() const { return Eigen::Index(texels_); }
  // Block of view v of every matrix (rows_per_view x texels each), in double.
  void Read(int v, std::vector<MatrixXd>& out) {
    s_.ReadViewSlot(v, slot_.data());
    CheckFiniteSlot(s_, v, slot_.data());
    const int L = s_.lights().size(), C = s_.channels();
    out.assign(std::size_t(count()), MatrixXd(rows_per_view(), cols()));
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
  std::vector<float> slot_;
  std::size_t texels_;
};

MatrixXd Orthonormal(const MatrixXd& a) {
  Eigen::HouseholderQR<MatrixXd> qr(a);
  return qr.householderQ() * MatrixXd::Identity(a.rows(), a.cols());
}

struct Factors {
  std::vector<double> s;
  MatrixXd u, sxv;  // rows x k, texels x k
};

}  // namespace

void FmfWriteOptions::Check() const {
  BTF_CHECK_OPTION(components >= 1, "components", "must be at least 1");
  BTF_CHECK_OPTION(oversampling >= 0, "oversampling", "must be >= 0");
  BTF_CHECK_OPTION(power_iterations >= 0 && power_iterations <= 10, "power_iterations", "must be 0 to 10");
}

ConvertSummary WriteFmf(const FmfWriteOptions& options, const SlotSource& input, const std::filesystem::path& path,
                        const Reporter& reporter) {
  options.Check();
  if (options.decorrelate && input.channels() != 3)
    ThrowUsage("'{}' has {} channels; DFMF's YUV decorrelation needs 3: write FMF instead (--to fmf)", input.name(),
               input.channels());
  Timer timer;
  Matrices x(input, options.decorrelate);
  const int nv = input.views().size(), M = x.count();
  const Eigen::Index R = x.rows_per_view(), D = x.rows(), T = x.cols();
  const Eigen::Index full = std::min(D, T);
  const Eigen::Index k = std::min<Eigen::Index>(options.components, full);
  const Eigen::Index r = std::min<Eigen::Index>(k + options.oversampling, full);
  CheckAllocation(8.0 * M * double(r) * double(D + T) + 8.0 * double(R) * double(T) * M,
                  fmt::format("'{}': factorisation", input.name()));
  // Randomised range finder (Halko et al. 2011) streamed over view slots: Y = X Omega, then
  // power iterations Y = X (X^T Q), then B = Q^T X and the SVD of the small B.
  std::mt19937_64 rng(options.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<MatrixXd> z(std::size_t(M), MatrixXd(T, r)), q(std::size_t(M), MatrixXd(D, r));
  for (auto& zm : z)
    for (Eigen::Index i = 0; i < zm.size(); ++i) zm.data()[i] = normal(rng);
  std::vector<MatrixXd> block;
  const int passes = 2 + 2 * options.power_iterations;
  int pass = 0;
  auto progress = [&] { reporter.Progress(std::size_t(++pass), std::size_t(passes), "factorising"); };
  auto range = [&] {  // q = orth(X z)
    for (int v = 0; v < nv; ++v) {
      x.Read(v, block);
      for (int m = 0; m < M; ++m) q[std::size_t(m)].middleRows(R * v, R) = block[std::size_t(m)] * z[std::size_t(m)];
    }
    for (auto& qm : q) qm = Orthonormal(qm);
    progress();
  };
  range();
  for (int it = 0; it < options.power_iterations; ++it) {
    for (auto& zm : z) zm.setZero();
    for (int v = 0; v < nv; ++v) {
      x.Read(v, block);
      for (int m = 0; m < M; ++m)
        z[std::size_t(m)].noalias() += block[std::size_t(m)].transpose() * q[std::size_t(m)].middleRows(R * v, R);
    }
    for (auto& zm : z) zm = Orthonormal(zm);
    progress();
    range();
  }
  // B = Q^T X (r x T), accumulated as B^T (T x r) in z.
  for (auto& zm : z) zm.setZero();
  for (int v = 0; v < nv; ++v) {
    x.Read(v, block);
    for (int m = 0; m < M; ++m)
      z[std::size_t(m)].noalias() += block[std::size_t(m)].transpose() * q[std::size_t(m)].middleRows(R * v, R);
  }
  progress();
  std::vector<Factors> f(static_cast<std::size_t>(M));
  for (int m = 0; m < M; ++m) {
    // B^T = V S W^T  =>  B = W S V^T, X ~ (Q W) S V^T: U = Q W, SxV = V S.
    Eigen::BDCSVD<MatrixXd> svd(z[std::size_t(m)], Eigen::ComputeThinU | Eigen::ComputeThinV);
    Factors& fm = f[std::size_t(m)];
    fm.u = q[std::size_t(m)] * svd.matrixV().leftCols(k);
    fm.sxv = svd.matrixU().leftCols(k) * svd.singularValues().head(k).asDiagonal();
    fm.s.assign(svd.singularValues().data(), svd.singularValues().data() + k);
    z[std::size_t(m)].resize(0, 0);
    q[std::size_t(m)].resize(0, 0);
  }
  // Header.
  std::string head = options.decorrelate ? "!DFMF08FCR" : "!FMF12FCER";
  head += EncodeBonnMetaAndSampling(input.views(), input.lights(), input.info(),
                                    options.decorrelate ? "libbtf dfmf" : "libbtf fmf");
  Put<std::uint32_t>(head, std::uint32_t(input.width()));
  Put<std::uint32_t>(head, std::uint32_t(input.height()));
  Put<std::uint32_t>(head, 0);  // no rotations
  if (options.decorrelate) {
    Put<std::uint32_t>(head, std::uint32_t(k));
    Put<std::int32_t>(head, 1);  // YUV
    for (int i = 0; i < 3; ++i) Put<float>(head, 0.0f);
    for (int i = 0; i < 9; ++i) Put<float>(head, i % 4 == 0 ? 1.0f : 0.0f);
  } else {
    Put<std::uint8_t>(head, 1);   // header version 1
    Put<std::uint32_t>(head, 0);  // no dynamic-range reduction
  }
  AtomicOutput out(path);
  out.Reserve();
  {
    std::ofstream file(out.temp_path(), std::ios::binary | std::ios::trunc);
    file.write(head.data(), std::streamsize(head.size()));
    std::string b;
    for (int m = 0; m < M; ++m) {
      const Factors& fm = f[std::size_t(m)];
      b.clear();
      if (options.decorrelate) {
        Put<std::uint8_t>(b, 4);
        Put<std::uint32_t>(b, std::uint32_t(k));
      } else {
        Put<std::uint32_t>(b, std::uint32_t(k));
        Put<std::uint8_t>(b, 4);
        Put<std::uint32_t>(b, std::uint32_t(k));
      }
      Put<std::uint32_t>(b, std::uint32_t(D));
      Put<std::uint32_t>(b, std::uint32_t(T));
      for (double s : fm.s) Put<float>(b, float(s));
      for (const MatrixXd* a : {&fm.u, &fm.sxv})
        for (Eigen::Index i = 0; i < a->rows(); ++i)
          for (Eigen::Index j = 0; j < k; ++j) Put<float>(b, float((*a)(i, j)));
      file.write(b.data(), std::streamsize(b.size()));
    }
    file.close();
    if (!file) ThrowIo("cannot write '{}': disk full or no permission?", path.string());
  }
  out.Commit();
  ConvertSummary s;
  s.input = input.name();
  s.input_kind = input.kind();
  s.output = path.string();
  s.output_format = options.decorrelate ? "dfmf" : "fmf";
  s.views = nv;
  s.lights = input.lights().size();
  s.height = input.height();
  s.width = input.width();
  s.channels = input.channels();
  std::error_code ec;
  s.bytes_written = std::filesystem::file_size(path, ec);
  s.times.Add("convert", timer.Seconds());
  return s;
}

}  // namespace btf
