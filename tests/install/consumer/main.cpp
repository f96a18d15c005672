// A program outside the libbtf tree, built by tests/install/install_test.sh against an installed
// libbtf (find_package or pkg-config). Usage: consumer DATASET CODEC
// Prints the library version, the dataset's shape and the RMSE of the codec against the dataset
// (decoded view slot by view slot), which the test compares with btf-compress's own figure.
#include <cmath>
#include <cstdio>
#include <vector>

#include "libbtf/compress/codec.h"
#include "libbtf/core/version.h"
#include "libbtf/export/sattler_reference_decoder.h"    // installed, header-only: must compile here
#include "libbtf/export/schneider_reference_decoder.h"  // (both layouts)
#include "libbtf/io/dataset_io.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: consumer DATASET CODEC\n");
    return 2;
  }
  try {
    const btf::DatasetReader dataset(argv[1]);
    const btf::Codec codec = btf::ReadCodec(argv[2]);
    const btf::DatasetHeader& h = dataset.header();
    const std::size_t slot = std::size_t(h.num_lights) * h.height * h.width * h.channels;
    std::vector<float> ref(slot), dec(slot);
    double sum = 0;
    for (int v = 0; v < h.num_views; ++v) {
      dataset.ReadViewSlot(v, ref.data());
      codec.DecodeViewSlot(v, dec.data());
      for (std::size_t i = 0; i < slot; ++i) sum += (double(dec[i]) - ref[i]) * (double(dec[i]) - ref[i]);
    }
    std::printf("version %s\nshape %d %d %d %d %d\nrmse %.9g\n", btf::Version().c_str(), h.num_views, h.num_lights,
                h.height, h.width, h.channels, std::sqrt(sum / (double(slot) * h.num_views)));
    return 0;
  } catch (const btf::Error& e) {  // thrown inside libbtf, caught here: one exception type across the boundary
    std::fprintf(stderr, "consumer: error: %s\n", e.what());
    return static_cast<int>(e.code());
  }
}
