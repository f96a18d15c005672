#pragma once
// Small scatter/line plots as SVG (docs/btf-eval.md, "sweep"). The SVG holds the drawing, the
// axes and their tick labels; the descriptive text (title, axis names, legend) is HTML for a
// caption (PlotCaptionHtml), and PlotFigureHtml puts both in one <figure> for a report.
#include <string>
#include <vector>

namespace btf {

// An sRGB color, components in [0, 1].
struct Color {
  double r = 0, g = 0, b = 0;
  static Color Hex(const std::string& hex);  // "#rrggbb"
  std::string ToHex() const;
};

struct PlotSeries {
  std::string name;
  Color color;
  std::vector<double> x, y;
  std::vector<std::string> labels;  // optional short per-point labels drawn next to the markers
  bool markers = true;
  bool line = false;         // connect the points in order
  bool ring_markers = false; // open rings instead of filled markers (used for Pareto fronts)
  int shape = 0;             // 0 circle, 1 square, 2 triangle, 3 diamond
};

struct Plot {
  std::string title, x_label, y_label;  // caption text, not drawn in the SVG
  // Logarithmic axes; an axis with a value <= 0 falls back to linear.
  bool log_x = false, log_y = false;
  int width = 640, height = 400;
  std::vector<PlotSeries> series;
};

// The plot as a standalone SVG document (also valid inline in HTML5). Its <title> and <desc>
// carry the title, axis names and legend for readers of the file alone.
std::string PlotSvg(const Plot& plot);
// The caption: title, axis names (with "log" where an axis is logarithmic) and a legend whose
// entries show each series' marker shape in its color.
std::string PlotCaptionHtml(const Plot& plot);
// <figure class="plot"><svg>...</svg><figcaption>...</figcaption></figure>
std::string PlotFigureHtml(const Plot& plot);

// Indices of the points not dominated by another (smaller-or-equal x and y, one strictly smaller),
// sorted by increasing x: the Pareto front when both coordinates are costs.
std::vector<int> ParetoFront(const std::vector<double>& x, const std::vector<double>& y);

// A palette of distinct colors for series i.
Color SeriesColor(int i);

// Escapes <, >, & and " for HTML and XML text and attributes.
std::string EscapeXml(const std::string& text);

}  // namespace btf
