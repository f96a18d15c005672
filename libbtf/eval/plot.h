#pragma once
// Small scatter/line plots written both as SVG text and as raster images (PNG through WriteImage),
// from one layout, so the two files show the same figure. Text in raster images uses a built-in
// 5x7 bitmap font (printable ASCII).
#include <string>
#include <vector>

#include "libbtf/io/image_io.h"

namespace btf {

// An sRGB colour, components in [0, 1].
struct Colour {
  double r = 0, g = 0, b = 0;
  static Colour Hex(const std::string& hex);  // "#rrggbb"
  std::string ToHex() const;
};

// A raster canvas. Coordinates in pixels, (0, 0) = top-left corner of the top-left pixel; shapes
// are anti-aliased by coverage. The image holds LINEAR values: write it with srgb = true so the
// file shows the requested sRGB colours.
class Canvas {
 public:
  Canvas(int width, int height, Colour background);
  void Line(double x0, double y0, double x1, double y1, double width, Colour c, double alpha = 1);
  void Circle(double cx, double cy, double radius, Colour c, bool filled, double stroke = 1.5);
  void FillRect(double x, double y, double w, double h, Colour c, double alpha = 1);
  // Text with its top-left corner at (x, y); scale = integer pixel size of one font dot.
  // vertical = rotated 90 degrees counter-clockwise (reads bottom to top), (x, y) = bottom-left.
  void Text(double x, double y, const std::string& text, Colour c, int scale = 1, bool vertical = false);
  static int TextWidth(const std::string& text, int scale = 1) { return int(text.size()) * 6 * scale; }
  static int TextHeight(int scale = 1) { return 7 * scale; }
  // Copies a linear-RGB image into the canvas at (x, y), each pixel repeated `zoom` times.
  void Blit(const Image& image, int x, int y, int zoom = 1);
  const Image& image() const { return image_; }

 private:
  void Blend(int x, int y, Colour c, double alpha);
  Image image_;
};

struct PlotSeries {
  std::string name;
  Colour colour;
  std::vector<double> x, y;
  std::vector<std::string> labels;  // optional per-point labels drawn next to the markers
  bool markers = true;
  bool line = false;         // connect the points in order
  bool ring_markers = false; // open rings instead of filled markers (used for Pareto fronts)
  int shape = 0;             // 0 circle, 1 square, 2 triangle, 3 diamond
};

struct Plot {
  std::string title, x_label, y_label;
  // Logarithmic axes; an axis with a value <= 0 falls back to linear.
  bool log_x = false, log_y = false;
  int width = 720, height = 440;
  std::vector<PlotSeries> series;
};

std::string PlotSvg(const Plot& plot);
Image PlotImage(const Plot& plot);

// Indices of the points not dominated by another (smaller-or-equal x and y, one strictly smaller),
// sorted by increasing x: the Pareto front when both coordinates are costs.
std::vector<int> ParetoFront(const std::vector<double>& x, const std::vector<double>& y);

// A palette of distinct colours for series i.
Colour SeriesColour(int i);

}  // namespace btf
