// LPCA's texel-major matrix: this rank's texels' rows (lpca_internal.h, LpcaRows).
#include <algorithm>
#include <cmath>
#include <numeric>

#include "libbtf/compress/lpca_internal.h"
#include "libbtf/core/error.h"

namespace btf::lpca {

LpcaRows::LpcaRows(const LpcaSetup& s) : LpcaPhase(s), t0_(TexelBegin(rank_)), t1_(TexelBegin(rank_ + 1)) {
  const double matrix = value_bytes() * double(N_) * double(d_), limit = double(LpcaMemoryLimit());
  ooc_ = o_.lpca.memory == "out-of-core" || (o_.lpca.memory == "auto" && R_ == 1 && matrix > limit);
  if (ooc_ && R_ > 1) ThrowUsage("--lpca-memory out-of-core runs on one rank (ranks split the texel matrix instead)");
  budget_ = limit / 2;  // out of core: the texel chunk, or one wave of clusters' rows
  chunk_ = std::max<std::size_t>(kRows, std::size_t(budget_ / (value_bytes() * double(d_))) / kRows * kRows);
  sum_.lpca_memory = ooc_ ? "out-of-core" : "in-core";
  sum_.lpca_matrix = o_.lpca.matrix;
}

std::size_t LpcaRows::TexelBegin(int r) const {
  const std::size_t blocks = (N_ + kRows - 1) / kRows;
  return std::min(N_, blocks * std::size_t(r) / std::size_t(R_) * kRows);
}

template <typename T>
void LpcaRows::ReadRows(const std::vector<std::size_t>& texels, const std::vector<T*>& rows, double* norms) const {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, std::uint16_t>);
  BTF_CHECK((std::is_same_v<T, float> || half()));
  const int V = in_.views().size(), L = in_.lights().size(), C = in_.channels();
  const std::size_t tiles = (texels.size() + kTile - 1) / kTile, run = kTile * std::size_t(C);
  const std::size_t part = std::size_t(L) * std::size_t(C);  // a row's values of one view
  std::vector<char> consecutive(tiles);
  for (std::size_t b = 0; b < tiles; ++b) {
    const std::size_t i0 = b * kTile, i1 = std::min(texels.size(), i0 + kTile);
    bool c = true;
    for (std::size_t i = i0; i < i1; ++i) c = c && texels[i] == texels[i0] + (i - i0);
    consecutive[b] = c;
  }
  // Per thread: one light's values of a tile (gathered, or half-rounded), as half bits, and the stage.
  const std::size_t threads = std::size_t(std::max(1, omp_get_max_threads()));
  std::vector<float> values(threads * run);
  std::vector<std::uint16_t> halves(half() ? threads * run : 0);
  std::vector<T> stages(threads * kTile * part);
  // Rows that miss texels of the slot (ranks, out-of-core chunks, samples) see only theirs
  // in the tiles: the slot is range-checked on its own then, so that every read of a slot
  // refuses what it holds beyond the half range, as one that covers it does.
  const bool covers = texels.size() == N_;
  PageBuffer buffer;  // the slot, where the source does not hold it or the log changes it
  if (norms) std::fill(norms, norms + texels.size(), 0.0);
  const bool check_underflow = half() && sum_.lpca_passes == 0;
  double energy = 0, below_normal = 0;  // of the transformed values: all, |x| < 2^-14
  for (int v = 0; v < V; ++v) {
    rep_.Progress(std::size_t(v), std::size_t(V), "read");
    const float* slot = tr_.log() ? nullptr : in_.ViewSlotData(v);
    float* read = nullptr;
    std::size_t read_size = 0;
    if (!slot) {
      read_size = in_.slot_size();
      read = buffer.Get<float>(read_size);
      in_.ReadViewSlot(v, read);
      slot = read;
    }
    // With a half matrix and no log, the range check below also finds NaN and Inf (and
    // RefuseBeyondHalf names them as CheckFiniteSlot does), so the slot is not scanned twice.
    if (tr_.log() || !half()) CheckFiniteSlot(in_, v, slot);
    tr_.Apply(in_.name(), v, read, read_size);  // (with the log, slot is the buffer)
    if (check_underflow) {
      double e = 0, b = 0;
#pragma omp parallel for schedule(static) reduction(+ : e, b)
      for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(in_.slot_size()); ++i) {
        const double x = slot[i], xx = x * x;
        e += xx;
        if (std::fabs(x) < 0x1p-14) b += xx;
      }
      energy += e, below_normal += b;
    }
    bool beyond = false;
    // channels: a compile-time 3 (RGB: the copies inlined) or C.
    const auto transpose = [&](auto channels) {
      const std::size_t cc = channels;
#pragma omp parallel for schedule(static) reduction(|| : beyond)
      for (std::ptrdiff_t b = 0; b < static_cast<std::ptrdiff_t>(tiles); ++b) {
        const std::size_t i0 = std::size_t(b) * kTile, i1 = std::min(texels.size(), i0 + kTile), w = (i1 - i0) * cc;
        const std::size_t th = std::size_t(omp_get_thread_num());
        float* own = values.data() + th * run;
        std::uint16_t* bits = half() ? halves.data() + th * run : nullptr;
        T* stage = stages.data() + th * kTile * part;
        bool any = false;
        for (int l = 0; l < L; ++l) {
          const float* from = slot + std::size_t(l) * N_ * cc;
          const float* x = from + texels[i0] * cc;  // the tile's values, as float
          if (!consecutive[std::size_t(b)]) {
            for (std::size_t i = i0; i < i1; ++i)
              for (std::size_t c = 0; c < cc; ++c) own[(i - i0) * cc + c] = from[texels[i] * cc + c];
            x = own;
          }
          if (half()) {
            FloatsToHalves(x, bits, w);
            for (std::size_t j = 0; j < w; ++j) any |= (bits[j] & 0x7c00u) == 0x7c00u;
            if (std::is_same_v<T, float> || norms) {  // the stored values, as float
              HalvesToFloats(bits, own, w);
              x = own;
            }
          }
          const T* stored;
          if constexpr (std::is_same_v<T, std::uint16_t>) stored = bits;
          else stored = x;
          for (std::size_t j = 0; j < i1 - i0; ++j)
            for (std::size_t c = 0; c < cc; ++c) stage[j * part + std::size_t(l) * cc + c] = stored[j * cc + c];
          if (!norms) continue;
          for (std::size_t i = i0; i < i1; ++i)
            for (std::size_t c = 0; c < cc; ++c) {
              const double y = x[(i - i0) * cc + c];
              norms[i] += y * y;
            }
        }
        for (std::size_t i = i0; i < i1; ++i) std::copy_n(stage + (i - i0) * part, part, rows[i] + std::size_t(v) * part);
        beyond = beyond || any;
      }
    };
    if (C == 3) transpose(std::integral_constant<std::size_t, 3>());
    else transpose(std::size_t(C));
    if (half() && (beyond || (!covers && std::any_of(slot, slot + in_.slot_size(), BeyondHalf))))
      RefuseBeyondHalf(v, slot);
  }
  rep_.Progress(std::size_t(V), std::size_t(V), "read");
  if (check_underflow && below_normal > kUnderflowShare * energy) throw HalfUnderflow{below_normal / energy};
  ++sum_.lpca_passes;
}

