#include "libbtf/synth/btf_generator.h"

#include <cmath>
#include <memory>
#include <vector>

#include "libbtf/core/distributed.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"

namespace btf {

PatternWarp::PatternWarp(double amplitude, std::uint64_t seed) : amplitude_(amplitude) {
  if (amplitude_ <= 0) return;
  // Four plane waves with periods of 2.5 to 7 tiles in random directions: smooth within a tile,
  // different from tile to tile. Weights make the RMS displacement equal `amplitude`.
  constexpr int kWaves = 4;
  for (int k = 0; k < kWaves; ++k) {
    const double ang = 2 * kPi * HashUniform(seed, 1, k);
    const double f = 1.0 / (2.5 + 4.5 * HashUniform(seed, 2, k));
    const double dir_ang = 2 * kPi * HashUniform(seed, 3, k);
    Wave w;
    w.freq = f * Vec2(std::cos(ang), std::sin(ang));
    w.phase = 2 * kPi * HashUniform(seed, 4, k);
    // Each sine has mean square 1/2: sum of kWaves gives mean square kWaves/2 * weight^2.
    w.dir = amplitude_ * std::sqrt(2.0 / kWaves) * Vec2(std::cos(dir_ang), std::sin(dir_ang));
    waves_.push_back(w);
  }
}

Vec2 PatternWarp::Apply(const Vec2& uv) const {
  Vec2 out = uv;
  for (const Wave& w : waves_) out += w.dir * std::sin(2 * kPi * w.freq.dot(uv) + w.phase);
  return out;
}

nlohmann::json PatternWarp::Describe() const {
  return {{"kind", "smooth random displacement: 4 plane waves, periods 2.5-7 tiles"},
          {"rms_displacement_tiles", amplitude_}};
}

void BtfOptions::Check() const {
  BTF_CHECK_OPTION(views.size() >= 1, "views", "at least one view direction");
  BTF_CHECK_OPTION(lights.size() >= 1, "lights", "at least one light direction");
  BTF_CHECK_OPTION(resolution >= 1 && resolution <= 8192, "resolution", "1..8192 texels");
  BTF_CHECK_OPTION(std::isfinite(tiles) && tiles > 0 && tiles <= 1024, "tiles", "in (0, 1024]");
  BTF_CHECK_OPTION(samples >= 1 && samples <= 64, "samples", "1..64 per axis");
  BTF_CHECK_OPTION(std::isfinite(irregularity) && irregularity >= 0 && irregularity <= 0.5, "irregularity",
                   "0..0.5 tiles");
}

nlohmann::json BtfSummary::ToJson() const {
  return {{"views", views},
          {"lights", lights},
          {"resolution", resolution},
          {"samples_per_axis", samples},
          {"texel_values", texel_values},
          {"model_evaluations", model_evaluations},
          {"texel_values_per_second", times.Total() > 0 ? texel_values / times.Total() : 0.0},
          {"seconds", times.ToJson()}};
}

Vec2 TexelSampleUv(const BtfOptions& o, int x, int y, int i, int j) {
  const std::uint64_t texel = static_cast<std::uint64_t>(y) * static_cast<std::uint64_t>(o.resolution) + x;
  const std::uint64_t sample = static_cast<std::uint64_t>(j) * static_cast<std::uint64_t>(o.samples) + i;
  const double fx = (i + HashUniform(o.seed, texel, 2 * sample)) / o.samples;
  const double fy = (j + HashUniform(o.seed, texel, 2 * sample + 1)) / o.samples;
  // Row 0 is the top of the texture: v decreases with y.
  return Vec2(o.tiles * (x + fx) / o.resolution, o.tiles * (1 - (y + fy) / o.resolution));
}

namespace {
// All sample positions, texel-major: [(y * N + x) * S^2 + j * S + i].
std::vector<Vec2> SamplePositions(const BtfOptions& o) {
  const int N = o.resolution, S = o.samples;
  std::vector<Vec2> uv(static_cast<std::size_t>(N) * N * S * S);
  const PatternWarp warp(o.irregularity, o.irregularity_seed);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < N; ++y)
    for (int x = 0; x < N; ++x)
      for (int j = 0; j < S; ++j)
        for (int i = 0; i < S; ++i)
          uv[((static_cast<std::size_t>(y) * N + x) * S + j) * S + i] = warp.Apply(TexelSampleUv(o, x, y, i, j));
  return uv;
}

void FillViewSlot(const SvbrdfModel& model, const BtfOptions& o, const std::vector<Vec2>& uv, int view, float* out) {
  const int N = o.resolution, S2 = o.samples * o.samples, L = o.lights.size(), C = model.channels();
  const Vec3 wo = o.views[view];
#pragma omp parallel
  {
    std::vector<float> vals(static_cast<std::size_t>(N) * S2 * C);
#pragma omp for collapse(2) schedule(dynamic)
    for (int l = 0; l < L; ++l)
      for (int y = 0; y < N; ++y) {
        // One batch per texel row: per-pair work is done once per N * S^2 samples.
        model.EvalBatch(o.lights[l], wo, uv.data() + static_cast<std::size_t>(y) * N * S2, N * S2, vals.data());
        float* row = out + ((static_cast<std::size_t>(l) * N + y) * N) * C;
        for (int x = 0; x < N; ++x)
          for (int c = 0; c < C; ++c) {
            double acc = 0;
            for (int s = 0; s < S2; ++s) acc += vals[(static_cast<std::size_t>(x) * S2 + s) * C + c];
            row[static_cast<std::size_t>(x) * C + c] = static_cast<float>(acc / S2);
          }
      }
  }
}
}  // namespace

