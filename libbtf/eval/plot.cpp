#include "libbtf/eval/plot.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include <fmt/format.h>

#include "libbtf/core/error.h"

namespace btf {

namespace {

// 5x7 glyphs, one byte per row (bit 4 = leftmost column), for the characters in kGlyphChars.
constexpr const char* kGlyphChars =
    " 0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz.,-+()/:%_=[]*<>^'|?!#";
constexpr std::uint8_t kGlyphs[][7] = {
    {0, 0, 0, 0, 0, 0, 0},                                  // space
    {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E},             // 0
    {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E},             // 1
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F},             // 2
    {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E},             // 3
    {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02},             // 4
    {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E},             // 5
    {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E},             // 6
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08},             // 7
    {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E},             // 8
    {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C},             // 9
    {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11},             // A
    {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E},             // B
    {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E},             // C
    {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C},             // D
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F},             // E
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10},             // F
    {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F},             // G
    {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11},             // H
    {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E},             // I
    {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C},             // J
    {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11},             // K
    {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F},             // L
    {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11},             // M
    {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11},             // N
    {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},             // O
    {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10},             // P
    {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D},             // Q
    {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11},             // R
    {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E},             // S
    {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04},             // T
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},             // U
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04},             // V
    {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A},             // W
    {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11},             // X
    {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04},             // Y
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F},             // Z
    {0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F},             // a
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E},             // b
    {0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E},             // c
    {0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F},             // d
    {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E},             // e
    {0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08},             // f
    {0x00, 0x00, 0x0F, 0x11, 0x0F, 0x01, 0x0E},             // g
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11},             // h
    {0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E},             // i
    {0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C},             // j
    {0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12},             // k
    {0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E},             // l
    {0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11},             // m
    {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11},             // n
    {0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E},             // o
    {0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10},             // p
    {0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01},             // q
    {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10},             // r
    {0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E},             // s
    {0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06},             // t
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D},             // u
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04},             // v
    {0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A},             // w
    {0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11},             // x
    {0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E},             // y
    {0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F},             // z
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C},             // .
    {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08},             // ,
    {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00},             // -
    {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00},             // +
    {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02},             // (
    {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08},             // )
    {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00},             // /
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00},             // :
    {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03},             // %
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F},             // _
    {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00},             // =
    {0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E},             // [
    {0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E},             // ]
    {0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00},             // *
    {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02},             // <
    {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08},             // >
    {0x04, 0x0A, 0x11, 0x00, 0x00, 0x00, 0x00},             // ^
    {0x04, 0x04, 0x00, 0x00, 0x00, 0x00, 0x00},             // '
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04},             // |
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04},             // ?
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04},             // !
    {0x0A, 0x1F, 0x0A, 0x0A, 0x1F, 0x0A, 0x00},             // #
};
static_assert(sizeof(kGlyphs) / sizeof(kGlyphs[0]) == std::char_traits<char>::length(kGlyphChars));

const std::uint8_t* Glyph(char ch) {
  static constexpr std::uint8_t kUnknown[7] = {0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F};
  const char* p = std::char_traits<char>::find(kGlyphChars, std::char_traits<char>::length(kGlyphChars), ch);
  return p ? kGlyphs[p - kGlyphChars] : kUnknown;
}

double SrgbComponentToLinear(double v) { return SrgbToLinear(static_cast<float>(v)); }

// Distance from p to the segment a-b.
double SegmentDistance(double px, double py, double ax, double ay, double bx, double by) {
  const double dx = bx - ax, dy = by - ay, len2 = dx * dx + dy * dy;
  double t = len2 > 0 ? ((px - ax) * dx + (py - ay) * dy) / len2 : 0;
  t = std::clamp(t, 0.0, 1.0);
  return std::hypot(px - (ax + t * dx), py - (ay + t * dy));
}

std::string XmlEscape(const std::string& s) {
  std::string out;
  for (char ch : s) {
    switch (ch) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += ch;
    }
  }
  return out;
}

// The drawing primitives a plot needs; one implementation writes SVG, one rasterises.
class Painter {
 public:
  virtual ~Painter() = default;
  virtual void Line(double x0, double y0, double x1, double y1, double width, Colour c, double alpha = 1) = 0;
  virtual void Marker(double x, double y, int shape, double size, Colour c, bool ring) = 0;
  virtual void Rect(double x, double y, double w, double h, Colour fill, Colour stroke) = 0;
  // anchor: 0 start, 1 middle, 2 end; (x, y) = left/centre/right of the text's top edge.
  virtual void Text(double x, double y, const std::string& text, Colour c, int scale, int anchor,
                    bool vertical = false) = 0;
};

