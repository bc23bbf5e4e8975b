// Small self-contained SVG charts for reports and training curves: no scripts, no fonts to
// fetch. Axes carry ticks at round values (1, 2 or 5 times a power of ten).
#pragma once

#include <string>
#include <vector>

namespace paircast::plot {

struct Series {
  std::string label;
  std::vector<double> x, y;
  // Optional half-widths of error bars, one per point (a bar from y - e to y + e, with caps);
  // a point whose e is NaN or <= 0 has none.
  std::vector<double> yErr;
  std::string color = "#1f77b4";
  bool dashed = false;
  bool markers = true;
};

struct Axes {
  std::string title, xLabel, yLabel;
  int width = 560, height = 340;
};

// Ticks of an axis over [lo, hi]: the multiples of one step that lie in the range, the step the
// smallest of 1, 2 or 5 times a power of ten that is at least (hi - lo) / target. So there are
// at most target + 1 ticks, and at least 2 when target >= 5. A single tick at lo when the ends
// are equal (or closer than a double can tell apart); none when an end is not finite or hi < lo.
struct Ticks {
  double step = 0;  // 0 when there is at most one tick
  std::vector<double> values;
};
Ticks ticks(double lo, double hi, int target = 6);
// A tick's label with as many decimals as the step needs: 0.25 -> "0.25", 1e6 steps -> "2e+06".
std::string tickLabel(double value, double step);

// Escapes &, <, >, ' and " for text and attributes.
std::string escape(const std::string& text);

// Bars over [edges[i], edges[i+1]).
std::string histogram(const std::vector<double>& edges, const std::vector<double>& counts,
                      const Axes& axes);
// Lines (with markers and any error bars) over shared axes, and a legend. The y axis spans
// the error bars too.
std::string lines(const std::vector<Series>& series, const Axes& axes);
// A heat map of counts[row][col] over x edges (cols) and y edges (rows), darker = more.
std::string heatmap(const std::vector<double>& xEdges, const std::vector<double>& yEdges,
                    const std::vector<std::vector<double>>& counts, const Axes& axes);
// Points with an optional direction segment each (dx, dy; 0 for none) coloured by a value in
// [0, 1], with a reference camera drawn at the origin looking up (+y).
struct Arrow {
  double x, y, dx, dy, value;
};
std::string cameraPlot(const std::vector<Arrow>& arrows, const Axes& axes);

}  // namespace paircast::plot
