// Writes the benchmarks' synthetic BTF (bench/synthetic_btf.h; not a material model) to a
// libbtf-dataset file view slot by view slot, so inputs larger than memory (UBO2014 size:
// ubo151, 400^2 texels, RGB, 43.8 GB in float32) can be made for bench/ubo2014_ooc.sh. btf-synth
// renders about 1.4e5 values/s (docs/btf-synth.md), 22 h for that size; this writes a hash per value.
//   bench_synthetic_input DIRECTIONS RESOLUTION OUT.h5     (DIRECTIONS: bonn81, ubo151 or a file)
#include <cstdio>
#include <string>
#include <vector>

#include "bench/synthetic_btf.h"
#include "libbtf/core/error.h"
#include "libbtf/io/dataset_io.h"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s DIRECTIONS RESOLUTION OUT.h5\n", argv[0]);
    return 2;
  }
  try {
    const btf::Sampling s = btf::Sampling::Named(argv[1]);
    const int n = std::stoi(argv[2]), V = s.size();
    btf::DatasetInfo info;
    info.provenance["creator"] = "bench_synthetic_input (bench/synthetic_btf.h: synthetic, not a material model)";
    btf::DatasetWriter w(argv[3], s, s, n, n, 3, info);
    std::vector<float> slot(std::size_t(V) * n * n * 3);
    for (int v = 0; v < V; ++v) {
      btf::bench::SyntheticViewSlot(s, n, v, slot.data());
      w.WriteViewSlot(v, slot.data());
    }
    w.Commit();
  } catch (const btf::Error& e) {
    std::fprintf(stderr, "bench_synthetic_input: %s\n", e.what());
    return int(e.code());
  }
  return 0;
}