class SvgPainter final : public Painter {
 public:
  std::string out;
  void Line(double x0, double y0, double x1, double y1, double width, Colour c, double alpha) override {
    out += fmt::format(
        "<line x1=\"{:.2f}\" y1=\"{:.2f}\" x2=\"{:.2f}\" y2=\"{:.2f}\" stroke=\"{}\" stroke-width=\"{:.2f}\" "
        "stroke-opacity=\"{:.2f}\"/>\n",
        x0, y0, x1, y1, c.ToHex(), width, alpha);
  }
  void Marker(double x, double y, int shape, double size, Colour c, bool ring) override {
    const std::string paint = ring ? fmt::format("fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"", c.ToHex())
                                   : fmt::format("fill=\"{}\"", c.ToHex());
    const double r = size;
    switch (ring ? 0 : shape % 4) {
      case 1:
        out += fmt::format("<rect x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" height=\"{:.2f}\" {}/>\n", x - r * 0.85,
                           y - r * 0.85, 1.7 * r, 1.7 * r, paint);
        break;
      case 2:
        out += fmt::format("<polygon points=\"{:.2f},{:.2f} {:.2f},{:.2f} {:.2f},{:.2f}\" {}/>\n", x, y - r * 1.1,
                           x - r, y + r * 0.8, x + r, y + r * 0.8, paint);
        break;
      case 3:
        out += fmt::format("<polygon points=\"{:.2f},{:.2f} {:.2f},{:.2f} {:.2f},{:.2f} {:.2f},{:.2f}\" {}/>\n", x,
                           y - r * 1.2, x + r * 1.2, y, x, y + r * 1.2, x - r * 1.2, y, paint);
        break;
      default:
        out += fmt::format("<circle cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"{:.2f}\" {}/>\n", x, y, r, paint);
    }
  }
  void Rect(double x, double y, double w, double h, Colour fill, Colour stroke) override {
    out += fmt::format("<rect x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" height=\"{:.2f}\" fill=\"{}\" stroke=\"{}\"/>\n",
                       x, y, w, h, fill.ToHex(), stroke.ToHex());
  }
  void Text(double x, double y, const std::string& text, Colour c, int scale, int anchor, bool vertical) override {
    static constexpr const char* kAnchor[] = {"start", "middle", "end"};
    const double size = 9.5 * scale;  // close to the bitmap font's 7-dot cap height plus descender
    if (vertical)
      out += fmt::format(
          "<text transform=\"translate({:.2f},{:.2f}) rotate(-90)\" text-anchor=\"{}\" dominant-baseline=\"hanging\" "
          "font-family=\"DejaVu Sans Mono, monospace\" font-size=\"{:.1f}\" fill=\"{}\">{}</text>\n",
          x, y, kAnchor[anchor], size, c.ToHex(), XmlEscape(text));
    else
      out += fmt::format(
          "<text x=\"{:.2f}\" y=\"{:.2f}\" text-anchor=\"{}\" dominant-baseline=\"hanging\" "
          "font-family=\"DejaVu Sans Mono, monospace\" font-size=\"{:.1f}\" fill=\"{}\">{}</text>\n",
          x, y, kAnchor[anchor], size, c.ToHex(), XmlEscape(text));
  }
};

class RasterPainter final : public Painter {
 public:
  explicit RasterPainter(Canvas& canvas) : canvas_(canvas) {}
  void Line(double x0, double y0, double x1, double y1, double width, Colour c, double alpha) override {
    canvas_.Line(x0, y0, x1, y1, width, c, alpha);
  }
  void Marker(double x, double y, int shape, double size, Colour c, bool ring) override {
    if (ring || shape % 4 == 0) {
      canvas_.Circle(x, y, size, c, !ring);
      return;
    }
    if (shape % 4 == 1) {
      canvas_.FillRect(x - size * 0.85, y - size * 0.85, 1.7 * size, 1.7 * size, c);
      return;
    }
    // Triangles and diamonds: fill by scanning rows (small shapes; coverage by sub-rows).
    const double r = size;
    for (double yy = -1.2 * r; yy <= 1.2 * r; yy += 0.25) {
      double half;
      if (shape % 4 == 2) {
        if (yy < -1.1 * r || yy > 0.8 * r) continue;
        half = r * (yy + 1.1 * r) / (1.9 * r);
      } else {
        half = 1.2 * r - std::abs(yy);
      }
      canvas_.FillRect(x - half, y + yy, 2 * half, 0.25, c);
    }
  }
  void Rect(double x, double y, double w, double h, Colour fill, Colour stroke) override {
    canvas_.FillRect(x, y, w, h, fill);
    canvas_.Line(x, y, x + w, y, 1, stroke);
    canvas_.Line(x + w, y, x + w, y + h, 1, stroke);
    canvas_.Line(x + w, y + h, x, y + h, 1, stroke);
    canvas_.Line(x, y + h, x, y, 1, stroke);
  }
  void Text(double x, double y, const std::string& text, Colour c, int scale, int anchor, bool vertical) override {
    const double w = Canvas::TextWidth(text, scale);
    const double shift = anchor == 0 ? 0 : anchor == 1 ? w / 2 : w;
    if (vertical)
      canvas_.Text(std::round(x), std::round(y + shift), text, c, scale, true);
    else
      canvas_.Text(std::round(x - shift), std::round(y), text, c, scale);
  }

