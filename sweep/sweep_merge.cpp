#include "sweep/sweep_merge.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "sweep/covis_sweep.h"
#include "sweep/sweep_report.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

struct Part {
  std::string file;  // its results.json
  nlohmann::json results;
  std::set<int> seeds;
};

// The config keys that may differ between the parts of one study: the seeds, the scene paths
// (compared by file name) and the precision each machine chose.
const std::set<std::string> kPartKeys = {"seeds", "first_seed", "scenes", "heldout", "precision"};

// The config keys that count what a draw found (held-out pairs, mechanism pairs): another CPU's
// draw may come up a pair short, so they belong to the draw, not to the settings.
const std::set<std::string> kDrawCounts = {"eval_pairs", "mechanism_pairs"};

const char* const kOtherDrawsHint =
    " (drawn on a CPU that draws other pairs? --other-draws merges parts whose settings agree)";

void requireArrayOfRuns(const std::string& file, const nlohmann::json& j, const char* key) {
  const auto it = j.find(key);
  if (it == j.end() || !it->is_array() || it->empty())
    throw Error(file, std::string("has no runs in '") + key +
                          "': not the results.json of a finished covis_sweep");
  for (const auto& run : *it)
    if (!run.is_object() || !run.contains("set") || !run["set"].is_string() ||
        !run.contains("seed_index") || !run["seed_index"].is_number_integer())
      throw Error(file, std::string("a run of '") + key + "' has no set or seed_index");
}

Part readPart(const std::string& path) {
  std::error_code ec;
  const fs::path file =
      fs::is_directory(path, ec) ? fs::path(path) / "results.json" : fs::path(path);
  if (!fs::is_regular_file(file, ec))
    throw Error(file.string(),
                "no such file: give a finished covis_sweep's folder or its results.json");
  Part p{file.string(), nlohmann::json::parse(readFile(file.string()), nullptr, false), {}};
  if (p.results.is_discarded() || !p.results.is_object())
    throw Error(p.file, "is not a JSON object (truncated?)");
  if (!p.results.contains("config") || !p.results["config"].is_object())
    throw Error(p.file, "has no config: not the results.json of a finished covis_sweep");
  requireArrayOfRuns(p.file, p.results, "runs");
  requireArrayOfRuns(p.file, p.results, "random_runs");
  for (const auto& run : p.results["random_runs"]) p.seeds.insert(run["seed_index"].get<int>());
  return p;
}

// The merged report goes elsewhere: written into a part's folder, it would replace that part's
// results.json, its only record once the checkpoints are gone.
void refuseToOverwrite(const Part& part, const std::string& out) {
  std::error_code ec;
  if (fs::equivalent(fs::path(part.file).parent_path(), out, ec))
    throw OptionError("out", out + " holds the part " + part.file +
                                 ", which the merge would overwrite: give another folder");
}

// Equal, numbers to a relative 1e-4 (one held-out set rendered on two CPUs).
bool nearlyEqual(const nlohmann::json& a, const nlohmann::json& b) {
  if (a.is_number() && b.is_number()) {
    const double x = a.get<double>(), y = b.get<double>();
    return std::abs(x - y) <= 1e-4 * std::max({1.0, std::abs(x), std::abs(y)});
  }
  if (a.type() != b.type() || a.size() != b.size()) return false;
  if (a.is_array()) {
    for (size_t i = 0; i < a.size(); ++i)
      if (!nearlyEqual(a[i], b[i])) return false;
    return true;
  }
  if (a.is_object()) {
    for (auto it = a.begin(); it != a.end(); ++it)
      if (!b.contains(it.key()) || !nearlyEqual(it.value(), b[it.key()])) return false;
    return true;
  }
  return a == b;
}

nlohmann::json fileNames(const nlohmann::json& paths) {
  nlohmann::json names = nlohmann::json::array();
  if (paths.is_array())
    for (const auto& p : paths)
      names.push_back(p.is_string() ? fs::path(p.get<std::string>()).filename().string() : "");
  return names;
}

// What must agree between two parts of one study, by name, in the order it is checked. The
// settings must agree; the draw (the pairs a machine drew, which differ between CPUs of other
// kinds) must agree unless the merge accepts other draws.
struct Identity {
  std::string name;
  nlohmann::json value;
  bool draw = false;
};

nlohmann::json setsMeanCovis(const nlohmann::json& results) {
  nlohmann::json sets = nlohmann::json::object();
  for (const auto& row : results.value("rows", nlohmann::json::array()))
    if (row.is_object() && row.contains("set"))
      sets[row["set"].get<std::string>()] = row.value("mean_covis", nlohmann::json());
  return sets;
}

