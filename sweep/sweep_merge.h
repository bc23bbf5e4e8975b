// A study in parts: each part a covis_sweep with its own seeds (--first-seed and --seeds), run
// on any machine, at any time; the merge writes the report of all their runs as one sweep over
// all those seeds writes it (results.csv, results_runs.csv, results.json, the plots and
// summary.html), from the parts' results.json files alone. A part's results.json is small
// (tens of kilobytes), so the parts of a long study can be kept and merged long after their
// checkpoints are gone.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace paircast {

// Reads each part (a finished sweep's folder, or its results.json), checks that they are parts
// of one study, and writes the merged report into `out`. Returns the merged results.json.
//
// Parts of one study have the same settings (results.json's config, but for the seeds, the
// scene folders, which may lie elsewhere on another machine, and the precision the machine
// chose), the same scene files by name, the same pool and the same held-out data (their
// baselines equal to 1e-4). Each seed comes from one part. The merged config lists the parts,
// each with its seeds and precision.
//
// Throws Error naming the part for a part that is missing, not JSON, or not a sweep's results,
// for one made with other settings or data, and for a seed two parts both ran.
nlohmann::json mergeSweepParts(const std::vector<std::string>& parts, const std::string& out);

}  // namespace paircast
