#include "libbtf/synth/apriltag_render.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagStandard41h12.h>

#include <memory>

#include "libbtf/core/error.h"
#include "libbtf/io/rig.h"

namespace btf {
namespace {

struct FamilyDeleter {
  void (*destroy)(apriltag_family_t*) = nullptr;
  void operator()(apriltag_family_t* f) const {
    if (f && destroy) destroy(f);
  }
};
using FamilyPtr = std::unique_ptr<apriltag_family_t, FamilyDeleter>;

FamilyPtr OpenFamily(const std::string& name) {
  if (name == "tag36h11") return FamilyPtr(tag36h11_create(), FamilyDeleter{tag36h11_destroy});
  if (name == "tag25h9") return FamilyPtr(tag25h9_create(), FamilyDeleter{tag25h9_destroy});
  if (name == "tag16h5") return FamilyPtr(tag16h5_create(), FamilyDeleter{tag16h5_destroy});
  if (name == "tagStandard41h12")
    return FamilyPtr(tagStandard41h12_create(), FamilyDeleter{tagStandard41h12_destroy});
  ThrowUsage("unknown AprilTag family '{}': use tag36h11, tag25h9, tag16h5 or tagStandard41h12", name);
}

}  // namespace


TagBitmap RenderTag(const std::string& family, int id, int border_bits) {
  if (family.rfind("aruco:", 0) == 0) {  // OpenCV's drawMarker: no quiet ring (a ChArUco square gives it)
    TagBitmap t;
    t.modules = ArucoMarkerModules(family.substr(6), id, border_bits, &t.total_width);
    t.width_at_border = t.total_width;
    return t;
  }
  const FamilyPtr f = OpenFamily(family);
  if (id < 0 || id >= static_cast<int>(f->ncodes))
    ThrowUsage("tag id {} is outside family {} (0..{})", id, family, f->ncodes - 1);
  if (border_bits < 1 || border_bits > 2 || (border_bits > 1 && family == "tagStandard41h12"))
    ThrowUsage("invalid option 'border_bits': {} for {} (1, or 2 for tag16h5, tag25h9 and tag36h11)", border_bits,
               family);
  const int extra = border_bits - 1;
  TagBitmap t;
  t.total_width = static_cast<int>(f->total_width) + 2 * extra;
  t.width_at_border = static_cast<int>(f->width_at_border) + 2 * extra;
  const int T = t.total_width, B = t.width_at_border;
  const int border_start = (T - B) / 2;  // first module of the detection square
  t.modules.assign(static_cast<std::size_t>(T * T), 0);
  // Background: white outside the detection square, black border ring inside it (for a
  // reversed border, the ring is white and the outside black).
  const std::uint8_t outside = f->reversed_border ? 0 : 1, ring = f->reversed_border ? 1 : 0;
  for (int r = 0; r < T; ++r)
    for (int c = 0; c < T; ++c) {
      const bool in_square = r >= border_start && r < border_start + B && c >= border_start && c < border_start + B;
      t.modules[static_cast<std::size_t>(r * T + c)] = in_square ? ring : outside;
    }
  // Data bits, most significant first; bit_x / bit_y count from the detection square's corner.
  const std::uint64_t code = f->codes[id];
  for (std::uint32_t i = 0; i < f->nbits; ++i) {
    const bool white = (code >> (f->nbits - 1 - i)) & 1u;
    const int r = border_start + extra + static_cast<std::int32_t>(f->bit_y[i]);
    const int c = border_start + extra + static_cast<std::int32_t>(f->bit_x[i]);
    if (r >= 0 && r < T && c >= 0 && c < T) t.modules[static_cast<std::size_t>(r * T + c)] = white ? 1 : 0;
  }
  return t;
}

}  // namespace btf