 private:
  Canvas& canvas_;
};

struct Axis {
  bool log = false;
  double lo = 0, hi = 1;  // in axis units (log10 for log axes)
  std::vector<double> ticks;  // in data units
  double ToAxis(double v) const { return log ? std::log10(v) : v; }
};

Axis MakeAxis(std::vector<double> values, bool want_log) {
  Axis a;
  a.log = want_log;
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }),
               values.end());
  if (values.empty()) values = {0.0, 1.0};
  for (double v : values)
    if (v <= 0) a.log = false;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (double v : values) lo = std::min(lo, a.ToAxis(v)), hi = std::max(hi, a.ToAxis(v));
  if (hi - lo < 1e-12 * std::max(1.0, std::abs(hi))) {
    // One distinct value: give the axis a sensible width around it.
    const double pad = a.log ? 0.5 : std::max(std::abs(hi) * 0.5, 1e-12);
    lo -= pad, hi += pad;
  }
  const double pad = 0.06 * (hi - lo);
  a.lo = lo - pad, a.hi = hi + pad;
  if (a.log) {
    const int d0 = int(std::floor(a.lo)), d1 = int(std::ceil(a.hi));
    const int step = std::max(1, (d1 - d0) / 8);
    for (int d = d0; d <= d1; d += step) {
      for (double m : {1.0, 2.0, 5.0}) {
        if (m != 1.0 && d1 - d0 > 3) continue;  // 2 and 5 only on short ranges
        const double v = m * std::pow(10.0, d);
        if (std::log10(v) >= a.lo && std::log10(v) <= a.hi) a.ticks.push_back(v);
      }
    }
  } else {
    const double raw = (a.hi - a.lo) / 6;
    const double mag = std::pow(10.0, std::floor(std::log10(raw)));
    double step = mag;
    for (double m : {1.0, 2.0, 5.0, 10.0})
      if (m * mag >= raw) {
        step = m * mag;
        break;
      }
    for (double v = std::ceil(a.lo / step) * step; v <= a.hi + 1e-9 * step; v += step)
      a.ticks.push_back(std::abs(v) < 1e-9 * step ? 0.0 : v);
  }
  return a;
}

std::string TickLabel(double v) { return fmt::format("{:.3g}", v); }

