#include "util/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace paircast::plot {
namespace {

struct Frame {
  double x0, x1, y0, y1;  // data range
  double left = 60, right = 20, top = 30, bottom = 45;
  int width = 0, height = 0;
  double px(double x) const { return left + (width - left - right) * (x - x0) / (x1 - x0); }
  double py(double y) const {
    return height - bottom - (height - top - bottom) * (y - y0) / (y1 - y0);
  }
};

std::string num(double v, const char* fmt = "%.4g") {
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

std::string open(const Axes& a) {
  return "<svg xmlns='http://www.w3.org/2000/svg' width='" + std::to_string(a.width) +
         "' height='" + std::to_string(a.height) + "' viewBox='0 0 " + std::to_string(a.width) +
         " " + std::to_string(a.height) +
         "' font-family='sans-serif' font-size='11'><rect width='100%' height='100%' "
         "fill='white'/>";
}

// Axis lines, ticks at round values on each axis with grid lines across, labels and title.
std::string frame(const Frame& f, const Axes& a) {
  std::string s;
  const double L = f.left, R = f.width - f.right, T = f.top, B = f.height - f.bottom;
  s += "<path d='M" + num(L) + " " + num(T) + " V" + num(B) + " H" + num(R) +
       "' stroke='#333' fill='none'/>";
  const Ticks xs = ticks(f.x0, f.x1), ys = ticks(f.y0, f.y1);
  for (double x : xs.values) {
    s += "<path d='M" + num(f.px(x)) + " " + num(B) + " v4' stroke='#333'/>";
    s += "<text x='" + num(f.px(x)) + "' y='" + num(B + 15) + "' text-anchor='middle'>" +
         tickLabel(x, xs.step) + "</text>";
  }
  for (double y : ys.values) {
    s += "<text x='" + num(L - 4) + "' y='" + num(f.py(y) + 4) + "' text-anchor='end'>" +
         tickLabel(y, ys.step) + "</text>";
    s += "<path d='M" + num(L) + " " + num(f.py(y)) + " H" + num(R) +
         "' stroke='#ddd' stroke-width='0.5'/>";
  }
  s += "<text x='" + num((L + R) / 2) + "' y='" + num(f.height - 8.0) + "' text-anchor='middle'>" +
       escape(a.xLabel) + "</text>";
  s += "<text transform='translate(14," + num((T + B) / 2) +
       ") rotate(-90)' text-anchor='middle'>" + escape(a.yLabel) + "</text>";
  s += "<text x='" + num((L + R) / 2) + "' y='18' text-anchor='middle' font-size='13'>" +
       escape(a.title) + "</text>";
  return s;
}

std::string viridis(double t) {  // a short viridis-like ramp
  static const double c[5][3] = {
      {68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * 4;
  const int i = std::min(3, static_cast<int>(t));
  const double u = t - i;
  char b[16];
  std::snprintf(b, sizeof b, "#%02x%02x%02x",
                static_cast<int>(c[i][0] + u * (c[i + 1][0] - c[i][0])),
                static_cast<int>(c[i][1] + u * (c[i + 1][1] - c[i][1])),
                static_cast<int>(c[i][2] + u * (c[i + 1][2] - c[i][2])));
  return b;
}

// m x 10^e, computed so that decimal steps are the nearest doubles (0.1, not 0.1000...2).
double decimal(double m, int e) {
  return e >= 0 ? m * std::pow(10.0, e) : m / std::pow(10.0, -e);
}

}  // namespace

Ticks ticks(double lo, double hi, int target) {
  Ticks t;
  if (!std::isfinite(lo) || !std::isfinite(hi) || hi < lo) return t;
  target = std::max(1, target);
  // Halves first: hi - lo may overflow where the step does not.
  const double raw = (hi / 2 - lo / 2) * (2.0 / target);
  const double scale = std::max(std::abs(lo), std::abs(hi));
  if (!(raw > scale * 1e-12) || raw < std::numeric_limits<double>::min() * 1e3) {
    t.values = {lo};  // equal ends, or a span below what the ends' precision can tell
    return t;
  }
  int e = static_cast<int>(std::floor(std::log10(raw)));
  double m = 0;
  for (double c : {1.0, 2.0, 5.0})
    if (m == 0 && decimal(c, e) >= raw * (1 - 1e-9)) m = c;
  if (m == 0) m = 1, ++e;
  t.step = decimal(m, e);
  // Multiples k x step within the range, allowing for rounding at the ends.
  const double k0 = std::ceil(lo / t.step - 1e-9), k1 = std::floor(hi / t.step + 1e-9);
  for (int i = 0; k0 + i <= k1 && i <= target + 2; ++i) {  // |k| < 1e12: exact in a double
    const double v = decimal((k0 + i) * m, e);
    t.values.push_back(v == 0 ? 0.0 : v);  // no "-0"
  }
  return t;
}

std::string tickLabel(double value, double step) {
  char b[64];
  if (value == 0) value = 0;  // no "-0"
  if (!std::isfinite(value) || !std::isfinite(step)) step = 0;
  if (step > 0 && step >= 1e-4 && std::abs(value) < 1e6) {
    const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
    std::snprintf(b, sizeof b, "%.*f", decimals, value);
  } else {
    // As many significant digits as the step's position below the value's leading digit.
    int digits = 4;
    if (step > 0 && std::isfinite(value) && value != 0)
      digits = std::clamp(static_cast<int>(std::floor(std::log10(std::abs(value)) + 1e-9) -
                                           std::floor(std::log10(step) + 1e-9)) +
                              1,
                          1, 17);
    std::snprintf(b, sizeof b, "%.*g", digits, value);
  }
  return b;
}

std::string escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '\'':
        out += "&#39;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string histogram(const std::vector<double>& edges, const std::vector<double>& counts,
                      const Axes& a) {
  double top = 1;
  for (double c : counts) top = std::max(top, c);
  Frame f{edges.front(), edges.back(), 0, top * 1.05};
  f.width = a.width, f.height = a.height;
  std::string s = open(a);
  for (size_t i = 0; i + 1 < edges.size() && i < counts.size(); ++i) {
    const double x = f.px(edges[i]), w = f.px(edges[i + 1]) - x, y = f.py(counts[i]);
    s += "<rect x='" + num(x + 0.5) + "' y='" + num(y) + "' width='" + num(std::max(0.5, w - 1)) +
         "' height='" + num(f.py(0) - y) + "' fill='#4c78a8'><title>" + num(edges[i]) + "-" +
         num(edges[i + 1]) + ": " + num(counts[i], "%.0f") + "</title></rect>";
  }
  return s + frame(f, a) + "</svg>\n";
}

namespace {
// The half-width of point i's error bar; 0 when it has none.
double errorBar(const Series& s, size_t i) {
  return i < s.yErr.size() && std::isfinite(s.yErr[i]) && s.yErr[i] > 0 ? s.yErr[i] : 0.0;
}
}  // namespace

std::string lines(const std::vector<Series>& series, const Axes& a) {
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      const double e = errorBar(s, i);
      x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, s.y[i] - e), y1 = std::max(y1, s.y[i] + e);
    }
  if (x0 > x1) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (x1 <= x0) x1 = x0 + 1;
  const double pad = (y1 - y0) > 0 ? 0.08 * (y1 - y0) : std::max(1e-6, 0.1 * std::abs(y0));
  Frame f{x0, x1, y0 - pad, y1 + pad};
  f.width = a.width, f.height = a.height, f.right = 130;
  std::string s = open(a) + frame(f, a);
  int row = 0;
  for (const auto& se : series) {
    std::string pts;
    for (size_t i = 0; i < se.x.size() && i < se.y.size(); ++i)
      if (std::isfinite(se.y[i])) pts += num(f.px(se.x[i])) + "," + num(f.py(se.y[i])) + " ";
    s += "<polyline fill='none' stroke='" + se.color + "' stroke-width='2'" +
         (se.dashed ? " stroke-dasharray='6 4'" : "") + " points='" + pts + "'/>";
    for (size_t i = 0; i < se.x.size() && i < se.y.size(); ++i)
      if (const double e = errorBar(se, i); std::isfinite(se.y[i]) && e > 0) {
        const std::string x = num(f.px(se.x[i])), lo = num(f.py(se.y[i] - e)),
                          hi = num(f.py(se.y[i] + e));
        s += "<path d='M" + x + " " + lo + " V" + hi + " m-4 0 h8 M" + num(f.px(se.x[i]) - 4) +
             " " + lo + " h8' stroke='" + se.color + "' stroke-width='1.5' fill='none'/>";
      }
    if (se.markers)
      for (size_t i = 0; i < se.x.size() && i < se.y.size(); ++i)
        if (std::isfinite(se.y[i]))
          s += "<circle cx='" + num(f.px(se.x[i])) + "' cy='" + num(f.py(se.y[i])) +
               "' r='3' fill='" + se.color + "'><title>" + escape(se.label) + " " + num(se.x[i]) +
               ": " + num(se.y[i]) + "</title></circle>";
    const double ly = f.top + 10 + 16 * row++;
    s += "<path d='M" + num(a.width - 122.0) + " " + num(ly) + " h22' stroke='" + se.color +
         "' stroke-width='2'" + (se.dashed ? " stroke-dasharray='6 4'" : "") + "/>";
    s += "<text x='" + num(a.width - 96.0) + "' y='" + num(ly + 4) + "'>" + escape(se.label) +
         "</text>";
  }
  return s + "</svg>\n";
}

