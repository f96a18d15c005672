#pragma once
// Text, color maps and compositing on images through OpenImageIO's ImageBufAlgo (render_text,
// color_map, paste, resample), for the PNG pictures btf-eval writes (docs/btf-eval.md).
//
// Text needs a TrueType font: $BTF_FONT when set (a path), else DejaVu Sans from the Debian
// package fonts-dejavu-core. Without one, pictures are made without their text and DrawText
// returns false, so that callers can warn; nothing throws.
#include <array>
#include <string>

#include "libbtf/io/image_io.h"

namespace btf {

// The font file text is drawn with: $BTF_FONT if set (empty when that file does not exist), else
// DejaVuSans.ttf where the Debian package fonts-dejavu-core (or another distribution's DejaVu
// package) installs it; empty when there is none (docs/btf-eval.md, "Text in pictures").
std::string LabelFont();

// Draws UTF-8 `text` with its top-left corner at (x, y), about `size` pixels high, in color
// `rgb`, onto `image` (any channel count >= 3; the color is written as given, so draw on display
// values, see ToDisplay). Returns false, drawing nothing, when there is no font or OpenImageIO
// cannot use it.
bool DrawText(Image& image, int x, int y, const std::string& text, int size, const std::array<float, 3>& rgb);
// Width in pixels of `text` drawn at `size`; 0 when there is no font.
int TextWidth(const std::string& text, int size);

// The perceptually uniform "viridis" color map of ImageBufAlgo::color_map (dark blue at 0,
// yellow at 1) applied to values / full_scale, clamped to [0, 1] (NaN shows as 1). `values` is
// a width x height plane; the result is linear RGB (OpenImageIO tabulates its maps linear).
Image FalseColorImage(const float* values, int width, int height, double full_scale);
// One value t in [0, 1] of the same map, as linear RGB.
void FalseColor(double t, float* rgb);

// Copies `src` into `dst` with its top-left pixel at (x, y), each pixel repeated `zoom` times
// (ImageBufAlgo::resample, nearest pixel, then paste); parts outside `dst` are cut off. Both
// images must have the same channel count.
void Paste(Image& dst, const Image& src, int x, int y, int zoom = 1);

// A filled image of `channels` channels, every pixel `rgb` (extra channels 0).
Image Filled(int width, int height, const std::array<float, 3>& rgb, int channels = 3);
// The sRGB transfer curve applied to / removed from every value (display <-> linear).
Image ToDisplay(const Image& linear);
Image ToLinear(const Image& display);

}  // namespace btf