void LpcaRows::RefuseBeyondHalf(int v, const float* slot) const {
  if (!tr_.log()) CheckFiniteSlot(in_, v, slot);  // after the log, the slot is finite
  const std::size_t i = std::size_t(std::find_if(slot, slot + in_.slot_size(), BeyondHalf) - slot);
  const std::size_t C = std::size_t(in_.channels()), W = std::size_t(in_.width());
  ThrowBadInput("'{}' holds {} at view {}, light {}, texel (y {}, x {}), channel {}{}: beyond the half range (|x| <= "
                "{}) of LPCA's texel matrix; use --lpca-matrix float (4 bytes a value instead of 2){}",
                in_.name(), slot[i], v, i / (N_ * C), i / C % N_ / W, i / C % W, i % C,
                tr_.log() ? " (after the log transform)" : "", kHalfMax, tr_.log() ? "" : " or --log");
}


void LpcaRows::LoadRows() {
  A_.Resize(local(), d_, half());
  std::vector<std::size_t> texels(local());
  std::iota(texels.begin(), texels.end(), t0_);
  chunk_norms_.resize(local());
  if (half()) {
    std::vector<std::uint16_t*> rows(local());
    for (std::size_t i = 0; i < local(); ++i) rows[i] = A_.HalfRow(i);
    ReadRows(texels, rows, chunk_norms_.data());
  } else {
    std::vector<float*> rows(local());
    for (std::size_t i = 0; i < local(); ++i) rows[i] = A_.FloatRow(i);
    ReadRows(texels, rows, chunk_norms_.data());
  }
}

