#include "libbtf/compress/bonn_pvf.h"

#include <cstring>
#include <fstream>
#include <string>

#include "libbtf/core/atomic_file.h"
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

}  // namespace

ConvertSummary WritePvf(const Codec& codec, const std::string& input_name, const std::filesystem::path& path,
                        const Reporter& reporter) {
  if (codec.method() != CodecMethod::kPcaView)
    ThrowUsage("'{}' is a {} codec; PVF stores per-view PCA: compress with --method pca-view", input_name,
               MethodName(codec.method()));
  if (codec.transform() != ValueTransform::kNone)
    ThrowUsage("'{}' was compressed with --log; PVF has no dynamic-range reduction: compress without --log", input_name);
  Timer timer;
  const int nv = codec.num_views(), nl = codec.num_lights();
  const std::size_t dim = codec.image_size();
  int max_k = 0;
  for (const auto& s : codec.pca_view()) max_k = std::max(max_k, s.components);
  std::string head = "!PVF06FCR";
  head += EncodeBonnMetaAndSampling(codec.views(), codec.lights(), codec.info(), "libbtf pca-view");
  Put<std::uint32_t>(head, std::uint32_t(codec.width()));
  Put<std::uint32_t>(head, std::uint32_t(codec.height()));
  Put<std::uint32_t>(head, 0);  // no rotations
  Put<std::uint32_t>(head, std::uint32_t(max_k));
  Put<std::uint32_t>(head, std::uint32_t(nv));
  AtomicOutput out(path);
  out.Reserve();
  {
    std::ofstream f(out.temp_path(), std::ios::binary | std::ios::trunc);
    f.write(head.data(), std::streamsize(head.size()));
    std::string b;
    for (int v = 0; v < nv; ++v) {
      const PcaViewSlot& s = codec.pca_view()[std::size_t(v)];
      const int k = s.components;
      b.clear();
      Put<std::uint8_t>(b, 4);
      Put<std::uint32_t>(b, std::uint32_t(k));
      Put<std::uint32_t>(b, std::uint32_t(nl));   // weights per light: stacked images
      Put<std::uint32_t>(b, std::uint32_t(dim));  // c + C * texel
      for (int i = 0; i < k; ++i) Put<float>(b, float(s.eigenvalues[std::size_t(i)]));
      b.append(reinterpret_cast<const char*>(s.mean.data()), dim * sizeof(float));
      for (std::size_t d = 0; d < dim; ++d)  // components[dim][k] = basis transposed
        for (int i = 0; i < k; ++i) Put<float>(b, s.basis[std::size_t(i) * dim + d]);
      b.append(reinterpret_cast<const char*>(s.weights.data()), std::size_t(nl) * k * sizeof(float));
      f.write(b.data(), std::streamsize(b.size()));
      reporter.Progress(std::size_t(v + 1), std::size_t(nv), "writing PVF");
    }
    f.close();
    if (!f) ThrowIo("cannot write '{}': disk full or no permission?", path.string());
  }
  out.Commit();
  ConvertSummary s;
  s.input = input_name;
  s.input_kind = kCodecFormat;
  s.output = path.string();
  s.output_format = "pvf";
  s.views = nv;
  s.lights = nl;
  s.height = codec.height();
  s.width = codec.width();
  s.channels = codec.channels();
  std::error_code ec;
  s.bytes_written = std::filesystem::file_size(path, ec);
  s.times.Add("convert", timer.Seconds());
  return s;
}

}  // namespace btf
