#include "sweep/sweep_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "sweep/sweep_stats.h"
#include "util/atomic_file.h"
#include "util/html.h"
#include "util/plot.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

// The metrics the verdicts compare, each with its better direction and a name for the page.
struct Metric {
  const char* key;
  bool higherIsBetter;
  const char* label;
};
const Metric kEvaluated[] = {{"xv_loss", false, "held-out completion loss (covis ~0.5)"},
                             {"probe_delta1", true, "depth probe delta1"},
                             {"probe_absrel", false, "depth probe AbsRel"},
                             {"probe_rmse", false, "depth probe RMSE (m)"}};

// Whether two runs' figures of `m` can be compared: the completion loss only between models of
// the same task (mae completes without the reference view), the probe always.
bool comparable(const Metric& m, const std::string& taskA, const std::string& taskB) {
  return std::string(m.key) != "xv_loss" || taskA == taskB;
}

// obj[key] as %.6g for the CSV files; nan when it is missing or no number.
std::string num(const nlohmann::json& obj, const std::string& key) {
  return html::number(numberOrNan(obj, key), "%.6g");
}

std::string text(const nlohmann::json& obj, const char* key) {
  const auto it = obj.find(key);
  return it != obj.end() && it->is_string() ? it->get<std::string>() : "";
}

std::string centerCell(const nlohmann::json& row) {
  return row.value("center", nlohmann::json()).is_number() ? centerName(row["center"]) : "";
}

// The columns both CSV files open with, naming the set (or baseline) a row is of.
const char* const kSetColumns = "mode,center,set,task,trained_on";
std::string setCells(const nlohmann::json& r) {
  return text(r, "mode") + "," + centerCell(r) + "," + text(r, "set") + "," + text(r, "task") +
         "," + text(r, "trained_on");
}

// "0.472 ± 0.010" (or "0.472" with one seed).
std::string withInterval(double mean, double halfWidth) {
  char b[64];
  if (std::isfinite(halfWidth))
    std::snprintf(b, sizeof b, "%.3f \u00b1 %.3f", mean, halfWidth);
  else
    std::snprintf(b, sizeof b, "%.3f", mean);
  return b;
}

// Every run's value of `metric`, by set, in order of first appearance.
struct RunValues {
  std::vector<std::string> sets;
  std::map<std::string, std::vector<double>> values;
  std::map<std::string, std::string> task;
};

RunValues byset(const nlohmann::json& runs, const std::string& metric) {
  RunValues r;
  for (const auto& run : runs) {
    const std::string set = run.at("set");
    if (!r.values.count(set)) r.sets.push_back(set), r.task[set] = text(run, "task");
    r.values[set].push_back(numberOrNan(run, metric));
  }
  return r;
}

// ---- results.csv and results_runs.csv ----

std::string resultsCsv(const nlohmann::json& rows, const nlohmann::json& random) {
  std::string csv = std::string(kSetColumns) + ",seeds,pairs,mean_covis";
  for (const auto& m : sweepMetrics()) csv += "," + m + "_mean," + m + "_ci95";
  csv += "\n";
  auto line = [&](const nlohmann::json& r) {
    std::string l = setCells(r) + "," + std::to_string(r.value("seeds", 0)) + "," +
                    std::to_string(r.value("pairs", 0)) + "," + num(r, "mean_covis");
    for (const auto& m : sweepMetrics()) l += "," + num(r, m + "_mean") + "," + num(r, m + "_ci95");
    return l + "\n";
  };
  for (const auto& r : rows) csv += line(r);
  return csv + line(random);
}

std::string runsCsv(const nlohmann::json& runs, const nlohmann::json& randomRuns) {
  std::string csv = std::string(kSetColumns) + ",seed_index,seed,pairs,mean_covis";
  for (const auto& m : sweepMetrics()) csv += "," + m;
  csv += "\n";
  for (const auto* list : {&runs, &randomRuns})
    for (const auto& r : *list) {
      csv += setCells(r) + "," + std::to_string(r.value("seed_index", 0)) + "," +
             std::to_string(r.value("seed", uint64_t{0})) + "," +
             std::to_string(r.value("pairs", 0)) + "," + num(r, "mean_covis");
      for (const auto& m : sweepMetrics()) csv += "," + num(r, m);
      csv += "\n";
    }
  return csv;
}