void DrawPlot(const Plot& plot, Painter& p) {
  const Colour black{0, 0, 0}, grey{0.55, 0.55, 0.55}, light{0.88, 0.88, 0.88}, white{1, 1, 1};
  std::vector<double> xs, ys;
  for (const auto& s : plot.series) xs.insert(xs.end(), s.x.begin(), s.x.end()), ys.insert(ys.end(), s.y.begin(), s.y.end());
  const Axis ax = MakeAxis(xs, plot.log_x), ay = MakeAxis(ys, plot.log_y);

  int legend_w = 0;
  for (const auto& s : plot.series) legend_w = std::max(legend_w, Canvas::TextWidth(s.name) + 30);
  const double left = 78, top = 34, bottom = 48, right = legend_w + 24;
  const double pw = plot.width - left - right, ph = plot.height - top - bottom;
  auto X = [&](double v) { return left + (ax.ToAxis(v) - ax.lo) / (ax.hi - ax.lo) * pw; };
  auto Y = [&](double v) { return top + ph - (ay.ToAxis(v) - ay.lo) / (ay.hi - ay.lo) * ph; };

  p.Rect(0, 0, plot.width, plot.height, white, white);
  p.Text(left + pw / 2, 10, plot.title, black, 2, 1);
  // Grid, ticks and tick labels.
  for (double t : ax.ticks) {
    p.Line(X(t), top, X(t), top + ph, 1, light);
    p.Line(X(t), top + ph, X(t), top + ph + 4, 1, black);
    p.Text(X(t), top + ph + 7, TickLabel(t), black, 1, 1);
  }
  for (double t : ay.ticks) {
    p.Line(left, Y(t), left + pw, Y(t), 1, light);
    p.Line(left - 4, Y(t), left, Y(t), 1, black);
    p.Text(left - 7, Y(t) - 3.5, TickLabel(t), black, 1, 2);
  }
  p.Line(left, top, left, top + ph, 1, black);
  p.Line(left, top + ph, left + pw, top + ph, 1, black);
  p.Line(left, top, left + pw, top, 1, grey);
  p.Line(left + pw, top, left + pw, top + ph, 1, grey);
  p.Text(left + pw / 2, top + ph + 24, plot.x_label + (ax.log ? " (log)" : ""), black, 1, 1);
  p.Text(14, top + ph / 2, plot.y_label + (ay.log ? " (log)" : ""), black, 1, 1, true);

  // Series: lines first, then markers, then labels.
  for (const auto& s : plot.series) {
    if (!s.line) continue;
    for (std::size_t i = 1; i < s.x.size(); ++i) p.Line(X(s.x[i - 1]), Y(s.y[i - 1]), X(s.x[i]), Y(s.y[i]), 1.5, s.colour, 0.8);
  }
  for (const auto& s : plot.series) {
    if (!s.markers) continue;
    for (std::size_t i = 0; i < s.x.size(); ++i) p.Marker(X(s.x[i]), Y(s.y[i]), s.shape, s.ring_markers ? 6.5 : 4, s.colour, s.ring_markers);
  }
  for (const auto& s : plot.series)
    for (std::size_t i = 0; i < std::min(s.labels.size(), s.x.size()); ++i)
      p.Text(X(s.x[i]) + 6, Y(s.y[i]) - 11, s.labels[i], grey, 1, 0);

  // Legend.
  double ly = top + 6;
  const double lx = left + pw + 14;
  for (const auto& s : plot.series) {
    if (s.line) p.Line(lx, ly + 4, lx + 16, ly + 4, 1.5, s.colour);
    if (s.markers) p.Marker(lx + 8, ly + 4, s.shape, s.ring_markers ? 5 : 4, s.colour, s.ring_markers);
    p.Text(lx + 22, ly, s.name, black, 1, 0);
    ly += 16;
  }
}

}  // namespace

Colour Colour::Hex(const std::string& hex) {
  if (hex.size() != 7 || hex[0] != '#') ThrowUsage("colour '{}' is not of the form #rrggbb", hex);
  auto component = [&](int i) { return std::stoi(hex.substr(1 + 2 * i, 2), nullptr, 16) / 255.0; };
  return {component(0), component(1), component(2)};
}

std::string Colour::ToHex() const {
  auto byte = [](double v) { return static_cast<int>(std::lround(std::clamp(v, 0.0, 1.0) * 255)); };
  return fmt::format("#{:02x}{:02x}{:02x}", byte(r), byte(g), byte(b));
}

Canvas::Canvas(int width, int height, Colour background) : image_(width, height, 3) {
  const float lin[3] = {float(SrgbComponentToLinear(background.r)), float(SrgbComponentToLinear(background.g)),
                        float(SrgbComponentToLinear(background.b))};
  for (std::size_t i = 0; i < image_.pixels.size(); ++i) image_.pixels[i] = lin[i % 3];
}

void Canvas::Blend(int x, int y, Colour c, double alpha) {
  if (x < 0 || y < 0 || x >= image_.width || y >= image_.height || alpha <= 0) return;
  alpha = std::min(alpha, 1.0);
  // Blend in sRGB space, as browsers do for SVG, so the PNG matches the SVG.
  const double src[3] = {c.r, c.g, c.b};
  for (int k = 0; k < 3; ++k) {
    float& v = image_.at(x, y, k);
    const double dst = LinearToSrgb(v);
    v = SrgbToLinear(static_cast<float>(dst + (src[k] - dst) * alpha));
  }
}

