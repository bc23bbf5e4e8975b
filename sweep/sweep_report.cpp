#include "sweep/sweep_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "sweep/sweep_downstream.h"
#include "sweep/sweep_stats.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/html.h"
#include "util/plot.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

// The metrics every run is evaluated on, each with its better direction, a name for the page,
// whether the verdicts judge it, and whether it needs a reference view (mae has none).
struct Metric {
  const char* key;
  bool higherIsBetter;
  const char* label;
  bool judged;
  bool needsReference;
};
const Metric kEvaluated[] = {
    {"xv_loss", false, "held-out completion loss (covis ~0.5)", true, false},
    {"probe_delta1", true, "depth probe delta1", true, false},
    {"probe_absrel", false, "depth probe AbsRel", true, false},
    {"probe_rmse", false, "depth probe RMSE (m)", true, false},
    {"ref_gain", true, "reference use, 1 - L_true / L_other", true, true},
    {"ref_gain_covisible", true, "reference use on covisible patches", true, true},
    {"ref_gain_hidden", true, "reference use on hidden patches (about 0 expected)", false, true},
    {"xattn_pck1", true, "cross-attention correspondence PCK@1 patch", true, true},
    {"xattn_epe", false, "cross-attention correspondence error (patches)", true, true},
    {"enc_pck1", true, "encoder-feature correspondence PCK@1 patch", true, false},
    // After fine-tuning (--downstream), on held-out pairs at covis 0.3-0.7 unless said.
    {"ft_flow_aepe", false, "fine-tuned flow AEPE (px)", true, false},
    {"ft_flow_aepe_covisible", false, "fine-tuned flow AEPE on covisible pixels (px)", true, false},
    {"ft_flow_px3", false, "fine-tuned flow 3 px outlier share", true, false},
    {"ft_flow_aepe_all", false, "fine-tuned flow AEPE, all of flow's held-out pairs (px)", false,
     false},
    {"ft_depth_delta1", true, "fine-tuned depth delta1", true, false},
    {"ft_depth_absrel", false, "fine-tuned depth AbsRel", true, false}};

// Whether a metric is measured after fine-tuning: its random baseline is then random weights
// fine-tuned like every run (from scratch on the fine-tuning data alone).
bool fineTuned(const Metric& m) {
  return std::string(m.key).rfind("ft_", 0) == 0;
}
const char* randomName(const Metric& m) {
  return fineTuned(m) ? "random weights (fine-tuned from scratch)" : "random encoder";
}

// The probes each claim is judged on, one verdict each.
const char* const kClaimProbes[] = {
    "xv_loss",      "ref_gain_covisible",     "xattn_pck1",  "enc_pck1",        "probe_delta1",
    "ft_flow_aepe", "ft_flow_aepe_covisible", "ft_flow_px3", "ft_depth_delta1", "ft_depth_absrel"};

const Metric& metric(const std::string& key) {
  for (const Metric& m : kEvaluated)
    if (key == m.key) return m;
  PAIRCAST_CHECK_MSG(false, "unknown sweep metric");
  return kEvaluated[0];
}