// ---- the verdicts ----

// a minus b in the metric's better direction (> 0: a is better), with Welch's interval.
Interval gain(const std::vector<double>& a, const std::vector<double>& b, const Metric& m) {
  Interval d = differenceInterval95(a, b);
  if (!m.higherIsBetter) d.mean = -d.mean;
  return d;
}

std::string signedInterval(const Interval& d) {
  char b[64];
  if (std::isfinite(d.halfWidth))
    std::snprintf(b, sizeof b, "%+.3f \u00b1 %.3f", d.mean, d.halfWidth);
  else
    std::snprintf(b, sizeof b, "%+.3f (no interval: one seed)", d.mean);
  return b;
}

// "bin_0.15 (-0.030 ± 0.012), mae (-0.041 ± 0.009)", or "none".
std::string listOf(const std::vector<std::string>& items) {
  if (items.empty()) return "none";
  std::string s;
  for (const auto& i : items) s += (s.empty() ? "" : ", ") + i;
  return s;
}

// Against the best set and against the random encoder, for one metric. The completion loss of
// a baseline with another task (mae completes without a reference) is not compared.
std::vector<std::string> metricVerdicts(const Metric& m, const RunValues& v,
                                        const std::vector<double>& random) {
  auto mean = [&](const std::string& s) { return interval95(v.values.at(s)).mean; };
  std::vector<std::string> sets;  // those with a figure (a set whose every run failed has none)
  for (const auto& s : v.sets)
    if (comparable(m, v.task.at(s), "croco") && std::isfinite(mean(s))) sets.push_back(s);
  if (sets.empty()) return {};
  const std::string best =
      *std::max_element(sets.begin(), sets.end(), [&](const std::string& a, const std::string& b) {
        return m.higherIsBetter ? mean(a) < mean(b) : mean(a) > mean(b);
      });
  std::vector<std::string> beyond, within, beats, notBeats;
  for (const auto& s : sets) {
    if (s != best) {
      const Interval d = gain(v.values.at(s), v.values.at(best), m);
      (excludesZero(d) ? beyond : within).push_back(s + " (" + signedInterval(d) + ")");
    }
    const Interval r = gain(v.values.at(s), random, m);
    (excludesZero(r) && r.mean > 0 ? beats : notBeats)
        .push_back(s + " (" + signedInterval(r) + ")");
  }
  const Interval b = interval95(v.values.at(best)), rnd = interval95(random);
  if (!std::isfinite(b.halfWidth))
    return {std::string(m.label) + ": the best is " + best + ", " +
            withInterval(b.mean, b.halfWidth) +
            ". With one seed there are no intervals, so no difference is told from noise (use "
            "--seeds 3)."};
  return {std::string(m.label) + ": the best is " + best + ", " +
              withInterval(b.mean, b.halfWidth) + ". Behind it by more than the interval: " +
              listOf(beyond) + ". Within the interval of it: " + listOf(within) + ".",
          std::string(m.label) + ": better than the random encoder (" +
              withInterval(rnd.mean, rnd.halfWidth) +
              ") by more than the interval: " + listOf(beats) + ". Not: " + listOf(notBeats) + "."};
}

