// btf-compress's controller: the input through a scene, --bytes as components, the method from
// the table (method.h), the codec written, the summary filled.
#include "libbtf/compress/compress.h"

#include <algorithm>
#include <memory>
#include <optional>

#include "libbtf/compress/codec_writer.h"
#include "libbtf/compress/method.h"
#include "libbtf/core/error.h"
#include "libbtf/core/timer.h"

namespace btf {

namespace {

// --bytes for the methods that meet it by components: the largest c <= options.components whose
// codec cannot exceed the budget (MethodEntry::bytes_at).
// neural: the latent width (at most options.neural.latent).
int ComponentsWithin(const CompressOptions& o, const MethodEntry& method, const SlotSource& in) {
  const double B = double(o.max_bytes), one = method.bytes_at(o, in, 1);
  if (one > B)
    ThrowUsage("--bytes {} is below the smallest {} codec of this input ({:.0f} bytes at 1 component)", o.max_bytes,
               MethodName(o.method), one);
  int c = o.method == CodecMethod::kNeural ? o.neural.latent : o.components;
  while (c > 1 && method.bytes_at(o, in, c) > B) --c;
  return c;
}

// What the full (scene-less) input would take with the same component counts (mean per
// slot/cluster), for the summary of a scene-reduced compression.
std::uint64_t FullCodecBytes(const CompressSummary& sum, const Codec& codec) {
  double cbar = 0;
  for (int c : sum.slot_components) cbar += c;
  cbar /= std::max<std::size_t>(sum.slot_components.size(), 1);
  const double Vf = sum.input_views, Lf = sum.input_lights, T = double(sum.input_height) * sum.input_width,
               Cf = sum.input_channels;
  double values = 0;
  if (codec.method() == CodecMethod::kLpcaTensor) {
    const LpcaTensorModel& m = codec.lpca_tensor();
    const double qb = m.bits / 8.0;
    return static_cast<std::uint64_t>(double(m.terms()) * ((Vf + Lf * Cf) * qb + 16) + T * (m.components * qb + 4) +
                                      double(m.clusters) * (1 + m.components) * 12);
  }
  if (codec.method() == CodecMethod::kNeural) {  // the same decoder, latents for every texel
    const NeuralCodecModel& m = codec.neural();
    return m.StoredBytes() + static_cast<std::uint64_t>((T - double(m.texels())) * m.latent *
                                                        (m.storage == LatentStorage::kHalf ? 2 : 1));
  }
  if (codec.method() == CodecMethod::kPcaView) {
    values = Vf * (T * Cf * (1 + cbar) + Lf * cbar);
  } else if (IsFullMatrixFactorisation(codec.method())) {
    const double matrices = double(sum.slot_components.size()), rows = Vf * Lf * Cf / matrices;
    values = matrices * cbar * (rows + T + 1);
  } else {
    const double K = codec.lpca().clusters, c = codec.lpca().components;
    values = K * (c + 1) * Vf * Lf * Cf + T * (c + 1) + K;
  }
  return static_cast<std::uint64_t>(values * 4);
}

// The summary's record of the input a scene reduced.
void RecordScene(const SlotSource& full, const SlotSource& used, CompressSummary& sum, const Reporter& rep) {
  sum.scene_used = true;
  sum.input_views = full.views().size();
  sum.input_lights = full.lights().size();
  sum.input_height = full.height();
  sum.input_width = full.width();
  sum.input_channels = full.channels();
  rep.Info("scene keeps {} of {} views, {} of {} lights, {} x {} texels, {} channels", used.views().size(),
           sum.input_views, used.lights().size(), sum.input_lights, used.width(), used.height(), used.channels());
}

// The summary's shape, sizes and ratios of the finished codec (streamed: bytes already written).
void RecordSizes(const SlotSource& in, const Codec& codec, std::uint64_t streamed_bytes, CompressSummary& sum) {
  sum.views = in.views().size();
  sum.lights = in.lights().size();
  sum.height = in.height();
  sum.width = in.width();
  sum.channels = in.channels();
  sum.components = 0;
  for (int c : sum.slot_components) sum.components = std::max(sum.components, c);
  sum.codec_bytes = streamed_bytes + codec.StoredBytes();
  sum.raw_float32_bytes = codec.RawBytes(4);
  sum.raw_half_bytes = codec.RawBytes(2);
  sum.ratio_float32 = sum.codec_bytes ? double(sum.raw_float32_bytes) / double(sum.codec_bytes) : 0;
  sum.ratio_half = sum.codec_bytes ? double(sum.raw_half_bytes) / double(sum.codec_bytes) : 0;
  if (sum.scene_used) {
    sum.full_codec_bytes = FullCodecBytes(sum, codec);
    sum.bytes_saved = sum.full_codec_bytes > sum.codec_bytes ? sum.full_codec_bytes - sum.codec_bytes : 0;
  }
}

// --error is a target per view slot (pca-view), cluster (lpca) or matrix (fmf, dfmf): when each
// part meets it, so does the whole, so a whole above it means the component cap (-c) or the byte
// budget kept some part from it. Said as a warning naming that limit. (lpca-tensor holds its own
// whole-codec target and warns itself; with --log the target is in the log domain, where the
// summary's errors are not.)
void WarnMissedTarget(const CompressOptions& o, const MethodContext& ctx, CompressSummary& sum) {
  if (!(o.target_error > 0) || o.log_transform || o.method == CodecMethod::kLpcaTensor ||
      !(sum.relative_error > o.target_error))
    return;
  const auto capped = std::count(sum.slot_components.begin(), sum.slot_components.end(), o.components);
  const char* part = o.method == CodecMethod::kPcaView ? "view slots" : o.method == CodecMethod::kLpca ? "clusters" : "matrices";
  std::string limit = fmt::format("the component cap -c {} held {} of {} {}; raise -c", o.components, capped,
                                  sum.slot_components.size(), part);
  if (o.max_bytes > 0) limit += fmt::format(" or --bytes (the budget {} set -c)", o.max_bytes);
  ctx.Warn(sum, fmt::format("{}: relative error {:.6g} above --error {} ({})", MethodName(o.method),
                            sum.relative_error, o.target_error, limit));
}

// Compress, and with `out` also the codec file (CompressToFile).
CompressSummary CompressAndWrite(const CompressOptions& options, const SlotSource& input_full, Codec* codec_out,
                                 AtomicOutput* out, const std::string& creator, const Reporter& rep,
                                 const dist::Context& ranks) {
  options.Check();
  BTF_CHECK(codec_out != nullptr);
  if (const auto missing = input_full.missing(); !missing.empty())
    ThrowBadInput("'{}' marks {} of {} images missing (first: view {}, light {}): every codec is fitted to all "
                  "images and would take their zeros for measurements; import the set again with --directions "
                  "present (only the directions with images), or add the missing photos",
                  input_full.name(), missing.size(), std::size_t(input_full.views().size()) * input_full.lights().size(),
                  missing.front().first, missing.front().second);
  CompressOptions o = options;
  CompressSummary sum;
  sum.input = input_full.name();
  std::unique_ptr<SlotSource> scene_input;
  if (o.scene) {
    scene_input = MakeSceneSource(input_full, *o.scene);
    if (o.scene->max_relative_error > 0 && o.target_error == 0 && o.retained_energy == 0)
      o.target_error = o.scene->max_relative_error;
    RecordScene(input_full, *scene_input, sum, rep);
  }
  const SlotSource& in = scene_input ? *scene_input : input_full;
  const MethodEntry& method = FindMethod(o.method);
  if (o.max_bytes > 0 && method.bytes_at) {
    const int c = ComponentsWithin(o, method, in);
    int& width = o.method == CodecMethod::kNeural ? o.neural.latent : o.components;
    if (c < width) rep.Info("--bytes {}: {} components (of at most {})", o.max_bytes, c, width);
    width = c;
  }
  const ValueMap transform = o.Transform();
  Codec codec = CodecBuilder::Make(o.method, in.views(), in.lights(), in.height(), in.width(), in.channels(), in.info(),
                                   transform);
  CodecBuilder::storage(codec) = o.storage;
  sum.method = MethodName(o.method);
  sum.storage = o.method == CodecMethod::kLpcaTensor ? fmt::format("uint{}", o.tensor.quant_bits)
                : o.method == CodecMethod::kNeural     ? o.neural.latent_storage
                                                       : StorageName(o.storage);
  std::optional<CodecFileWriter> writer;
  if (out && method.streams_slots && !ranks.distributed()) writer.emplace(*out, codec, creator);
  const MethodContext ctx{in, o, transform, ranks, rep, writer ? &*writer : nullptr};
  const std::uint64_t streamed_bytes = method.compress(ctx, codec, sum);
  WarnMissedTarget(o, ctx, sum);
  RecordSizes(in, codec, streamed_bytes, sum);
  nlohmann::json prov;
  prov["options"] = o.ToJson();
  if (o.scene) prov["scene"] = o.scene->ToJson();
  prov["summary"] = sum.ToJson();
  CodecBuilder::provenance(codec) = prov;
  if (out) {  // timed in the returned summary only: the file holds the summary before it is written
    Timer t;
    if (writer)
      writer->Finish(codec, codec.num_views());
    else
      WriteCodec(*out, codec, creator);
    sum.times.Add("write", t.Seconds());
  }
  *codec_out = std::move(codec);
  return sum;
}

}  // namespace

CompressSummary Compress(const CompressOptions& options, const SlotSource& input, Codec* codec, const Reporter& rep,
                         const dist::Context& ranks) {
  return CompressAndWrite(options, input, codec, nullptr, {}, rep, ranks);
}

CompressSummary CompressToFile(const CompressOptions& options, const SlotSource& input, AtomicOutput* out,
                               const std::string& creator, const Reporter& rep, const dist::Context& ranks) {
  Codec codec;
  return CompressAndWrite(options, input, &codec, out, creator, rep, ranks);
}

}  // namespace btf
