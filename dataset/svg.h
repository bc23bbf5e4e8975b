// Small self-contained SVG charts for the HTML reports: no scripts, no fonts to fetch.
#pragma once

#include <string>
#include <vector>

namespace paircast::svg {

struct Series {
  std::string label;
  std::vector<double> x, y;
  std::string color = "#1f77b4";
  bool dashed = false;
  bool markers = true;
};

struct Axes {
  std::string title, xLabel, yLabel;
  int width = 560, height = 340;
};

// Escapes &, <, >, ' and " for text and attributes.
std::string escape(const std::string& text);

// Bars over [edges[i], edges[i+1]).
std::string histogram(const std::vector<double>& edges, const std::vector<double>& counts,
                      const Axes& axes);
// Lines (with markers) over shared axes, and a legend.
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

}  // namespace paircast::svg
