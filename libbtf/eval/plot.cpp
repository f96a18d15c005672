#include "libbtf/eval/plot.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "libbtf/core/error.h"

namespace btf {

std::string EscapeXml(const std::string& s) {
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

namespace {

struct Axis {
  bool log = false;
  double lo = 0, hi = 1;  // in axis units (log10 for log axes)
  std::vector<double> ticks;  // in data units
  double ToAxis(double v) const { return log ? std::log10(v) : v; }
};

// An axis over `values` drawn `pixels` long, with ticks at least `min_gap` pixels apart.
Axis MakeAxis(std::vector<double> values, bool want_log, double pixels, double min_gap) {
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
  auto gaps_ok = [&](const std::vector<double>& ticks) {
    for (std::size_t i = 1; i < ticks.size(); ++i)
      if ((a.ToAxis(ticks[i]) - a.ToAxis(ticks[i - 1])) / (a.hi - a.lo) * pixels < min_gap) return false;
    return true;
  };
  if (a.log) {
    // Decades, with intermediate mantissas where there is room: the densest set whose ticks are
    // min_gap apart; a range too short for two decade ticks gets linear ticks (below) instead.
    const int d0 = int(std::floor(a.lo)), d1 = int(std::ceil(a.hi));
    const int step = std::max(1, int(std::ceil((d1 - d0) / std::max(1.0, pixels / min_gap))));
    const std::vector<std::vector<double>> mantissas = {{1, 2, 3, 4, 5, 6, 7, 8, 9}, {1, 2, 3, 5}, {1, 2, 5}, {1, 3}, {1}};
    for (const auto& ms : mantissas) {
      std::vector<double> ticks;
      for (int d = d0; d <= d1; d += step)
        for (double m : ms) {
          if (m != 1.0 && step > 1) continue;
          const double v = m * std::pow(10.0, d);
          if (std::log10(v) >= a.lo && std::log10(v) <= a.hi) ticks.push_back(v);
        }
      if (gaps_ok(ticks) || ms.size() == 1) {
        a.ticks = ticks;
        break;
      }
    }
    if (a.ticks.size() >= 2) return a;
    a.ticks.clear();
  }
  // Linear ticks at 1, 2 or 5 times a power of ten, as many as fit (at most 7).
  const double vlo = a.log ? std::pow(10.0, a.lo) : a.lo, vhi = a.log ? std::pow(10.0, a.hi) : a.hi;
  for (int n = std::clamp(int(pixels / min_gap), 1, 6); n >= 1; --n) {
    const double raw = (vhi - vlo) / n;
    const double mag = std::pow(10.0, std::floor(std::log10(raw)));
    double step = mag;
    for (double m : {1.0, 2.0, 5.0, 10.0})
      if (m * mag >= raw) {
        step = m * mag;
        break;
      }
    std::vector<double> ticks;
    for (double v = std::ceil(vlo / step) * step; v <= vhi + 1e-9 * step; v += step)
      ticks.push_back(std::abs(v) < 1e-9 * step ? 0.0 : v);
    a.ticks = ticks;
    if (gaps_ok(ticks)) break;
  }
  return a;
}

std::string TickLabel(double v) { return fmt::format("{:.3g}", v); }

struct Axes {
  Axis x, y;
};

// Margins of the plot area: y tick labels on the left, x tick labels below, room for point labels
// on the right.
constexpr double kLeft = 66, kTop = 14, kBottom = 28, kRight = 30;

Axes MakeAxes(const Plot& plot) {
  std::vector<double> xs, ys;
  for (const auto& s : plot.series) xs.insert(xs.end(), s.x.begin(), s.x.end()), ys.insert(ys.end(), s.y.begin(), s.y.end());
  // Tick labels ("1e+07", 13 px) need about 45 px side by side, 18 px stacked.
  return {MakeAxis(xs, plot.log_x, plot.width - kLeft - kRight, 56),
          MakeAxis(ys, plot.log_y, plot.height - kTop - kBottom, 22)};
}

std::string Line(double x0, double y0, double x1, double y1, double width, const std::string& color,
                 double alpha = 1) {
  return fmt::format(
      "<line x1=\"{:.2f}\" y1=\"{:.2f}\" x2=\"{:.2f}\" y2=\"{:.2f}\" stroke=\"{}\" stroke-width=\"{:.2f}\"{}/>\n", x0, y0,
      x1, y1, color, width, alpha < 1 ? fmt::format(" stroke-opacity=\"{:.2f}\"", alpha) : "");
}

std::string Marker(double x, double y, int shape, double r, const std::string& color, bool ring) {
  const std::string paint = ring ? fmt::format("fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"", color)
                                 : fmt::format("fill=\"{}\"", color);
  switch (ring ? 0 : shape % 4) {
    case 1:
      return fmt::format("<rect x=\"{:.2f}\" y=\"{:.2f}\" width=\"{:.2f}\" height=\"{:.2f}\" {}/>\n", x - r * 0.85,
                         y - r * 0.85, 1.7 * r, 1.7 * r, paint);
    case 2:
      return fmt::format("<polygon points=\"{:.2f},{:.2f} {:.2f},{:.2f} {:.2f},{:.2f}\" {}/>\n", x, y - r * 1.1, x - r,
                         y + r * 0.8, x + r, y + r * 0.8, paint);
    case 3:
      return fmt::format("<polygon points=\"{:.2f},{:.2f} {:.2f},{:.2f} {:.2f},{:.2f} {:.2f},{:.2f}\" {}/>\n", x,
                         y - r * 1.2, x + r * 1.2, y, x, y + r * 1.2, x - r * 1.2, y, paint);
    default:
      return fmt::format("<circle cx=\"{:.2f}\" cy=\"{:.2f}\" r=\"{:.2f}\" {}/>\n", x, y, r, paint);
  }
}

// anchor: "start", "middle" or "end"; (x, y) = the anchor point on the text's baseline.
std::string Text(double x, double y, const std::string& text, const std::string& color, double size,
                 const char* anchor) {
  return fmt::format("<text x=\"{:.2f}\" y=\"{:.2f}\" text-anchor=\"{}\" font-size=\"{:.1f}\" fill=\"{}\">{}</text>\n",
                     x, y, anchor, size, color, EscapeXml(text));
}

std::string AxisName(const std::string& label, const Axis& axis) { return label + (axis.log ? " (log scale)" : ""); }

// The legend's key for one series: its marker shape (Unicode) in its color, with dashes for a line.
std::string LegendKey(const PlotSeries& s) {
  static constexpr const char* kShapes[] = {"&#9679;", "&#9632;", "&#9650;", "&#9670;"};
  const std::string mark = !s.markers ? "" : s.ring_markers ? "&#9675;" : kShapes[s.shape % 4];
  const std::string dash = s.line ? "&#8212;" : "";
  return fmt::format("<span class=\"key\" style=\"color:{}\">{}{}{}</span>", s.color.ToHex(), dash, mark, dash);
}

}  // namespace

Color Color::Hex(const std::string& hex) {
  if (hex.size() != 7 || hex[0] != '#' || hex.find_first_not_of("0123456789abcdefABCDEF", 1) != std::string::npos)
    ThrowUsage("colour '{}' is not of the form #rrggbb", hex);
  auto component = [&](int i) { return std::stoi(hex.substr(1 + 2 * i, 2), nullptr, 16) / 255.0; };
  return {component(0), component(1), component(2)};
}

std::string Color::ToHex() const {
  auto byte = [](double v) { return static_cast<int>(std::lround(std::clamp(v, 0.0, 1.0) * 255)); };
  return fmt::format("#{:02x}{:02x}{:02x}", byte(r), byte(g), byte(b));
}

std::string PlotSvg(const Plot& plot) {
  const std::string black = "#000000", gray = "#8c8c8c", light = "#e0e0e0";
  const Axes axes = MakeAxes(plot);
  const Axis &ax = axes.x, &ay = axes.y;
  const double left = kLeft, top = kTop, bottom = kBottom, right = kRight;
  const double pw = plot.width - left - right, ph = plot.height - top - bottom;
  auto X = [&](double v) { return left + (ax.ToAxis(v) - ax.lo) / (ax.hi - ax.lo) * pw; };
  auto Y = [&](double v) { return top + ph - (ay.ToAxis(v) - ay.lo) / (ay.hi - ay.lo) * ph; };

  std::string desc = AxisName(plot.y_label, ay) + " against " + AxisName(plot.x_label, ax) + ". Series:";
  for (const auto& s : plot.series) desc += " " + s.name + " (" + s.color.ToHex() + ");";
  std::string out = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
      "font-family=\"DejaVu Sans, sans-serif\">\n<title>{2}</title>\n<desc>{3}</desc>\n",
      plot.width, plot.height, EscapeXml(plot.title), EscapeXml(desc));
  out += fmt::format("<rect x=\"0\" y=\"0\" width=\"{}\" height=\"{}\" fill=\"#ffffff\"/>\n", plot.width, plot.height);
  // Grid, ticks and tick labels.
  for (double t : ax.ticks) {
    out += Line(X(t), top, X(t), top + ph, 1, light);
    out += Line(X(t), top + ph, X(t), top + ph + 4, 1, black);
    out += Text(X(t), top + ph + 18, TickLabel(t), black, 13, "middle");
  }
  for (double t : ay.ticks) {
    out += Line(left, Y(t), left + pw, Y(t), 1, light);
    out += Line(left - 4, Y(t), left, Y(t), 1, black);
    out += Text(left - 7, Y(t) + 4.5, TickLabel(t), black, 13, "end");
  }
  out += Line(left, top, left, top + ph, 1, black);
  out += Line(left, top + ph, left + pw, top + ph, 1, black);
  out += Line(left, top, left + pw, top, 1, gray);
  out += Line(left + pw, top, left + pw, top + ph, 1, gray);
  // Series: lines first, then markers, then point labels.
  for (const auto& s : plot.series) {
    if (!s.line) continue;
    for (std::size_t i = 1; i < s.x.size(); ++i)
      out += Line(X(s.x[i - 1]), Y(s.y[i - 1]), X(s.x[i]), Y(s.y[i]), 1.5, s.color.ToHex(), 0.8);
  }
  for (const auto& s : plot.series) {
    if (!s.markers) continue;
    for (std::size_t i = 0; i < s.x.size(); ++i)
      out += Marker(X(s.x[i]), Y(s.y[i]), s.shape, s.ring_markers ? 6.5 : 4, s.color.ToHex(), s.ring_markers);
  }
  for (const auto& s : plot.series)
    for (std::size_t i = 0; i < std::min(s.labels.size(), s.x.size()); ++i)
      out += Text(X(s.x[i]) + 6, Y(s.y[i]) - 6, s.labels[i], gray, 11, "start");
  out += "</svg>\n";
  return out;
}

std::string PlotCaptionHtml(const Plot& plot) {
  const Axes axes = MakeAxes(plot);
  std::string h = "<b>" + EscapeXml(plot.title) + "</b>. x: " + EscapeXml(AxisName(plot.x_label, axes.x)) +
                  "; y: " + EscapeXml(AxisName(plot.y_label, axes.y)) + ".<br>\n";
  for (const auto& s : plot.series) h += LegendKey(s) + "&nbsp;" + EscapeXml(s.name) + " &nbsp; ";
  return h;
}

std::string PlotFigureHtml(const Plot& plot) {
  return "<figure class=\"plot\">\n" + PlotSvg(plot) + "<figcaption>" + PlotCaptionHtml(plot) +
         "</figcaption>\n</figure>\n";
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

Color SeriesColor(int i) {
  static const char* kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b"};
  return Color::Hex(kPalette[i % 7]);
}

}  // namespace btf