void Canvas::Line(double x0, double y0, double x1, double y1, double width, Colour c, double alpha) {
  const double h = width / 2;
  const int xa = int(std::floor(std::min(x0, x1) - h - 1)), xb = int(std::ceil(std::max(x0, x1) + h + 1));
  const int ya = int(std::floor(std::min(y0, y1) - h - 1)), yb = int(std::ceil(std::max(y0, y1) + h + 1));
  for (int y = std::max(ya, 0); y <= std::min(yb, image_.height - 1); ++y)
    for (int x = std::max(xa, 0); x <= std::min(xb, image_.width - 1); ++x) {
      const double d = SegmentDistance(x + 0.5, y + 0.5, x0, y0, x1, y1);
      Blend(x, y, c, alpha * std::clamp(h + 0.5 - d, 0.0, 1.0));
    }
}

void Canvas::Circle(double cx, double cy, double radius, Colour c, bool filled, double stroke) {
  const int r = int(std::ceil(radius + stroke + 1));
  for (int y = int(cy) - r; y <= int(cy) + r; ++y)
    for (int x = int(cx) - r; x <= int(cx) + r; ++x) {
      const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
      const double cover = filled ? std::clamp(radius + 0.5 - d, 0.0, 1.0)
                                  : std::clamp(stroke / 2 + 0.5 - std::abs(d - radius), 0.0, 1.0);
      Blend(x, y, c, cover);
    }
}

void Canvas::FillRect(double x, double y, double w, double h, Colour c, double alpha) {
  for (int py = int(std::floor(y)); py < int(std::ceil(y + h)); ++py)
    for (int px = int(std::floor(x)); px < int(std::ceil(x + w)); ++px) {
      const double cx = std::min(px + 1.0, x + w) - std::max(double(px), x);
      const double cy = std::min(py + 1.0, y + h) - std::max(double(py), y);
      Blend(px, py, c, alpha * std::max(cx, 0.0) * std::max(cy, 0.0));
    }
}

void Canvas::Text(double x, double y, const std::string& text, Colour c, int scale, bool vertical) {
  const int x0 = int(std::lround(x)), y0 = int(std::lround(y));
  for (std::size_t i = 0; i < text.size(); ++i) {
    const std::uint8_t* g = Glyph(text[i]);
    for (int row = 0; row < 7; ++row)
      for (int col = 0; col < 5; ++col) {
        if (!(g[row] & (0x10 >> col))) continue;
        // Along the text: (i*6 + col) dots; across: row dots.
        const int along = (int(i) * 6 + col) * scale, across = row * scale;
        for (int sy = 0; sy < scale; ++sy)
          for (int sx = 0; sx < scale; ++sx) {
            if (vertical)
              Blend(x0 + across + sy, y0 - along - sx - 1, c, 1);
            else
              Blend(x0 + along + sx, y0 + across + sy, c, 1);
          }
      }
  }
}

void Canvas::Blit(const Image& image, int x, int y, int zoom) {
  for (int py = 0; py < image.height * zoom; ++py)
    for (int px = 0; px < image.width * zoom; ++px) {
      const int tx = x + px, ty = y + py;
      if (tx < 0 || ty < 0 || tx >= image_.width || ty >= image_.height) continue;
      for (int k = 0; k < 3; ++k)
        image_.at(tx, ty, k) = image.at(px / zoom, py / zoom, std::min(k, image.channels - 1));
    }
}

std::string PlotSvg(const Plot& plot) {
  SvgPainter p;
  p.out = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\">\n"
      "<title>{2}</title>\n",
      plot.width, plot.height, XmlEscape(plot.title));
  DrawPlot(plot, p);
  p.out += "</svg>\n";
  return p.out;
}

Image PlotImage(const Plot& plot) {
  Canvas canvas(plot.width, plot.height, Colour{1, 1, 1});
  RasterPainter p(canvas);
  DrawPlot(plot, p);
  return canvas.image();
}

std::vector<int> ParetoFront(const std::vector<double>& x, const std::vector<double>& y) {
  std::vector<int> order;
  for (int i = 0; i < int(std::min(x.size(), y.size())); ++i)
    if (std::isfinite(x[i]) && std::isfinite(y[i])) order.push_back(i);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return x[a] != x[b] ? x[a] < x[b] : y[a] < y[b]; });
  std::vector<int> front;
  double best = std::numeric_limits<double>::infinity();
  for (int i : order)
    if (y[i] < best) {
      front.push_back(i);
      best = y[i];
    }
  return front;
}

Colour SeriesColour(int i) {
  static const char* kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b"};
  return Colour::Hex(kPalette[i % 7]);
}

}  // namespace btf