std::string heatmap(const std::vector<double>& xEdges, const std::vector<double>& yEdges,
                    const std::vector<std::vector<double>>& counts, const Axes& a) {
  double top = 1;
  for (const auto& r : counts)
    for (double c : r) top = std::max(top, c);
  Frame f{xEdges.front(), xEdges.back(), yEdges.front(), yEdges.back()};
  f.width = a.width, f.height = a.height;
  std::string s = open(a);
  for (size_t r = 0; r + 1 < yEdges.size() && r < counts.size(); ++r)
    for (size_t c = 0; c + 1 < xEdges.size() && c < counts[r].size(); ++c) {
      if (counts[r][c] <= 0) continue;
      const double x = f.px(xEdges[c]), y = f.py(yEdges[r + 1]);
      s += "<rect x='" + num(x) + "' y='" + num(y) + "' width='" + num(f.px(xEdges[c + 1]) - x) +
           "' height='" + num(f.py(yEdges[r]) - y) + "' fill='" +
           viridis(std::sqrt(counts[r][c] / top)) + "'><title>" + num(counts[r][c], "%.0f") +
           "</title></rect>";
    }
  return s + frame(f, a) + "</svg>\n";
}

std::string cameraPlot(const std::vector<Arrow>& arrows, const Axes& a) {
  double r = 1;
  for (const auto& p : arrows)
    if (std::isfinite(p.x) && std::isfinite(p.y)) r = std::max({r, std::abs(p.x), std::abs(p.y)});
  r *= 1.1;
  Frame f{-r, r, -r, r};
  f.width = a.width, f.height = a.height;
  std::string s = open(a);
  const double len = 0.06 * r;
  for (const auto& p : arrows) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) continue;
    const std::string col = viridis(p.value);
    s += "<circle cx='" + num(f.px(p.x)) + "' cy='" + num(f.py(p.y)) + "' r='2' fill='" + col +
         "'/>";
    if (p.dx != 0 || p.dy != 0)
      s += "<path d='M" + num(f.px(p.x)) + " " + num(f.py(p.y)) + " L" +
           num(f.px(p.x + len * p.dx)) + " " + num(f.py(p.y + len * p.dy)) + "' stroke='" + col +
           "' stroke-width='0.8'/>";
  }
  // The reference camera: a triangle at the origin, looking up the page.
  s += "<path d='M" + num(f.px(0)) + " " + num(f.py(0) - 10) + " L" + num(f.px(0) - 6) + " " +
       num(f.py(0) + 6) + " L" + num(f.px(0) + 6) + " " + num(f.py(0) + 6) + " Z' fill='#d62728'/>";
  return s + frame(f, a) + "</svg>\n";
}

}  // namespace paircast::plot
