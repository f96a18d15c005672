#pragma once
// AprilTag marker bitmaps from the families compiled into libapriltag (no image files needed).
#include <cstdint>
#include <string>
#include <vector>

namespace btf {

// The module grid of one tag: total_width x total_width modules, row 0 = top of the upright
// tag, value 1 = white, 0 = black. Includes the white quiet ring for families without a reversed
// border (tag36h11: 10 x 10 grid, black border ring 8 x 8 = the detection square).
struct TagBitmap {
  int total_width = 0;       // modules per side of the whole grid
  int width_at_border = 0;   // modules per side of the detection square
  std::vector<std::uint8_t> modules;
  int at(int row, int col) const { return modules[static_cast<std::size_t>(row * total_width + col)]; }
};

// Decodes code `id` of `family` ("tag36h11", "tag25h9", "tag16h5", "tagStandard41h12") into its
// module grid. `border_bits` = black border width in modules (2: Kalibr AprilGrid; the detection
// square grows by 2 modules, the data bits stay centred; not for tagStandard41h12). Throws
// btf::Error (usage) for an unknown family, an id outside the family or a bad border.
// "aruco:DICT_..." (a ChArUco dictionary, libbtf/io/rig.h): OpenCV's marker, total_width =
// width_at_border (no white quiet ring).
TagBitmap RenderTag(const std::string& family, int id, int border_bits = 1);

}  // namespace btf
