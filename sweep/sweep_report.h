// The files a covis sweep ends with, in its --out folder: results.csv and results.json (the
// numbers), plot_<metric>.svg (each metric against the training sets' covis centre, a line per
// mode, the random encoder dashed) and summary.html (the page that shows them, and links each
// set's dataset report).
#pragma once

#include <nlohmann/json.hpp>

#include "sweep/covis_sweep.h"

namespace paircast {

// Writes the files from `results`, as runCovisSweep returns it: "rows" (one per set: mode,
// center, set, pairs, mean_covis, train_loss, xv_loss, probe_delta1, probe_absrel,
// probe_rmse), "random_encoder" (xv_loss and probe_*), "constant_depth" (probe_*) and
// "config"; results.json holds `results` itself.
void writeSweepReport(const SweepConfig& config, const nlohmann::json& results);

}  // namespace paircast
