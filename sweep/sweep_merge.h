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
// chose), the same scene files by name and the same pool size, and by default the same draw:
// the sets' mean covis and the held-out data's baselines equal to 1e-4. Each seed comes from one
// part. The merged config lists the parts, each with its seeds and precision.
//
// The same seed draws some other pairs on a CPU of another kind (AVX-512 against AVX2). With
// otherDraws, parts whose settings agree are merged whatever their draws: each seed's runs are
// still compared on that seed's own data. When the parts' draws differ, the merged baselines
// (zero flow, also by held-out covis, and the constant depth) are the seed-weighted means of the
// parts', each set's mean covis the mean over its runs, and the config says "other_draws" and
// keeps each part's draw.
//
// Throws Error naming the part for a part that is missing, not JSON, or not a sweep's results,
// for one made with other settings (or, without otherDraws, another draw), and for a seed two
// parts both ran.
nlohmann::json mergeSweepParts(const std::vector<std::string>& parts, const std::string& out,
                               bool otherDraws = false);

}  // namespace paircast