void LpcaRows::SetNorms(const std::vector<double>& all) {
  BTF_CHECK(all.size() == N_);
  norms_ = Eigen::Map<const Eigen::VectorXd>(all.data(), static_cast<Eigen::Index>(N_));
  total_ = norms_.sum();
}

void LpcaRows::ReadTexelMajor() {
  CheckAllocation(value_bytes() * double(local()) * double(d_),
                  R_ > 1 ? fmt::format("texel-major copy of '{}' for LPCA (texels {}-{} of {} on this rank)", in_.name(),
                                       t0_, t1_, N_)
                         : fmt::format("texel-major copy of '{}' for LPCA (--lpca-memory out-of-core streams it)", in_.name()));
  LoadRows();
  SetNorms(R_ > 1 ? ranks_.AllGatherConcat(chunk_norms_) : chunk_norms_);
}

RowMatrixXf LpcaRows::ReadSampleRows(const std::vector<std::size_t>& sample) const {
  CheckAllocation(4.0 * double(sample.size()) * double(d_), fmt::format("k-means sample of '{}'", in_.name()));
  RowMatrixXf S(static_cast<Eigen::Index>(sample.size()), static_cast<Eigen::Index>(d_));
  std::vector<float*> rows(sample.size());
  for (std::size_t i = 0; i < sample.size(); ++i) rows[i] = S.row(Eigen::Index(i)).data();
  ReadRows(sample, rows);
  return S;
}

RowMatrixXf LpcaRows::GatherSampleRows(const std::vector<std::size_t>& sample) const {
  const auto lo = std::lower_bound(sample.begin(), sample.end(), t0_) - sample.begin();
  const auto hi = std::lower_bound(sample.begin(), sample.end(), t1_) - sample.begin();
  RowMatrixXf S;
  if (rank_ == 0) {
    CheckAllocation(4.0 * double(sample.size()) * double(d_), fmt::format("k-means sample of '{}' on rank 0", in_.name()));
    S.resize(static_cast<Eigen::Index>(sample.size()), static_cast<Eigen::Index>(d_));
    for (auto i = lo; i < hi; ++i) A_.CopyRow(sample[std::size_t(i)] - t0_, S.row(i).data());
    std::size_t at = std::size_t(hi);
    for (int r = 1; r < R_; ++r) {
      const std::size_t end = std::size_t(
          std::lower_bound(sample.begin(), sample.end(), TexelBegin(r + 1)) - sample.begin());
      ranks_.Recv(r, 1, S.data() + at * d_, (end - at) * d_ * sizeof(float));
      at = end;
    }
  } else {
    RowMatrixXf mine(hi - lo, static_cast<Eigen::Index>(d_));
    for (auto i = lo; i < hi; ++i) A_.CopyRow(sample[std::size_t(i)] - t0_, mine.row(i - lo).data());
    ranks_.Send(0, 1, mine.data(), std::size_t(mine.size()) * sizeof(float));
  }
  return S;
}

void LpcaRows::ReadClusterRows(const std::vector<std::vector<std::size_t>>& members, const std::vector<int>& list,
                     std::size_t first, std::size_t last, std::vector<RowMatrixXf>& X) const {
  std::vector<std::size_t> texels;
  std::vector<float*> rows;
  for (std::size_t j = first; j < last; ++j) {
    const auto& m = members[static_cast<std::size_t>(list[j])];
    RowMatrixXf& x = X[static_cast<std::size_t>(list[j])];
    x.resize(static_cast<Eigen::Index>(m.size()), static_cast<Eigen::Index>(d_));
    for (std::size_t i = 0; i < m.size(); ++i) texels.push_back(m[i]), rows.push_back(x.row(Eigen::Index(i)).data());
  }
  ReadRows(texels, rows);
}

bool LpcaRows::OwnsAny(const std::vector<std::size_t>& texels) const {
  const auto it = std::lower_bound(texels.begin(), texels.end(), t0_);
  return it != texels.end() && *it < t1_;
}

template void LpcaRows::ReadRows(const std::vector<std::size_t>&, const std::vector<float*>&, double*) const;
template void LpcaRows::ReadRows(const std::vector<std::size_t>&, const std::vector<std::uint16_t*>&, double*) const;

}  // namespace btf::lpca
