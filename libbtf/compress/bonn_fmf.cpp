#include "libbtf/compress/bonn_fmf.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/distributed.h"
#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"

namespace btf {

namespace {

template <typename T>
void Put(std::string& b, T v) {
  char bytes[sizeof v];
  std::memcpy(bytes, &v, sizeof v);
  b.append(bytes, sizeof v);
}

struct FmfFileShape {
  const Sampling& views;
  const Sampling& lights;
  DatasetInfo info;
  int width, height;
};

// Writes the factors of `model` as FMF (`log_reduction`: dynamic-range reduction 1) or DFMF.
ConvertSummary WriteFactors(const FmfModel& model, const FmfFileShape& shape, bool log_reduction,
                            const std::filesystem::path& path) {
  const bool dfmf = model.decorrelated;
  const std::uint32_t rows = std::uint32_t(shape.views.size() * model.rows_per_view());
  std::uint32_t max_k = 0;
  for (const auto& m : model.matrices) max_k = std::max(max_k, std::uint32_t(m.components));
  std::string head = dfmf ? "!DFMF08FCR" : "!FMF12FCER";
  head += EncodeBonnMetaAndSampling(shape.views, shape.lights, shape.info, dfmf ? "libbtf dfmf" : "libbtf fmf");
  Put<std::uint32_t>(head, std::uint32_t(shape.width));
  Put<std::uint32_t>(head, std::uint32_t(shape.height));
  Put<std::uint32_t>(head, 0);  // no rotations
  if (dfmf) {
    Put<std::uint32_t>(head, max_k);
    Put<std::int32_t>(head, 1);  // YUV
    for (int i = 0; i < 3; ++i) Put<float>(head, 0.0f);
    for (int i = 0; i < 9; ++i) Put<float>(head, i % 4 == 0 ? 1.0f : 0.0f);
  } else {
    Put<std::uint8_t>(head, 1);  // header version 1
    Put<std::uint32_t>(head, log_reduction ? 1 : 0);
  }
  ConvertSummary s;
  s.output = path.string();
  s.output_format = dfmf ? "dfmf" : "fmf";
  s.views = shape.views.size();
  s.lights = shape.lights.size();
  s.height = shape.height;
  s.width = shape.width;
  s.channels = model.channels;
  if (dist::Rank() != 0) return s;  // distributed: every rank holds the factors, rank 0 writes them
  AtomicOutput out(path);
  out.Reserve();
  {
    std::ofstream file(out.temp_path(), std::ios::binary | std::ios::trunc);
    file.write(head.data(), std::streamsize(head.size()));
    std::string b;
    for (const FmfMatrix& m : model.matrices) {
      const std::uint32_t k = std::uint32_t(m.components);
      b.clear();
      if (dfmf) {
        Put<std::uint8_t>(b, 4);
        Put<std::uint32_t>(b, k);
      } else {
        Put<std::uint32_t>(b, k);
        Put<std::uint8_t>(b, 4);
        Put<std::uint32_t>(b, k);
      }
      Put<std::uint32_t>(b, rows);
      Put<std::uint32_t>(b, std::uint32_t(model.texels));
      // float32 row-major, as the codec holds them.
      for (const auto* a : {&m.singular_values, &m.u, &m.sxv})
        b.append(reinterpret_cast<const char*>(a->data()), a->size() * sizeof(float));
      file.write(b.data(), std::streamsize(b.size()));
    }
    file.close();
    if (!file) ThrowIo("cannot write '{}': disk full or no permission?", path.string());
  }
  out.Commit();
  std::error_code ec;
  s.bytes_written = std::filesystem::file_size(path, ec);
  return s;
}

}  // namespace

ConvertSummary WriteFmf(const FmfWriteOptions& options, const SlotSource& input, const std::filesystem::path& path,
                        const Reporter& reporter) {
  Timer timer;
  const FmfModel model = FactoriseFmf(options, input, {}, reporter);
  ConvertSummary s = WriteFactors(model, {input.views(), input.lights(), input.info(), input.width(), input.height()},
                                  false, path);
  s.input = input.name();
  s.input_kind = input.kind();
  s.times.Add("convert", timer.Seconds());
  return s;
}

ConvertSummary WriteFmf(const Codec& codec, const std::string& input_name, const std::filesystem::path& path,
                        const Reporter&) {
  if (!IsFullMatrixFactorisation(codec.method()))
    ThrowUsage("'{}' is a {} codec; only fmf and dfmf codecs are written as FMF/DFMF without refactorising",
               input_name, MethodName(codec.method()));
  const bool log = codec.transform() == ValueTransform::kLog;
  if (log && (codec.method() == CodecMethod::kDfmf || codec.log_epsilon() != kBonnEpsilon))
    ThrowUsage("'{}' was compressed with --log (epsilon {}); only an fmf codec with --log-epsilon 1e-5 maps onto a "
               "Bonn file (FMF's dynamic-range reduction): recompress so, or without --log",
               input_name, codec.log_epsilon());
  Timer timer;
  ConvertSummary s =
      WriteFactors(codec.fmf(), {codec.views(), codec.lights(), codec.info(), codec.width(), codec.height()}, log, path);
  s.input = input_name;
  s.input_kind = kCodecFormat;
  s.times.Add("convert", timer.Seconds());
  return s;
}

}  // namespace btf
