// The files a covis sweep ends with, in its --out folder: results.csv (a row per set and
// baseline: each metric's mean over the seeds and the half-width of its 95 % t-interval),
// results_runs.csv (a row per run), results.json (all of it, and the verdicts),
// plot_<metric>.svg (each metric against the training sets' covis centre, a line per mode with
// error bars, the baselines dashed) and summary.html (the page that shows them, says in words
// which differences are larger than their intervals, and links each set's dataset report).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "sweep/covis_sweep.h"

namespace paircast {

// The metrics every run is evaluated on, in the files' column order: train_loss, xv_loss,
// probe_delta1, probe_absrel, probe_rmse.
const std::vector<std::string>& sweepMetrics();

// obj[key] when it is a number, else NaN (results.json writes a NaN as null).
double numberOrNan(const nlohmann::json& obj, const std::string& key);

// Runs' rows (each with set, mode, center, task, trained_on, pairs, mean_covis and the metrics)
// grouped by set, in the order each set first appears: a row per set with those fields, "seeds"
// (its runs), and for every metric <metric>_mean and <metric>_ci95 (NaN with one seed).
nlohmann::json aggregateRuns(const nlohmann::json& runs);

// What summary.html says, a sentence each: the paper's two claims about "reference_set" (see
// referenceSet: against the lowest and the highest bin; against mae), where the sweep has those
// runs; then, for every evaluation metric, which sets and baselines are behind the best one and
// ahead of the random encoder by more than the 95 % interval of the difference (Welch's), and
// which are not. `results` as collectResults makes it: "runs", "random_runs", "reference_set".
std::vector<std::string> sweepVerdicts(const nlohmann::json& results);

// Writes the files from `results`, as runCovisSweep returns it: "rows" (aggregateRuns of
// "runs"), "runs", "random_encoder" (aggregated), "random_runs", "constant_depth" (probe_*),
// "verdicts" and "config"; results.json holds `results` itself.
void writeSweepReport(const SweepConfig& config, const nlohmann::json& results);
// The page's paragraph on the fine-tunes (--downstream): the tasks, the budget, the pairs each
// task trains on and the held-out pairs its columns average over.
std::string downstreamParagraph(const SweepConfig& config);

}  // namespace paircast
