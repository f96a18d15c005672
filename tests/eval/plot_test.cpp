#include "libbtf/eval/plot.h"

#include <gtest/gtest.h>

namespace btf {
namespace {

TEST(EvalPlot, ParetoFrontKnownAnswer) {
  //             0    1    2    3    4    5
  const std::vector<double> x = {1, 2, 3, 2, 5, 4};
  const std::vector<double> y = {9, 4, 5, 6, 1, 1};
  // Point 5 (4,1) dominates 4 (5,1); 2 is dominated by 1; 3 by 1.
  EXPECT_EQ(ParetoFront(x, y), (std::vector<int>{0, 1, 5}));
  EXPECT_TRUE(ParetoFront({}, {}).empty());
}

TEST(EvalPlot, SvgAndPngShowTheSameFigure) {
  Plot p;
  p.title = "error vs bytes";
  p.x_label = "bytes";
  p.y_label = "rmse";
  p.log_x = p.log_y = true;
  PlotSeries s;
  s.name = "pca-view";
  s.colour = Colour::Hex("#d62728");
  s.x = {100, 1000, 10000};
  s.y = {0.1, 0.01, 0.001};
  p.series.push_back(s);
  const std::string svg = PlotSvg(p);
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("error vs bytes"), std::string::npos);
  std::size_t circles = 0;
  for (std::size_t pos = 0; (pos = svg.find("<circle", pos)) != std::string::npos; ++pos) ++circles;
  EXPECT_EQ(circles, 4u);  // 3 markers + 1 legend marker
  const Image im = PlotImage(p);
  ASSERT_EQ(im.width, p.width);
  ASSERT_EQ(im.height, p.height);
  // Count pixels of the series colour (linear red of #d62728 is about 0.67): the 3 markers + legend
  // are filled circles of radius 4, about 50 pixels each.
  int red = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      if (im.at(x, y, 0) > 0.6f && im.at(x, y, 1) < 0.05f) ++red;
  EXPECT_GT(red, 4 * 30);
  EXPECT_LT(red, 4 * 80);
}

TEST(EvalPlot, TextIsDrawn) {
  Canvas c(40, 12, Colour{1, 1, 1});
  c.Text(1, 1, "8", Colour{0, 0, 0});
  // Glyph '8' has 5 x 7 dots of which 17 are set (rows 0E 11 11 0E 11 11 0E).
  int dark = 0;
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 40; ++x) dark += c.image().at(x, y, 0) < 0.5f;
  EXPECT_EQ(dark, 17);
}

}  // namespace
}  // namespace btf
