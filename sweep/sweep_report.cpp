#include "sweep/sweep_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "util/atomic_file.h"
#include "util/html.h"
#include "util/plot.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

// A result for the CSV file and the page: obj[key] as %.6g, nan when it is missing or no number.
std::string num(const nlohmann::json& obj, const char* key) {
  const auto it = obj.find(key);
  return html::number(it != obj.end() && it->is_number() ? it->get<double>() : NAN, "%.6g");
}

std::string resultsCsv(const nlohmann::json& rows, const nlohmann::json& random) {
  std::string csv =
      "mode,center,set,pairs,mean_covis,train_loss,xv_loss,probe_delta1,probe_absrel,probe_rmse\n";
  for (const auto& r : rows)
    csv += r["mode"].get<std::string>() + "," + centerName(r["center"]) + "," +
           r["set"].get<std::string>() + "," + std::to_string(r["pairs"].get<int>()) + "," +
           num(r, "mean_covis") + "," + num(r, "train_loss") + "," + num(r, "xv_loss") + "," +
           num(r, "probe_delta1") + "," + num(r, "probe_absrel") + "," + num(r, "probe_rmse") +
           "\n";
  csv += "random,,random_encoder,0,," + std::string(",") + num(random, "xv_loss") + "," +
         num(random, "probe_delta1") + "," + num(random, "probe_absrel") + "," +
         num(random, "probe_rmse") + "\n";
  return csv;
}

void writePlots(const SweepConfig& c, const nlohmann::json& rows, const nlohmann::json& random) {
  const fs::path out(c.out);
  const char* colors[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd"};
  struct Metric {
    const char* key;
    const char* label;
  } metrics[] = {{"xv_loss", "held-out completion loss (covis ~0.5), lower is better"},
                 {"probe_delta1", "depth probe delta1, higher is better"},
                 {"probe_absrel", "depth probe AbsRel, lower is better"},
                 {"probe_rmse", "depth probe RMSE (m), lower is better"}};
  for (const auto& m : metrics) {
    std::vector<plot::Series> series;
    int k = 0;
    for (const auto& mode : c.modes) {
      plot::Series s;
      s.label = mode;
      s.color = colors[k++ % 4];
      for (const auto& r : rows)
        if (r["mode"] == mode) s.x.push_back(r["center"]), s.y.push_back(r[m.key]);
      series.push_back(s);
    }
    // The random encoder as a dashed line, unless it lies so far from the sets that the line
    // would flatten them (as the completion loss's can, far above every set's); then in the title.
    const double baseline = random[m.key].get<double>();
    double lo = INFINITY, hi = -INFINITY;
    for (const auto& s : series)
      for (double y : s.y) lo = std::min(lo, y), hi = std::max(hi, y);
    std::string title = m.label;
    if (lo <= hi && (baseline < lo - 3 * (hi - lo) || baseline > hi + 3 * (hi - lo))) {
      char note[96];
      std::snprintf(note, sizeof note, "; random encoder %.3f", baseline);
      title += note;
    } else {
      plot::Series base;
      base.label = "random encoder";
      base.color = "#7f7f7f";
      base.dashed = true;
      base.markers = false;
      base.x = {c.centers.front(), c.centers.back()};
      base.y = {baseline, baseline};
      series.push_back(base);
    }
    writeFileAtomic(
        (out / (std::string("plot_") + m.key + ".svg")).string(),
        plot::lines(series, {title, "covis centre of the training set", m.key, 620, 340}));
  }
}

// summary.html: what was trained, the plots, and a table of the sets and both baselines.
std::string summaryPage(const SweepConfig& c, const nlohmann::json& rows,
                        const nlohmann::json& random, const nlohmann::json& constant) {
  std::string page =
      html::pageStart("covis_sweep results", html::style(1300)) +
      html::heading(1, "Co-visibility sweep") +
      html::paragraph(
          std::to_string(rows.size()) + " training sets of " + std::to_string(c.pairsPerSet) +
          " pairs (" + plot::escape(c.preset) + " model, " + std::to_string(c.steps) +
          " steps of " + std::to_string(c.batchSize) + " at " + std::to_string(c.imgSize) +
          " px), evaluated on held-out scenes. Data: " + html::link("results.csv", "results.csv") +
          ", " + html::link("results.json", "results.json") + ".");
  for (const char* m : {"xv_loss", "probe_delta1", "probe_absrel", "probe_rmse"})
    page += html::image("plot_" + std::string(m) + ".svg", m) + "\n";
  page += html::tableStart(
      {"set", "mean covis", "train loss", "xv loss", "delta1", "AbsRel", "RMSE", "dataset"});
  for (const auto& r : rows) {
    const std::string set = r["set"].get<std::string>();
    page += html::labelledRow(
        set, {num(r, "mean_covis"), num(r, "train_loss"), num(r, "xv_loss"), num(r, "probe_delta1"),
              num(r, "probe_absrel"), num(r, "probe_rmse"),
              c.reports ? html::link("sets/" + set + "/report.html", "report") : "-"});
  }
  page += html::labelledRow("random encoder",
                            {"", "", num(random, "xv_loss"), num(random, "probe_delta1"),
                             num(random, "probe_absrel"), num(random, "probe_rmse"), ""});
  page += html::labelledRow("constant depth (no encoder)",
                            {"", "", "", num(constant, "probe_delta1"),
                             num(constant, "probe_absrel"), num(constant, "probe_rmse"), ""});
  return page + html::tableEnd() + html::pageEnd();
}

}  // namespace

void writeSweepReport(const SweepConfig& c, const nlohmann::json& results) {
  const fs::path out(c.out);
  const nlohmann::json& rows = results.at("rows");
  const nlohmann::json& random = results.at("random_encoder");
  const nlohmann::json& constant = results.at("constant_depth");
  writeFileAtomic((out / "results.csv").string(), resultsCsv(rows, random));
  writeFileAtomic((out / "results.json").string(), results.dump(1) + "\n");
  writePlots(c, rows, random);
  writeFileAtomic((out / "summary.html").string(), summaryPage(c, rows, random, constant));
}

}  // namespace paircast