std::vector<Identity> studyIdentity(const nlohmann::json& results) {
  const nlohmann::json& config = results["config"];
  std::vector<Identity> id;
  nlohmann::json counts = nlohmann::json::object();
  for (auto it = config.begin(); it != config.end(); ++it)
    if (kDrawCounts.count(it.key()))
      counts[it.key()] = it.value();
    else if (!kPartKeys.count(it.key()))
      id.push_back({"setting '" + it.key() + "'", it.value()});
  id.push_back({"scene files", fileNames(config.value("scenes", nlohmann::json()))});
  id.push_back({"held-out scene files", fileNames(config.value("heldout", nlohmann::json()))});
  id.push_back({"pool", results.value("pool_pairs", nlohmann::json())});
  id.push_back({"held-out pair counts", counts, true});
  id.push_back({"sets' mean covis", setsMeanCovis(results), true});
  id.push_back({"held-out data (zero flow's and constant depth's figures)",
                nlohmann::json::array({results.value("finetune_baselines", nlohmann::json()),
                                       results.value("constant_depth", nlohmann::json())}),
                true});
  return id;
}

// Whether `part` drew other pairs than `first`. Throws for other settings, and for another draw
// unless otherDraws.
bool checkSameStudy(const Part& first, const Part& part, bool otherDraws) {
  const auto want = studyIdentity(first.results), got = studyIdentity(part.results);
  std::map<std::string, nlohmann::json> have;
  for (const Identity& i : got) have[i.name] = i.value;
  bool drawDiffers = false;
  for (const Identity& i : want) {
    const auto it = have.find(i.name);
    const bool present = it != have.end();
    const nlohmann::json other = present ? it->second : nlohmann::json();
    have.erase(i.name);
    if (nearlyEqual(i.value, other)) continue;
    if (i.draw && otherDraws && present) {
      drawDiffers = true;
      continue;
    }
    throw Error(part.file, "is not a part of the study of " + first.file + ": its " + i.name +
                               " is " + other.dump() + ", not " + i.value.dump() +
                               (i.draw ? std::string(kOtherDrawsHint) : ""));
  }
  if (!have.empty())
    throw Error(part.file, "is not a part of the study of " + first.file + ": it has the " +
                               have.begin()->first + ", which " + first.file + " lacks");
  return drawDiffers;
}

void checkSeedsOnce(const std::vector<Part>& parts) {
  std::map<int, std::string> from;
  for (const Part& p : parts)
    for (const int k : p.seeds)
      if (const auto [it, fresh] = from.emplace(k, p.file); !fresh)
        throw Error(p.file, "seed " + std::to_string(k) + " is in " + it->second +
                                " too: merge each seed from one part");
}

// The seed-weighted mean of the parts' figures: numbers averaged, objects key by key, anything
// else (names, nulls, arrays, figures equal in every part) as the first part has it. The one array
// among the baselines, zero flow by covis, is merged bin by bin (mergeByCovis).
nlohmann::json weightedMean(const std::vector<std::pair<nlohmann::json, double>>& items) {
  const nlohmann::json& first = items.front().first;
  if (first.is_number()) {
    double sum = 0, weight = 0;
    for (const auto& [value, w] : items) {
      if (!value.is_number()) return first;
      sum += w * value.get<double>(), weight += w;
    }
    const bool same = std::all_of(items.begin(), items.end(),
                                  [&](const auto& item) { return item.first == first; });
    return same ? first : nlohmann::json(sum / weight);
  }
  if (!first.is_object()) return first;
  nlohmann::json out = first;
  for (auto it = out.begin(); it != out.end(); ++it) {
    std::vector<std::pair<nlohmann::json, double>> children;
    for (const auto& [value, w] : items)
      if (value.is_object() && value.contains(it.key())) children.emplace_back(value[it.key()], w);
    *it = weightedMean(children);
  }
  return out;
}

// Zero flow by held-out covis over parts whose bins differ (a draw leaves out the bins it has no
// pair in): bins matched by their bounds, each figure the mean over all the parts' pairs in the
// bin, seed-weighted, and its pairs the seed-weighted mean count (0 where a part has none).
nlohmann::json mergeByCovis(const std::vector<Part>& parts) {
  struct Sums {
    nlohmann::json bin;
    double pairs = 0;
    std::map<std::string, std::pair<double, double>> figures;  // sum and weight (pairs x seeds)
  };
  std::map<std::pair<double, double>, Sums> bins;
  double seeds = 0;
  for (const Part& p : parts) {
    const double w = double(p.seeds.size());
    seeds += w;
    const nlohmann::json baselines = p.results.value("finetune_baselines", nlohmann::json());
    if (!baselines.is_object() || !baselines.contains("ft_flow_by_covis")) continue;
    for (const auto& bin : baselines["ft_flow_by_covis"]) {
      Sums& sums = bins[{bin.value("covis_lo", 0.0), bin.value("covis_hi", 0.0)}];
      if (sums.bin.is_null()) sums.bin = bin;
      const double n = bin.value("pairs", 0.0);
      sums.pairs += w * n;
      for (auto it = bin.begin(); it != bin.end(); ++it)
        if (it.value().is_number() && it.key().rfind("ft_", 0) == 0) {
          auto& [sum, weight] = sums.figures[it.key()];
          sum += w * n * it.value().get<double>(), weight += w * n;
        }
    }
  }
  nlohmann::json out = nlohmann::json::array();
  for (auto& [bounds, sums] : bins) {
    nlohmann::json bin = sums.bin;
    for (const auto& [key, sum] : sums.figures) bin[key] = sum.first / sum.second;
    bin["pairs"] = std::lround(sums.pairs / seeds);
    out.push_back(bin);
  }
  return out;
}