// A claim that `a` beats each of `others` on the depth probe's metrics (and on the completion
// loss when all are cross-view sets): "holds" when it wins every comparison beyond the
// interval, "does not hold" when it loses one beyond it, else "unresolved at this scale".
std::string claimVerdict(const std::string& claim, const std::string& a,
                         const std::vector<std::string>& others,
                         const std::map<std::string, RunValues>& values) {
  int wins = 0, losses = 0, total = 0;
  bool intervals = true;
  std::string detail;
  for (const Metric& m : kEvaluated) {
    const RunValues& v = values.at(m.key);
    bool same = true;
    for (const auto& o : others) same = same && comparable(m, v.task.at(a), v.task.at(o));
    if (!same) continue;
    for (const auto& o : others) {
      const Interval d = gain(v.values.at(a), v.values.at(o), m);
      ++total;
      intervals = intervals && std::isfinite(d.halfWidth);
      if (excludesZero(d)) ++(d.mean > 0 ? wins : losses);
      detail +=
          std::string(detail.empty() ? "" : "; ") + m.key + " vs " + o + " " + signedInterval(d);
    }
  }
  const char* verdict = !intervals      ? "cannot be judged with one seed (use --seeds 3)"
                        : wins == total ? "holds"
                        : losses > 0    ? "does not hold"
                                        : "is not resolved at this scale";
  return claim + ": " + verdict + " (" + a + " is ahead by more than the interval in " +
         std::to_string(wins) + " of " + std::to_string(total) +
         " comparisons and behind by more than it in " + std::to_string(losses) + "; its gains " +
         "with their 95 % intervals, positive when " + a + " is better: " + detail + ").";
}

// The paper's claims about the reference set (the bin set nearest 0.5, which mae trains on),
// where the sweep has the runs they need.
std::vector<std::string> claimVerdicts(const nlohmann::json& runs, const std::string& reference,
                                       const std::map<std::string, RunValues>& values) {
  const RunValues& any = values.begin()->second;
  if (!any.values.count(reference)) return {};
  std::vector<std::pair<double, std::string>> bins;  // (centre, set) of the bin sets
  for (const auto& r : runs) {
    const nlohmann::json center = r.value("center", nlohmann::json());
    if (r.value("mode", "") == "bin" && center.is_number())
      bins.emplace_back(center.get<double>(), r.value("set", ""));
  }
  std::sort(bins.begin(), bins.end());
  bins.erase(std::unique(bins.begin(), bins.end()), bins.end());
  std::vector<std::string> out;
  // Claim 1: against the lowest and the highest bin, those that are not the reference itself.
  const bool referenceIsABin =
      std::any_of(bins.begin(), bins.end(), [&](const auto& b) { return b.second == reference; });
  std::vector<std::string> ends, sides;
  if (referenceIsABin && bins.front().second != reference)
    ends.push_back(bins.front().second), sides.push_back("low");
  if (referenceIsABin && bins.back().second != reference)
    ends.push_back(bins.back().second), sides.push_back("high");
  if (!ends.empty())
    out.push_back(claimVerdict("Claim 1, covis near 0.5 beats " + sides.front() +
                                   (sides.size() > 1 ? " and " + sides.back() : "") + " covis",
                               reference, ends, values));
  if (any.values.count("mae"))
    out.push_back(claimVerdict("Claim 2, cross-view completion beats auto-completion (MAE)",
                               reference, {"mae"}, values));
  return out;
}

// ---- the plots and the page ----