void GenerateViewSlot(const SvbrdfModel& model, const BtfOptions& options, int view, float* out) {
  options.Check();
  FillViewSlot(model, options, SamplePositions(options), view, out);
}

namespace {

// DatasetInfo for a generated BTF: units, texel size and provenance (model, sampling, supersampling).
DatasetInfo GeneratedBtfInfo(const SvbrdfModel& model, const BtfOptions& o) {
  DatasetInfo info;
  info.units = "brdf_per_sr";
  info.cos_theta_i_included = false;
  info.texel_size_mm = o.tiles * model.tile_size_mm() / o.resolution;
  if (model.channels() != 3) {
    info.channel_names.clear();
    for (int c = 0; c < model.channels(); ++c) info.channel_names.push_back("C" + std::to_string(c));
  }
  info.provenance = {{"generator", "btf-synth btf"},
                     {"model", model.Describe()},
                     {"model_name", model.name()},
                     {"views", o.views.name()},
                     {"lights", o.lights.name()},
                     {"resolution", o.resolution},
                     {"tiles_per_side", o.tiles},
                     {"tile_size_mm", model.tile_size_mm()},
                     {"supersampling",
                      {{"kind", "stratified jittered, box footprint of each texel"},
                       {"samples_per_axis", o.samples},
                       {"seed", o.seed}}},
                     {"irregularity", PatternWarp(o.irregularity, o.irregularity_seed).Describe()},
                     {"texture_coordinates", "u = tiles (x + 0.5) / N, v = tiles (1 - (y + 0.5) / N) at texel centres"}};
  return info;
}

BtfSummary MakeSummary(const BtfOptions& o, const PhaseTimes& times) {
  const int N = o.resolution;
  BtfSummary s;
  s.views = o.views.size();
  s.lights = o.lights.size();
  s.resolution = N;
  s.samples = o.samples;
  s.texel_values = static_cast<std::uint64_t>(o.views.size()) * o.lights.size() * N * N;
  s.model_evaluations = s.texel_values * o.samples * o.samples;
  s.times = times;
  return s;
}

}  // namespace

std::string BtfSummary::Report() const {
  const double t = times.Total();
  return fmt::format("{} views x {} lights x {}^2 texels, {:.3g} texel values/s, {:.1f} s\n", views, lights, resolution,
                     t > 0 ? texel_values / t : 0.0, t);
}