// Parts that drew their pairs apart: the held-out baselines are the seed-weighted means of the
// parts', each set's mean covis the mean of its runs', and the config lists each part's draw.
void mergeDraws(const std::vector<Part>& parts, nlohmann::json& merged) {
  for (const char* key : {"finetune_baselines", "constant_depth"}) {
    std::vector<std::pair<nlohmann::json, double>> items;
    for (const Part& p : parts)
      items.emplace_back(p.results.value(key, nlohmann::json()), double(p.seeds.size()));
    merged[key] = weightedMean(items);
  }
  if (merged["finetune_baselines"].is_object() &&
      merged["finetune_baselines"].contains("ft_flow_by_covis"))
    merged["finetune_baselines"]["ft_flow_by_covis"] = mergeByCovis(parts);
  for (auto& row : merged["rows"]) {
    double sum = 0;
    int n = 0;
    for (const auto& run : merged["runs"])
      if (run.value("set", "") == row.value("set", "") && run.contains("mean_covis") &&
          run["mean_covis"].is_number())
        sum += run["mean_covis"].get<double>(), ++n;
    if (n > 0) row["mean_covis"] = sum / n;
  }
  nlohmann::json& config = merged["config"];
  config["other_draws"] = true;
  for (size_t i = 0; i < parts.size(); ++i)
    config["parts"][i]["draw"] = {
        {"sets_mean_covis", setsMeanCovis(parts[i].results)},
        {"finetune_baselines", parts[i].results.value("finetune_baselines", nlohmann::json())},
        {"constant_depth", parts[i].results.value("constant_depth", nlohmann::json())}};
}

nlohmann::json bySeed(const std::vector<Part>& parts, const char* key) {
  nlohmann::json all = nlohmann::json::array();
  for (const Part& p : parts)
    for (const auto& run : p.results[key]) all.push_back(run);
  std::stable_sort(all.begin(), all.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
    return a["seed_index"].get<int>() < b["seed_index"].get<int>();
  });
  return all;
}

// The options that the report's page describes, as the parts ran them.
SweepConfig reportConfig(const nlohmann::json& config, const std::string& out) {
  SweepConfig c;
  c.out = out;
  c.reports = false;  // the parts' per-set dataset reports stay with them
  c.seeds = config.value("seeds", 1);
  c.pairsPerSet = config.value("pairs_per_set", c.pairsPerSet);
  c.steps = config.value("steps", c.steps);
  c.preset = config.value("preset", c.preset);
  c.imgSize = config.value("img_size", c.imgSize);
  c.batchSize = config.value("batch_size", c.batchSize);
  const nlohmann::json d = config.value("downstream", nlohmann::json());
  if (d.is_object()) {
    c.downstream = d.value("tasks", std::vector<std::string>{});
    c.finetuneSteps = d.value("steps", c.finetuneSteps);
    c.finetunePairs = d.value("pairs", c.finetunePairs);
    c.finetuneBatch = d.value("batch", c.finetuneBatch);
    c.finetuneFlowMotion = d.value("flow_motion", c.finetuneFlowMotion);
  }
  return c;
}

}  // namespace

nlohmann::json mergeSweepParts(const std::vector<std::string>& paths, const std::string& out,
                               bool otherDraws) {
  if (paths.empty()) throw OptionError("merge", "give the parts to merge");
  if (out.empty()) throw OptionError("out", "an output folder is required");
  std::vector<Part> parts;
  for (const std::string& path : paths) parts.push_back(readPart(path));
  for (const Part& part : parts) refuseToOverwrite(part, out);
  bool drawsDiffer = false;
  for (const Part& part : parts)
    drawsDiffer = checkSameStudy(parts.front(), part, otherDraws) || drawsDiffer;
  checkSeedsOnce(parts);

  nlohmann::json merged = parts.front().results;
  merged["runs"] = bySeed(parts, "runs");
  merged["random_runs"] = bySeed(parts, "random_runs");
  merged["rows"] = aggregateRuns(merged["runs"]);
  merged["random_encoder"] = aggregateRuns(merged["random_runs"]).at(0);
  nlohmann::json& config = merged["config"];
  config["seeds"] = merged["random_runs"].size();
  config["first_seed"] = merged["random_runs"][0]["seed_index"];
  config["parts"] = nlohmann::json::array();
  for (const Part& p : parts)
    config["parts"].push_back(
        {{"results", p.file},
         {"seeds", p.seeds},
         {"precision", p.results["config"].value("precision", nlohmann::json())}});
  if (drawsDiffer) mergeDraws(parts, merged);
  merged["verdicts"] = sweepVerdicts(merged);
  makeDirs(out);
  writeSweepReport(reportConfig(config, out), merged);
  return merged;
}

}  // namespace paircast