// Whether two runs' figures of `m` can be compared: the completion loss only between models of
// the same task (mae completes without the reference view), the probes that need a reference
// only between models that have one, the others always.
bool comparable(const Metric& m, const std::string& taskA, const std::string& taskB) {
  if (m.needsReference) return taskA != "mae" && taskB != "mae";
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

// Every run's value of `metric`, by set, in order of first appearance, with its seed index.
struct RunValues {
  std::vector<std::string> sets;
  std::map<std::string, std::vector<double>> values;
  std::map<std::string, std::vector<int>> seeds;
  std::map<std::string, std::string> task;
};

RunValues byset(const nlohmann::json& runs, const std::string& metric) {
  RunValues r;
  for (const auto& run : runs) {
    const std::string set = run.at("set");
    if (!r.values.count(set)) r.sets.push_back(set), r.task[set] = text(run, "task");
    r.values[set].push_back(numberOrNan(run, metric));
    r.seeds[set].push_back(run.value("seed_index", 0));
  }
  return r;
}

// One set's values, with their seeds.
struct SetValues {
  std::vector<double> values;
  std::vector<int> seeds;
};
SetValues of(const RunValues& v, const std::string& set) {
  return {v.values.at(set), v.seeds.at(set)};
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

// a minus b in the metric's better direction (> 0: a is better). Runs with the same seeds start
// from the same weights and draw the same masks, so they are compared seed by seed (a paired
// t-interval); others with Welch's interval.
bool paired(const SetValues& a, const SetValues& b) {
  return a.seeds == b.seeds && a.seeds.size() >= 2;
}

Interval gain(const SetValues& a, const SetValues& b, const Metric& m) {
  Interval d = paired(a, b) ? pairedDifferenceInterval95(a.values, b.values)
                            : differenceInterval95(a.values, b.values);
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

// The items with `sep` between each two.
std::string joined(const std::vector<std::string>& items, const std::string& sep) {
  std::string s;
  for (const auto& i : items) s += (s.empty() ? "" : sep) + i;
  return s;
}

// "bin_0.15 (-0.030 ± 0.012), mae (-0.041 ± 0.009)", or "none".
std::string listOf(const std::vector<std::string>& items) {
  return items.empty() ? "none" : joined(items, ", ");
}

// Against the best set and against the random encoder, for one metric. The completion loss of
// a baseline with another task (mae completes without a reference) is not compared, nor are
// the probes that need a reference.
std::vector<std::string> metricVerdicts(const Metric& m, const RunValues& v,
                                        const SetValues& random) {
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
      const Interval d = gain(of(v, s), of(v, best), m);
      (excludesZero(d) ? beyond : within).push_back(s + " (" + signedInterval(d) + ")");
    }
    const Interval r = gain(of(v, s), random, m);
    (excludesZero(r) && r.mean > 0 ? beats : notBeats)
        .push_back(s + " (" + signedInterval(r) + ")");
  }
  const Interval b = interval95(v.values.at(best)), rnd = interval95(random.values);
  if (!std::isfinite(b.halfWidth))
    return {std::string(m.label) + ": the best is " + best + ", " +
            withInterval(b.mean, b.halfWidth) +
            ". With one seed there are no intervals, so no difference is told from noise (use "
            "--seeds 3)."};
  return {std::string(m.label) + ": the best is " + best + ", " +
              withInterval(b.mean, b.halfWidth) + ". Behind it by more than the interval: " +
              listOf(beyond) + ". Within the interval of it: " + listOf(within) + ".",
          std::string(m.label) + ": better than " + randomName(m) + " (" +
              withInterval(rnd.mean, rnd.halfWidth) +
              ") by more than the interval: " + listOf(beats) + ". Not: " + listOf(notBeats) + "."};
}

// A claim that `a` beats each of `others` on one probe: "holds" when it wins every comparison
// beyond the interval, "does not hold" when it loses one beyond it, else "is not resolved at
// this scale". A probe that some of them cannot be compared on says why.
std::string claimVerdict(const std::string& claim, const std::string& a,
                         const std::vector<std::string>& others, const Metric& m,
                         const RunValues& v) {
  const std::string head = claim + ", on the " + m.label + ": ";
  for (const auto& o : others)
    if (!comparable(m, v.task.at(a), v.task.at(o)))
      return head + "not compared: " + o +
             (m.needsReference ? " has no reference view, so this probe has no figure for it."
                               : " is another task, whose loss is not comparable.");
  int wins = 0, losses = 0;
  bool intervals = true, allPaired = true;
  std::string detail;
  for (const auto& o : others) {
    const Interval d = gain(of(v, a), of(v, o), m);
    if (d.n == 0) return head + "no figures (the runs of " + a + " or " + o + " lack this probe).";
    intervals = intervals && std::isfinite(d.halfWidth);
    allPaired = allPaired && paired(of(v, a), of(v, o));
    if (excludesZero(d)) ++(d.mean > 0 ? wins : losses);
    detail += std::string(detail.empty() ? "" : "; ") + "vs " + o + " " + signedInterval(d);
  }
  const int total = static_cast<int>(others.size());
  const char* verdict =
      !intervals      ? "cannot be judged with fewer than 2 seeds with figures (use --seeds 3)"
      : wins == total ? "holds"
      : losses > 0    ? "does not hold"
                      : "is not resolved at this scale";
  return head + verdict + " (" + a + "'s gain, positive when it is better, with the " +
         (allPaired ? "paired 95 % interval over the seeds" : "95 % Welch interval") + ": " +
         detail + ").";
}

// The bin sets' names, by centre.
std::vector<std::string> binSets(const nlohmann::json& runs) {
  std::vector<std::pair<double, std::string>> bins;
  for (const auto& r : runs) {
    const nlohmann::json center = r.value("center", nlohmann::json());
    if (r.value("mode", "") == "bin" && center.is_number())
      bins.emplace_back(center.get<double>(), r.value("set", ""));
  }
  std::sort(bins.begin(), bins.end());
  bins.erase(std::unique(bins.begin(), bins.end()), bins.end());
  std::vector<std::string> names;
  for (const auto& b : bins) names.push_back(b.second);
  return names;
}

// Whether any run of `set` has a figure of the probe (the fine-tuned ones need --downstream).
bool hasFigures(const RunValues& v, const std::string& set) {
  const auto it = v.values.find(set);
  return it != v.values.end() && std::any_of(it->second.begin(), it->second.end(),
                                             [](double x) { return std::isfinite(x); });
}

// The paper's claims about the reference set (the bin set nearest 0.5, which mae trains on),
// where the sweep has the runs they need: a verdict on each probe of kClaimProbes that has
// figures. `values` holds the runs and each seed's random weights ("random_encoder").
std::vector<std::string> claimVerdicts(const nlohmann::json& runs, const std::string& reference,
                                       const std::map<std::string, RunValues>& values) {
  const RunValues& any = values.begin()->second;
  if (!any.values.count(reference)) return {};
  const std::vector<std::string> bins = binSets(runs);
  std::vector<std::pair<std::string, std::vector<std::string>>> claims;
  // Claim 1: against the lowest and the highest bin, those that are not the reference itself.
  if (std::find(bins.begin(), bins.end(), reference) != bins.end()) {
    std::vector<std::string> ends, sides;
    if (bins.front() != reference) ends.push_back(bins.front()), sides.push_back("low");
    if (bins.back() != reference) ends.push_back(bins.back()), sides.push_back("high");
    if (!ends.empty())
      claims.push_back({"Claim 1, covis near 0.5 beats " + sides.front() +
                            (sides.size() > 1 ? " and " + sides.back() : "") + " covis",
                        ends});
  }
  if (any.values.count("mae"))
    claims.push_back({"Claim 2, cross-view completion beats auto-completion (MAE)", {"mae"}});
  // After fine-tuning, also against random weights fine-tuned alike (the paper's first row).
  const bool random = any.values.count("random_encoder") > 0;
  std::vector<std::string> out;
  for (const auto& [claim, others] : claims)
    for (const char* probe : kClaimProbes)
      if (!fineTuned(metric(probe)) || hasFigures(values.at(probe), reference))
        out.push_back(claimVerdict(claim + (fineTuned(metric(probe)) && others[0] == "mae"
                                                ? ", its encoder with a random decoder"
                                                : ""),
                                   reference, others, metric(probe), values.at(probe)));
  for (const char* probe : kClaimProbes)
    if (random && fineTuned(metric(probe)) && hasFigures(values.at(probe), reference))
      out.push_back(claimVerdict("Claim 2, cross-view pre-training beats random weights", reference,
                                 {"random_encoder"}, metric(probe), values.at(probe)));
  return out;
}

// The widest 95 % half-width of the difference between two of `sets` (paired by seed where
// their seeds match, else Welch's), with the pair's names and its count of values.
struct Widest {
  Interval d{NAN, NAN, 0};
  std::string pair;
};
Widest widestDifference(const RunValues& v, const std::vector<std::string>& sets) {
  Widest w;
  for (size_t i = 0; i < sets.size(); ++i)
    for (size_t j = i + 1; j < sets.size(); ++j) {
      const SetValues a = of(v, sets[i]), b = of(v, sets[j]);
      const Interval d = paired(a, b) ? pairedDifferenceInterval95(a.values, b.values)
                                      : differenceInterval95(a.values, b.values);
      if (std::isfinite(d.halfWidth) && !(d.halfWidth <= w.d.halfWidth))
        w = {d, sets[i] + " and " + sets[j]};
    }
  return w;
}

// The fewest seeds at which a half-width of `halfWidth` over `seeds` shrinks to `target`: the
// spread of the differences is halfWidth sqrt(seeds) / t(seeds - 1), and the half-width at n
// seeds t(n - 1) spread / sqrt(n). 0 when not within 100,000.
long seedsToDecide(double halfWidth, int seeds, double target) {
  const double spread = halfWidth * std::sqrt(seeds) / tQuantile95(seeds - 1);
  for (long n = 2; n <= 100000; ++n)
    if (tQuantile95(n - 1) * spread / std::sqrt(n) <= target) return n;
  return 0;
}

// Whether a fine-tuned flow error can decide between two sets: the widest paired 95 % half-width
// of the difference between two training sets, against a quarter of the gap between random
// weights and the best pre-trained run. Empty without fine-tuned figures.
std::string instrumentVerdict(const Metric& m, const RunValues& runs, const RunValues& withRandom) {
  if (!hasFigures(withRandom, "random_encoder")) return "";
  std::vector<std::string> sets;
  double best = INFINITY;  // lower is better for the flow errors
  std::string bestSet;
  for (const auto& s : runs.sets) {
    if (runs.task.at(s) == "croco" && hasFigures(runs, s)) sets.push_back(s);
    const double mean = interval95(runs.values.at(s)).mean;
    if (std::isfinite(mean) && mean < best) best = mean, bestSet = s;
  }
  const Widest w = widestDifference(runs, sets);
  const std::string head = std::string("Instrument, ") + m.label + ": ";
  if (!std::isfinite(w.d.halfWidth) || bestSet.empty())
    return head +
           "with fewer than two sets of 2 seeds or more, the intervals are not known (use "
           "--seeds 3).";
  const double random = interval95(withRandom.values.at("random_encoder")).mean;
  const double gap = random - best, quarter = gap / 4;
  char b[512];
  if (!(gap > 0)) {
    std::snprintf(b, sizeof b,
                  "does not decide. No pre-trained run beats random weights (%.3f; the best "
                  "run, %s, %.3f), so there is no gap to resolve; the widest 95 %% half-width "
                  "between two sets (%s) is %.3f.",
                  random, bestSet.c_str(), best, w.pair.c_str(), w.d.halfWidth);
    return head + b;
  }
  const bool decides = w.d.halfWidth <= quarter;
  std::snprintf(b, sizeof b,
                "%s. The widest 95 %% half-width of the difference between two sets (%s) is "
                "%.3f, %.1fx a quarter of the gap between random weights (%.3f) and the best "
                "pre-trained run (%s, %.3f): %.3f / 4 = %.3f.",
                decides ? "decides" : "does not decide", w.pair.c_str(), w.d.halfWidth,
                w.d.halfWidth / quarter, random, bestSet.c_str(), best, gap, quarter);
  if (decides) return head + b;
  const long n = seedsToDecide(w.d.halfWidth, w.d.n, quarter);
  return head + b + " At this budget about " +
         (n ? std::to_string(n) : std::string("more than 100000")) +
         " seeds would decide (the spread of the differences staying as it is), or a budget "
         "that widens the gap.";
}

// ---- the plots and the page ----

// One line per mode over the covis centres, with error bars.
std::vector<plot::Series> modeSeries(const nlohmann::json& rows, const Metric& m) {
  const char* colors[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd"};
  const std::string mean = std::string(m.key) + "_mean", ci = std::string(m.key) + "_ci95";
  std::vector<std::string> modes;  // of the cross-view sets, in order of appearance
  for (const auto& r : rows)
    if (r["center"].is_number() && std::find(modes.begin(), modes.end(), r["mode"]) == modes.end())
      modes.push_back(r["mode"]);
  std::vector<plot::Series> series;
  for (const auto& mode : modes) {
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
plot::Series baselineSeries(const nlohmann::json& rows, std::string label, const char* color,
                            const nlohmann::json& row, const Metric& m) {
  const double mean = numberOrNan(row, std::string(m.key) + "_mean");
  if (const double e = numberOrNan(row, std::string(m.key) + "_ci95"); std::isfinite(e))
    label += " \u00b1" + html::number(e, "%.3f");
  plot::Series base;
  base.label = label;
  base.color = color;
  base.dashed = true;
  base.markers = false;
  base.x = {INFINITY, -INFINITY};  // the sets' centres
  for (const auto& r : rows)
    if (r["center"].is_number())
      base.x = {std::min(base.x[0], r["center"].get<double>()),
                std::max(base.x[1], r["center"].get<double>())};
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

// Whether a metric has a plot: some set has a figure of it (fine-tuned ones need --downstream).
bool plotted(const nlohmann::json& rows, const Metric& m) {
  for (const auto& r : rows)
    if (std::isfinite(numberOrNan(r, std::string(m.key) + "_mean"))) return true;
  return false;
}

// plot_<metric>.svg: the modes, mae (not in the completion loss's: its task is another) and the
// random encoder, which goes in the title instead when it is off the scale.
void writePlots(const SweepConfig& c, const nlohmann::json& rows, const nlohmann::json& random) {
  for (const Metric& m : kEvaluated) {
    if (!m.judged || !plotted(rows, m)) continue;
    std::vector<plot::Series> series = modeSeries(rows, m);
    for (const auto& r : rows)
      if (r["task"] != "croco" && comparable(m, r["task"], "croco"))
        series.push_back(baselineSeries(rows, text(r, "set"), "#d62728", r, m));
    std::string title = m.label;
    const double randomMean = numberOrNan(random, std::string(m.key) + "_mean");
    if (offTheScale(series, randomMean))
      title += "; random encoder " + html::number(randomMean, "%.3f");
    else
      series.push_back(baselineSeries(rows, "random", "#7f7f7f", random, m));
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

// The table's probe columns, after the set's seeds, mean covis and train loss; then, with
// --downstream, the fine-tuned ones.
const char* const kTableMetrics[] = {"xv_loss",         "probe_delta1", "probe_absrel",
                                     "probe_rmse",      "ref_gain",     "ref_gain_covisible",
                                     "ref_gain_hidden", "xattn_pck1",   "xattn_epe",
                                     "enc_pck1"};
const char* const kTableFineTuned[] = {"ft_flow_aepe",    "ft_flow_aepe_covisible",
                                       "ft_flow_px3",     "ft_flow_aepe_all",
                                       "ft_depth_delta1", "ft_depth_absrel"};

// summary.html: what was trained, the verdicts, the plots, and the table of sets and baselines.
std::string summaryPage(const SweepConfig& c, const nlohmann::json& results) {
  const nlohmann::json& rows = results.at("rows");
  const nlohmann::json& random = results.at("random_encoder");
  const nlohmann::json& constant = results.at("constant_depth");
  const nlohmann::json trivial = results.value("finetune_baselines", nlohmann::json());
  const bool downstream = trivial.is_object() && !trivial.empty();
  std::vector<std::string> metrics(std::begin(kTableMetrics), std::end(kTableMetrics));
  if (downstream)
    metrics.insert(metrics.end(), std::begin(kTableFineTuned), std::end(kTableFineTuned));
  std::string page =
      html::pageStart("covis_sweep results", html::style(1500)) +
      html::heading(1, "Co-visibility sweep") +
      html::paragraph(std::to_string(rows.size()) + " training sets and baselines of " +
                      std::to_string(c.pairsPerSet) + " pairs, each trained with " +
                      std::to_string(c.seeds) + " seed(s) (" + plot::escape(c.preset) + " model, " +
                      std::to_string(c.steps) + " steps of " + std::to_string(c.batchSize) +
                      " at " + std::to_string(c.imgSize) +
                      " px), evaluated on held-out scenes. Figures are means over "
                      "the seeds \u00b1 the half-width of a 95 % t-interval; differences between "
                      "runs of the same seeds are paired. mae has no reference view, so its "
                      "reference-use and cross-attention cells are empty. Data: " +
                      html::link("results.csv", "results.csv") + " (per set), " +
                      html::link("results_runs.csv", "results_runs.csv") + " (per run), " +
                      html::link("probe_by_covis.csv", "probe_by_covis.csv") +
                      " (correspondence by the held-out pair's covis), " +
                      (trivial.contains("ft_flow_by_covis")
                           ? html::link("downstream_by_covis.csv", "downstream_by_covis.csv") +
                                 " (fine-tuned flow error by the held-out pair's covis), "
                           : std::string()) +
                      html::link("results.json", "results.json") + ".") +
      (downstream ? downstreamParagraph(c) : std::string()) + html::heading(2, "Verdicts");
  for (const auto& v : results.at("verdicts")) page += html::paragraph(plot::escape(v));
  for (const Metric& m : kEvaluated)
    if (m.judged && plotted(rows, m))
      page += html::image("plot_" + std::string(m.key) + ".svg", m.key) + "\n";
  page += html::image("plot_probe_by_covis.svg", "probe_by_covis") + "\n";
  if (downstream && trivial.contains("ft_flow_by_covis"))
    page += html::image("plot_downstream_by_covis.svg", "downstream_by_covis") + "\n";
  std::vector<std::string> head = {"set", "seeds", "mean covis", "train loss"};
  head.insert(head.end(), metrics.begin(), metrics.end());
  head.push_back("dataset");
  page += html::tableStart(head);
  auto cells = [&](const nlohmann::json& r, const std::string& seeds, const std::string& covis,
                   const std::string& trainLoss, const std::string& report) {
    std::vector<std::string> out = {seeds, covis, trainLoss};
    for (const auto& m : metrics) out.push_back(cell(r, m));
    out.push_back(report);
    return out;
  };
  for (const auto& r : rows) {
    const std::string set = r["set"].get<std::string>();
    page += html::labelledRow(
        set + (r["task"] == "mae" ? " (xv loss: its own task)" : ""),
        cells(r, std::to_string(r.value("seeds", 0)), num(r, "mean_covis"), cell(r, "train_loss"),
              c.reports ? html::link("sets/" + text(r, "trained_on") + "/report.html", "report")
                        : "-"));
  }
  page +=
      html::labelledRow(downstream ? "random encoder (fine-tuned: from scratch)" : "random encoder",
                        cells(random, std::to_string(random.value("seeds", 0)), "", "", ""));
  std::vector<std::string> floor = {"", "", ""};
  for (const auto& m : metrics)
    floor.push_back(m.rfind("probe_", 0) == 0 ? num(constant, m)
                    : m.rfind("ft_", 0) == 0  ? num(trivial, m)
                                              : "");
  floor.push_back("");
  page += html::labelledRow(
      downstream ? "constant depth (no encoder); zero flow" : "constant depth (no encoder)", floor);
  return page + html::tableEnd() + html::pageEnd();
}

// ---- probe_by_covis.csv and its plot ----

const std::vector<std::string> kByCovisMetrics = {"xattn_pck1", "xattn_epe", "enc_pck1"};
const std::vector<std::string> kDownstreamByCovis = {"ft_flow_aepe", "ft_flow_aepe_covisible"};

// A row per set (and the random encoder) and covis bin of the held-out pairs: the mean over the
// seeds of each figure of the runs' `field` (a list of bins), with its 95 % interval.
nlohmann::json byCovis(const nlohmann::json& runs, const nlohmann::json& randomRuns,
                       const std::string& field, const std::vector<std::string>& metrics) {
  std::vector<std::string> order;
  std::map<std::pair<std::string, double>, std::vector<nlohmann::json>> cells;
  std::map<std::string, std::string> task;
  for (const auto* list : {&runs, &randomRuns})
    for (const auto& r : *list) {
      const std::string set = r.at("set");
      if (!task.count(set)) order.push_back(set), task[set] = text(r, "task");
      for (const auto& bin : r.value(field, nlohmann::json::array()))
        cells[{set, bin.at("covis_lo").get<double>()}].push_back(bin);
    }
  nlohmann::json out = nlohmann::json::array();
  for (const auto& set : order)
    for (const auto& [key, bins] : cells) {
      if (key.first != set) continue;
      nlohmann::json row = {{"set", set},
                            {"task", task[set]},
                            {"covis_lo", key.second},
                            {"covis_hi", bins.front().at("covis_hi")},
                            {"pairs", bins.front().at("pairs")},
                            {"seeds", bins.size()}};
      for (const auto& m : metrics) {
        std::vector<double> v;
        for (const auto& b : bins) v.push_back(numberOrNan(b, m));
        const Interval i = interval95(v);
        row[m + "_mean"] = i.mean;
        row[m + "_ci95"] = i.halfWidth;
      }
      out.push_back(row);
    }
  return out;
}

std::string byCovisCsv(const nlohmann::json& rows, const std::vector<std::string>& metrics) {
  std::string csv = "set,task,covis_lo,covis_hi,pairs,seeds";
  for (const auto& m : metrics) csv += "," + m + "_mean," + m + "_ci95";
  csv += "\n";
  for (const auto& r : rows) {
    csv += text(r, "set") + "," + text(r, "task") + "," + num(r, "covis_lo") + "," +
           num(r, "covis_hi") + "," + std::to_string(r.value("pairs", 0)) + "," +
           std::to_string(r.value("seeds", 0));
    for (const auto& m : metrics) csv += "," + num(r, m + "_mean") + "," + num(r, m + "_ci95");
    csv += "\n";
  }
  return csv;
}

// The sets of by-covis rows, in order of first appearance.
std::vector<std::string> setsOf(const nlohmann::json& rows) {
  std::vector<std::string> sets;
  for (const auto& r : rows)
    if (std::find(sets.begin(), sets.end(), text(r, "set")) == sets.end())
      sets.push_back(text(r, "set"));
  return sets;
}

// One set's line of a by-covis metric: its mean at each bin's centre, with its interval.
plot::Series byCovisSeries(const nlohmann::json& rows, const std::string& set,
                           const std::string& metric) {
  plot::Series s;
  for (const auto& r : rows) {
    const double y = numberOrNan(r, metric + "_mean");
    if (text(r, "set") != set || !std::isfinite(y)) continue;
    s.x.push_back(numberOrNan(r, "covis_lo") + 0.05);
    s.y.push_back(y);
    s.yErr.push_back(numberOrNan(r, metric + "_ci95"));
  }
  return s;
}

const char* const kSetColors[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#d62728", "#7f7f7f"};

// Cross-attention PCK ("xattn", solid) and encoder PCK ("enc", dashed) against the held-out pair's
// covis, a colour per set.
std::string probeByCovisPlot(const nlohmann::json& rows) {
  const std::vector<std::string> sets = setsOf(rows);
  std::vector<plot::Series> series;
  for (size_t k = 0; k < sets.size(); ++k)
    for (const std::string m : {"xattn_pck1", "enc_pck1"}) {
      plot::Series s = byCovisSeries(rows, sets[k], m);
      s.label = sets[k] + (m == "enc_pck1" ? " enc" : " xattn");
      s.color = kSetColors[k % 6];
      s.dashed = m == "enc_pck1";
      if (!s.x.empty()) series.push_back(s);
    }
  return plot::lines(series, {"correspondence PCK@1 patch by the held-out pair's covis",
                              "covis of the held-out pair (bins of 0.1)", "PCK@1", 720, 400});
}

// Fine-tuned flow AEPE against the held-out pair's covis: a line per set, random weights and
// zero flow (dashed).
std::string downstreamByCovisPlot(const nlohmann::json& rows) {
  const std::vector<std::string> sets = setsOf(rows);
  std::vector<plot::Series> series;
  for (size_t k = 0; k < sets.size(); ++k) {
    plot::Series s = byCovisSeries(rows, sets[k], "ft_flow_aepe");
    s.label = sets[k];
    s.color = kSetColors[k % 6];
    s.dashed = sets[k] == "zero_flow" || sets[k] == "random_encoder";
    if (!s.x.empty()) series.push_back(s);
  }
  return plot::lines(series, {"fine-tuned flow AEPE by the held-out pair's covis, lower is better",
                              "covis of the held-out pair (bins of 0.1)", "AEPE (px)", 720, 400});
}

}  // namespace

std::string downstreamParagraph(const SweepConfig& c) {
  const auto g = [](double x) {  // 0.5, not 0.500000
    char b[32];
    std::snprintf(b, sizeof b, "%g", x);
    return std::string(b);
  };
  const std::string band = "covis " + g(kDownstreamBandLo) + "-" + g(kDownstreamBandHi);
  const std::string wide = "wide pairs, covis >= " + g(kWideTrainMinCovis);
  std::vector<std::string> kinds, bands;  // each task's training pairs and held-out band
  if (c.flowOnFlowStylePairs()) {
    kinds.push_back("flow: flow-style pairs, generate_pairs --motion near, covis >= " +
                    g(kFlowStyleMinCovis));
    bands.push_back("flow on every flow-style pair");
  } else if (c.finetunes("flow")) {
    kinds.push_back("flow: " + wide);
    bands.push_back("flow at " + band + " (ft_flow_aepe_all: " + g(kWideHeldoutMinCovis) + "-1)");
  }
  if (c.finetunes("depth")) {
    kinds.push_back("depth: " + wide);
    bands.push_back("depth at " + band);
  }
  return html::paragraph(
      "Fine-tuned (columns ft_*): every run, and each seed's random weights (fine-tuned from "
      "scratch on the fine-tuning data alone), for " +
      joined(c.downstream, " and ") + " with the linear heads, " + std::to_string(c.finetuneSteps) +
      " steps of " + std::to_string(c.finetuneBatch) + " on " + std::to_string(c.finetunePairs) +
      " pairs of the training scenes (" + joined(kinds, "; ") +
      "), the same data order, crops and jitter for every run of a seed; mae keeps its encoder "
      "and the seed's random decoder. Measured on held-out pairs of the same kinds: " +
      joined(bands, ", ") + "; the floor row is zero flow and a constant depth.");
}

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
  nlohmann::json withRandom = runs;
  for (const auto& r : results.at("random_runs")) withRandom.push_back(r);
  std::map<std::string, RunValues> values, claimValues;
  std::vector<std::string> out;
  for (const Metric& m : kEvaluated) {
    values[m.key] = byset(runs, m.key);
    claimValues[m.key] = byset(withRandom, m.key);
    const RunValues randomValues = byset(results.at("random_runs"), m.key);
    if (!m.judged || !randomValues.values.count("random_encoder")) continue;
    for (auto& line : metricVerdicts(m, values[m.key], of(randomValues, "random_encoder")))
      out.push_back(std::move(line));
  }
  // The claims come first.
  std::vector<std::string> claims =
      claimVerdicts(runs, results.value("reference_set", std::string()), claimValues);
  out.insert(out.begin(), claims.begin(), claims.end());
  for (const char* key : {"ft_flow_aepe", "ft_flow_aepe_covisible"})
    if (const std::string line =
            instrumentVerdict(metric(key), values.at(key), claimValues.at(key));
        !line.empty())
      out.push_back(line);
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
  const nlohmann::json probes =
      byCovis(results.at("runs"), results.at("random_runs"), "probe_by_covis", kByCovisMetrics);
  writeFileAtomic((out / "probe_by_covis.csv").string(), byCovisCsv(probes, kByCovisMetrics));
  writeFileAtomic((out / "plot_probe_by_covis.svg").string(), probeByCovisPlot(probes));
  const nlohmann::json trivial = results.value("finetune_baselines", nlohmann::json());
  if (trivial.is_object() && trivial.contains("ft_flow_by_covis")) {
    nlohmann::json zero = trivial;
    zero["set"] = "zero_flow";
    zero["task"] = "none";
    const nlohmann::json flow = byCovis(results.at("runs"), results.at("random_runs"),
                                        "ft_flow_by_covis", kDownstreamByCovis);
    nlohmann::json rows = flow;
    for (const auto& r : byCovis(nlohmann::json::array({zero}), nlohmann::json::array(),
                                 "ft_flow_by_covis", kDownstreamByCovis))
      rows.push_back(r);
    writeFileAtomic((out / "downstream_by_covis.csv").string(),
                    byCovisCsv(rows, kDownstreamByCovis));
    writeFileAtomic((out / "plot_downstream_by_covis.svg").string(), downstreamByCovisPlot(rows));
  }
  writeFileAtomic((out / "summary.html").string(), summaryPage(c, results));
}

}  // namespace paircast