BtfSummary GenerateBtf(const BtfOptions& o, const SvbrdfModel& model, Dataset* out, const Reporter& reporter) {
  o.Check();
  BTF_CHECK(out != nullptr);
  const int N = o.resolution;
  CheckAllocation(4.0 * o.views.size() * o.lights.size() * N * N * model.channels(), "generated BTF");
  Dataset ds(o.views, o.lights, N, N, model.channels(), GeneratedBtfInfo(model, o));
  PhaseTimes times;
  Timer t;
  const auto uv = SamplePositions(o);
  times.Add("sample_positions", t.Seconds());
  t.Restart();
  for (int v = 0; v < o.views.size(); ++v) {
    reporter.Progress(static_cast<std::size_t>(v), static_cast<std::size_t>(o.views.size()), "views");
    FillViewSlot(model, o, uv, v, ds.view_slot(v).data());
  }
  reporter.Progress(static_cast<std::size_t>(o.views.size()), static_cast<std::size_t>(o.views.size()), "views");
  times.Add("evaluate", t.Seconds());
  *out = std::move(ds);
  return MakeSummary(o, times);
}

BtfSummary WriteGeneratedBtf(const BtfOptions& o, const SvbrdfModel& model, const std::filesystem::path& path,
                             const Reporter& reporter, const nlohmann::json& extra_provenance) {
  o.Check();
  const int N = o.resolution;
  DatasetInfo info = GeneratedBtfInfo(model, o);
  if (extra_provenance.is_object())
    for (const auto& [k, v] : extra_provenance.items()) info.provenance[k] = v;
  DatasetWriteOptions wo;
  wo.creator = "btf-synth";
  PhaseTimes times;
  Timer t;
  const auto uv = SamplePositions(o);
  times.Add("sample_positions", t.Seconds());
  // Distributed (docs/scaling.md): each rank renders the view slots it owns; rank 0 receives
  // the others' slots in view order and alone writes the file. A slot does not depend on which
  // rank renders it, so the file is the same for any number of ranks.
  const bool root = dist::Rank() == 0;
  std::unique_ptr<DatasetWriter> writer;
  if (root) writer = std::make_unique<DatasetWriter>(path, o.views, o.lights, N, N, model.channels(), info, wo);
  std::vector<float> slot(static_cast<std::size_t>(o.lights.size()) * N * N * model.channels());
  const std::size_t slot_bytes = slot.size() * sizeof(float);
  double eval_s = 0, write_s = 0;
  for (int v = 0; v < o.views.size(); ++v) {
    reporter.Progress(static_cast<std::size_t>(v), static_cast<std::size_t>(o.views.size()), "views");
    t.Restart();
    if (dist::Owns(v)) FillViewSlot(model, o, uv, v, slot.data());
    eval_s += t.Seconds();
    t.Restart();
    if (!root && dist::Owns(v)) dist::Send(0, v, slot.data(), slot_bytes);
    if (root) {
      if (!dist::Owns(v)) dist::Recv(dist::Owner(v), v, slot.data(), slot_bytes);
      writer->WriteViewSlot(v, slot.data());
    }
    write_s += t.Seconds();
  }
  reporter.Progress(static_cast<std::size_t>(o.views.size()), static_cast<std::size_t>(o.views.size()), "views");
  t.Restart();
  if (root) writer->Commit();
  write_s += t.Seconds();
  times.Add("evaluate", eval_s);
  times.Add("write", write_s);
  return MakeSummary(o, times);
}

Dataset GenerateBrdf(const SvbrdfModel& model, const Sampling& views, const Sampling& lights) {
  DatasetInfo info;
  info.provenance = {{"generator", "btf-synth brdf"},
                     {"model", model.Describe()},
                     {"model_name", model.name()},
                     {"views", views.name()},
                     {"lights", lights.name()},
                     {"value", "far-field BRDF (tile average; analytic where the model has one)"}};
  info.texel_size_mm = model.tile_size_mm();
  if (model.channels() != 3) {
    info.channel_names.clear();
    for (int c = 0; c < model.channels(); ++c) info.channel_names.push_back("C" + std::to_string(c));
  }
  Dataset ds(views, lights, 1, 1, model.channels(), info);
#pragma omp parallel for collapse(2) schedule(dynamic)
  for (int v = 0; v < views.size(); ++v)
    for (int l = 0; l < lights.size(); ++l) model.EvalBrdf(lights[l], views[v], ds.image(v, l).data());
  return ds;
}

}  // namespace btf
