#include "libbtf/eval/plot.h"

#include <gtest/gtest.h>

#include "libbtf/core/error.h"

namespace btf {
namespace {

std::size_t Count(const std::string& text, const std::string& needle) {
  std::size_t n = 0;
  for (std::size_t pos = 0; (pos = text.find(needle, pos)) != std::string::npos; pos += needle.size()) ++n;
  return n;
}

Plot ExamplePlot() {
  Plot p;
  p.title = "error vs bytes";
  p.x_label = "bytes";
  p.y_label = "rmse";
  p.log_x = p.log_y = true;
  PlotSeries s;
  s.name = "pca-view <c>";
  s.color = Color::Hex("#d62728");
  s.x = {100, 1000, 10000};
  s.y = {0.1, 0.01, 0.001};
  s.labels = {"c1", "c2", "c4"};
  p.series.push_back(s);
  PlotSeries t;
  t.name = "lpca k=8";
  t.color = Color::Hex("#1f77b4");
  t.shape = 1;
  t.line = true;
  t.x = {300, 3000};
  t.y = {0.05, 0.004};
  p.series.push_back(t);
  return p;
}

TEST(EvalPlot, ParetoFrontKnownAnswer) {
  //             0    1    2    3    4    5
  const std::vector<double> x = {1, 2, 3, 2, 5, 4};
  const std::vector<double> y = {9, 4, 5, 6, 1, 1};
  // Point 5 (4,1) dominates 4 (5,1); 2 is dominated by 1; 3 by 1.
  EXPECT_EQ(ParetoFront(x, y), (std::vector<int>{0, 1, 5}));
  EXPECT_TRUE(ParetoFront({}, {}).empty());
}

TEST(EvalPlot, SvgDrawsMarkersAndTicksButNoDescriptiveText) {
  const Plot p = ExamplePlot();
  const std::string svg = PlotSvg(p);
  ASSERT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  // One marker per point, none for a legend (the legend is in the caption).
  EXPECT_EQ(Count(svg, "<circle"), 3u);
  EXPECT_EQ(Count(svg, "<rect") - 1, 2u);  // minus the white background
  EXPECT_EQ(Count(svg, "fill=\"#d62728\""), 3u);
  // Drawn text: tick labels (log decades) and the point labels, nothing else.
  EXPECT_NE(svg.find(">1e+03</text>"), std::string::npos);
  EXPECT_NE(svg.find(">0.01</text>"), std::string::npos);
  EXPECT_NE(svg.find(">c2</text>"), std::string::npos);
  EXPECT_EQ(svg.find(">error vs bytes</text>"), std::string::npos);
  EXPECT_EQ(svg.find("lpca k=8</text>"), std::string::npos);
  EXPECT_EQ(svg.find(">bytes"), std::string::npos);
  // The standalone file still says what it shows (not drawn), with names escaped.
  EXPECT_NE(svg.find("<title>error vs bytes</title>"), std::string::npos);
  EXPECT_NE(svg.find("pca-view &lt;c&gt; (#d62728)"), std::string::npos);
  EXPECT_EQ(svg.find("<c>"), std::string::npos);
}

TEST(EvalPlot, FigureHasTheSvgInlineAndTheTextInItsCaption) {
  const Plot p = ExamplePlot();
  const std::string fig = PlotFigureHtml(p);
  ASSERT_EQ(fig.rfind("<figure", 0), 0u);
  const std::size_t svg = fig.find("<svg"), cap = fig.find("<figcaption>");
  ASSERT_NE(svg, std::string::npos);
  ASSERT_NE(cap, std::string::npos);
  EXPECT_LT(svg, cap);
  EXPECT_EQ(fig.find("<img"), std::string::npos);
  const std::string caption = fig.substr(cap);
  EXPECT_NE(caption.find("error vs bytes"), std::string::npos);
  EXPECT_NE(caption.find("x: bytes (log scale)"), std::string::npos);
  EXPECT_NE(caption.find("y: rmse (log scale)"), std::string::npos);
  // Legend: each series' name, its color and marker (circle; square with a line).
  EXPECT_NE(caption.find("pca-view &lt;c&gt;"), std::string::npos);
  EXPECT_NE(caption.find("color:#d62728\">&#9679;<"), std::string::npos);
  EXPECT_NE(caption.find("color:#1f77b4\">&#8212;&#9632;&#8212;<"), std::string::npos);
}

TEST(EvalPlot, NonPositiveValuesFallBackToALinearAxis) {
  Plot p = ExamplePlot();
  p.series[0].y[0] = 0;  // log of 0 is undefined: linear y axis
  const std::string caption = PlotCaptionHtml(p);
  EXPECT_NE(caption.find("x: bytes (log scale)"), std::string::npos);
  EXPECT_NE(caption.find("y: rmse."), std::string::npos);
}

// x positions of the x-axis tick labels (the only text anchored in the middle).
std::vector<double> XTickPositions(const std::string& svg) {
  std::vector<double> xs;
  for (std::size_t pos = 0; (pos = svg.find("<text x=\"", pos)) != std::string::npos; ++pos) {
    const std::size_t end = svg.find('>', pos);
    if (svg.substr(pos, end - pos).find("text-anchor=\"middle\"") == std::string::npos) continue;
    xs.push_back(std::stod(svg.substr(pos + 9)));
  }
  return xs;
}

TEST(EvalPlot, TickLabelsHaveRoomOnShortAndLongLogRanges) {
  for (const auto& [lo, hi] : std::vector<std::pair<double, double>>{{6e6, 4e7}, {0.9, 1.1}, {1e-3, 1e9}, {2, 2}}) {
    Plot p;
    p.log_x = p.log_y = true;
    PlotSeries s;
    s.x = {lo, hi};
    s.y = {0.12, 0.14};
    p.series.push_back(s);
    const std::vector<double> xs = XTickPositions(PlotSvg(p));
    EXPECT_GE(xs.size(), 2u) << lo << " " << hi;
    EXPECT_LE(xs.size(), 12u) << lo << " " << hi;
    for (std::size_t i = 1; i < xs.size(); ++i) EXPECT_GE(xs[i] - xs[i - 1], 56 - 1e-9) << lo << " " << hi << " " << i;
  }
}

TEST(EvalPlot, ColorHex) {
  const Color c = Color::Hex("#ff8000");
  EXPECT_DOUBLE_EQ(c.r, 1.0);
  EXPECT_NEAR(c.g, 128 / 255.0, 1e-12);
  EXPECT_EQ(c.ToHex(), "#ff8000");
  EXPECT_THROW(Color::Hex("red"), Error);
  EXPECT_THROW(Color::Hex("#12345g"), Error);
}

}  // namespace
}  // namespace btf