// One line per mode over the covis centres, with error bars.
std::vector<plot::Series> modeSeries(const SweepConfig& c, const nlohmann::json& rows,
                                     const Metric& m) {
  const char* colors[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd"};
  const std::string mean = std::string(m.key) + "_mean", ci = std::string(m.key) + "_ci95";
  std::vector<plot::Series> series;
  for (const auto& mode : c.modes) {
    plot::Series s;
    s.label = mode;
    s.color = colors[series.size() % 4];
    for (const auto& r : rows)
      if (r["mode"] == mode)
        s.x.push_back(r["center"]), s.y.push_back(numberOrNan(r, mean)),
            s.yErr.push_back(numberOrNan(r, ci));
    series.push_back(s);
  }
  return series;
}

// A baseline's mean as a dashed line over the centres, its interval in the legend.
plot::Series baselineSeries(const SweepConfig& c, std::string label, const char* color,
                            const nlohmann::json& row, const Metric& m) {
  const double mean = numberOrNan(row, std::string(m.key) + "_mean");
  if (const double e = numberOrNan(row, std::string(m.key) + "_ci95"); std::isfinite(e))
    label += " \u00b1" + html::number(e, "%.3f");
  plot::Series base;
  base.label = label;
  base.color = color;
  base.dashed = true;
  base.markers = false;
  base.x = {c.centers.front(), c.centers.back()};
  base.y = {mean, mean};
  return base;
}

// Whether a baseline at y lies so far from the other lines that drawing it would flatten them
// (as the random encoder's completion loss does, far above every set's).
bool offTheScale(const std::vector<plot::Series>& series, double y) {
  double lo = INFINITY, hi = -INFINITY;
  for (const auto& s : series)
    for (double v : s.y) lo = std::min(lo, v), hi = std::max(hi, v);
  return lo <= hi && (y < lo - 3 * (hi - lo) || y > hi + 3 * (hi - lo));
}

// plot_<metric>.svg: the modes, mae (not in the completion loss's: its task is another) and the
// random encoder, which goes in the title instead when it is off the scale.
void writePlots(const SweepConfig& c, const nlohmann::json& rows, const nlohmann::json& random) {
  for (const Metric& m : kEvaluated) {
    std::vector<plot::Series> series = modeSeries(c, rows, m);
    for (const auto& r : rows)
      if (r["task"] != "croco" && comparable(m, r["task"], "croco"))
        series.push_back(baselineSeries(c, text(r, "set"), "#d62728", r, m));
    std::string title = m.label;
    const double randomMean = numberOrNan(random, std::string(m.key) + "_mean");
    if (offTheScale(series, randomMean))
      title += "; random encoder " + html::number(randomMean, "%.3f");
    else
      series.push_back(baselineSeries(c, "random", "#7f7f7f", random, m));
    title += std::string(m.higherIsBetter ? ", higher" : ", lower") + " is better";
    writeFileAtomic(
        (fs::path(c.out) / (std::string("plot_") + m.key + ".svg")).string(),
        plot::lines(series, {title, "covis centre of the training set", m.key, 620, 340}));
  }
}

std::string cell(const nlohmann::json& r, const std::string& metric) {
  const double mean = numberOrNan(r, metric + "_mean");
  return std::isfinite(mean) ? withInterval(mean, numberOrNan(r, metric + "_ci95")) : "";
}

// summary.html: what was trained, the verdicts, the plots, and the table of sets and baselines.
std::string summaryPage(const SweepConfig& c, const nlohmann::json& results) {
  const nlohmann::json& rows = results.at("rows");
  const nlohmann::json& random = results.at("random_encoder");
  const nlohmann::json& constant = results.at("constant_depth");
  std::string page =
      html::pageStart("covis_sweep results", html::style(1300)) +
      html::heading(1, "Co-visibility sweep") +
      html::paragraph(std::to_string(rows.size()) + " training sets and baselines of " +
                      std::to_string(c.pairsPerSet) + " pairs, each trained with " +
                      std::to_string(c.seeds) + " seed(s) (" + plot::escape(c.preset) + " model, " +
                      std::to_string(c.steps) + " steps of " + std::to_string(c.batchSize) +
                      " at " + std::to_string(c.imgSize) +
                      " px), evaluated on held-out scenes. Figures are means over "
                      "the seeds \u00b1 the half-width of a 95 % t-interval. Data: " +
                      html::link("results.csv", "results.csv") + " (per set), " +
                      html::link("results_runs.csv", "results_runs.csv") + " (per run), " +
                      html::link("results.json", "results.json") + ".") +
      html::heading(2, "Verdicts");
  for (const auto& v : results.at("verdicts")) page += html::paragraph(plot::escape(v));
  for (const Metric& m : kEvaluated)
    page += html::image("plot_" + std::string(m.key) + ".svg", m.key) + "\n";
  page += html::tableStart({"set", "seeds", "mean covis", "train loss", "xv loss", "delta1",
                            "AbsRel", "RMSE", "dataset"});
  for (const auto& r : rows) {
    const std::string set = r["set"].get<std::string>();
    page += html::labelledRow(
        set + (r["task"] == "mae" ? " (xv loss: its own task)" : ""),
        {std::to_string(r.value("seeds", 0)), num(r, "mean_covis"), cell(r, "train_loss"),
         cell(r, "xv_loss"), cell(r, "probe_delta1"), cell(r, "probe_absrel"),
         cell(r, "probe_rmse"),
         c.reports ? html::link("sets/" + text(r, "trained_on") + "/report.html", "report") : "-"});
  }
  page += html::labelledRow(
      "random encoder",
      {std::to_string(random.value("seeds", 0)), "", "", cell(random, "xv_loss"),
       cell(random, "probe_delta1"), cell(random, "probe_absrel"), cell(random, "probe_rmse"), ""});
  page += html::labelledRow("constant depth (no encoder)",
                            {"", "", "", "", num(constant, "probe_delta1"),
                             num(constant, "probe_absrel"), num(constant, "probe_rmse"), ""});
  return page + html::tableEnd() + html::pageEnd();
}

}  // namespace

const std::vector<std::string>& sweepMetrics() {
  static const std::vector<std::string> metrics = [] {
    std::vector<std::string> m = {"train_loss"};
    for (const Metric& e : kEvaluated) m.push_back(e.key);
    return m;
  }();
  return metrics;
}

double numberOrNan(const nlohmann::json& obj, const std::string& key) {
  const auto it = obj.find(key);
  return it != obj.end() && it->is_number() ? it->get<double>() : NAN;
}

nlohmann::json aggregateRuns(const nlohmann::json& runs) {
  nlohmann::json rows = nlohmann::json::array();
  std::map<std::string, size_t> index;
  for (const auto& run : runs) {
    const std::string set = run.at("set");
    if (index.count(set)) continue;
    index[set] = rows.size();
    nlohmann::json row;
    for (const char* f : {"mode", "center", "set", "task", "trained_on", "pairs", "mean_covis"})
      if (run.contains(f)) row[f] = run[f];
    rows.push_back(row);
  }
  for (const auto& m : sweepMetrics()) {
    const RunValues v = byset(runs, m);
    for (const auto& set : v.sets) {
      const Interval i = interval95(v.values.at(set));
      nlohmann::json& row = rows[index.at(set)];
      row["seeds"] = v.values.at(set).size();
      row[m + "_mean"] = i.mean;  // nlohmann writes NaN as null
      row[m + "_ci95"] = i.halfWidth;
    }
  }
  return rows;
}

std::vector<std::string> sweepVerdicts(const nlohmann::json& results) {
  const nlohmann::json& runs = results.at("runs");
  std::map<std::string, RunValues> values;
  std::vector<std::string> out;
  for (const Metric& m : kEvaluated) {
    values[m.key] = byset(runs, m.key);
    const std::vector<double> random =
        byset(results.at("random_runs"), m.key).values["random_encoder"];
    for (auto& line : metricVerdicts(m, values[m.key], random)) out.push_back(std::move(line));
  }
  // The claims come first.
  std::vector<std::string> claims =
      claimVerdicts(runs, results.value("reference_set", std::string()), values);
  out.insert(out.begin(), claims.begin(), claims.end());
  return out;
}

void writeSweepReport(const SweepConfig& c, const nlohmann::json& results) {
  const fs::path out(c.out);
  writeFileAtomic((out / "results.csv").string(),
                  resultsCsv(results.at("rows"), results.at("random_encoder")));
  writeFileAtomic((out / "results_runs.csv").string(),
                  runsCsv(results.at("runs"), results.at("random_runs")));
  writeFileAtomic((out / "results.json").string(), results.dump(1) + "\n");
  writePlots(c, results.at("rows"), results.at("random_encoder"));
  writeFileAtomic((out / "summary.html").string(), summaryPage(c, results));
}

}  // namespace paircast
