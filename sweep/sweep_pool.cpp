#include "sweep/sweep_pool.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "dataset/generate_range.h"
#include "dataset/pair_generator.h"
#include "dataset/shard.h"
#include "sweep/sweep_scene.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

// What pool.json holds: the pool so far, and where its sampling goes on.
struct PoolProgress {
  Pool pool;
  uint64_t nextIndex = 0;  // of the next pair to sample
  int rounds = 0;
  std::vector<int> have = std::vector<int>(kCovisBuckets, 0);  // pairs per bucket

  void add(const std::string& key, double covis) {
    pool.keys.push_back(key);
    pool.covis.push_back(covis);
    have[covisBucket(pool.covis.back())]++;
  }
  // Pairs still needed per bucket.
  std::vector<int> deficit(const std::vector<int>& demand) const {
    std::vector<int> d(kCovisBuckets);
    for (int b = 0; b < kCovisBuckets; ++b) d[b] = std::max(0, demand[b] - have[b]);
    return d;
  }
};

int total(const std::vector<int>& counts) {
  int n = 0;
  for (int v : counts) n += v;
  return n;
}

// The settings a pool was sampled with: a pool.json of other settings is not resumed.
nlohmann::json poolSettings(const SweepConfig& c, const std::vector<std::string>& sceneFiles,
                            const std::vector<int>& demand) {
  nlohmann::json settings = {{"scenes", sceneFiles},
                             {"seed", c.seed},
                             {"resolution", c.resolution},
                             {"demand", demand},
                             {"min_walk_scale", c.minWalkScale}};
  // Only a non-default axis is named, so that pools sampled before --up existed still resume.
  if (c.load.up != UpAxis::Y) settings["up"] = c.load.up == UpAxis::Z ? "z" : "auto";
  return settings;
}

// pool.json's progress; none (an empty pool) when there is no such file.
PoolProgress readPoolProgress(const std::string& statePath, const nlohmann::json& settings) {
  PoolProgress p;
  if (const nlohmann::json state = readSweepState(statePath); state.is_object()) {
    if (state.value("settings", nlohmann::json()) != settings)
      throw Error(statePath,
                  "was sampled with other settings (scenes, seed, resolution or set sizes); use "
                  "another --out or delete the pool folder");
    for (const auto& pair : state.at("pairs"))
      p.add(pair.at("key").get<std::string>(), pair.at("covis").get<double>());
    p.nextIndex = state.at("next_index").get<uint64_t>();
    p.rounds = state.at("rounds").get<int>();
  }
  return p;
}

void writePoolProgress(const std::string& statePath, const nlohmann::json& settings,
                       const PoolProgress& p) {
  nlohmann::json pairs = nlohmann::json::array();
  for (size_t i = 0; i < p.pool.keys.size(); ++i)
    pairs.push_back({{"key", p.pool.keys[i]}, {"covis", p.pool.covis[i]}});
  writeFileAtomic(statePath, nlohmann::json({{"settings", settings},
                                             {"pairs", pairs},
                                             {"next_index", p.nextIndex},
                                             {"rounds", p.rounds}})
                                     .dump() +
                                 "\n");
}

// One sampling round: pairs nextIndex .. nextIndex + m - 1, each from the scenes in turn, of which
// those whose bucket still needs them (`need`) are kept, in index order, in pool-<round>.tar.
// Returns the kept pairs' keys and covis.
nlohmann::json samplePoolRound(const SweepConfig& c,
                               const std::vector<std::unique_ptr<SweepScene>>& scenes,
                               const SamplerOptions& so, const std::vector<int>& need, int m,
                               uint64_t nextIndex, int round, const fs::path& dir) {
  PairOptions po;
  po.resolution = c.resolution;
  po.keepDepth = false;
  po.sampler = so;
  po.maxReferences = 4;  // rare buckets: many cheap tries over more indices
  po.maxAttempts = 25;
  po.accept = [need](double v) { return need[covisBucket(v)] > 0; };
  std::vector<std::unique_ptr<PairGenerator>> gens;
  for (auto& s : scenes)
    gens.push_back(std::make_unique<PairGenerator>(*s->scene, *s->caster, *s->sampler, po));
  const std::vector<std::optional<PairSample>> got = generateRange(
      [&gens](uint64_t idx) -> const PairGenerator& { return *gens[idx % gens.size()]; }, c.seed,
      nextIndex, m, sweepThreads(c));
  // Keep, in index order, the pairs whose bucket still needs them.
  char name[64];
  std::snprintf(name, sizeof name, "pool-%06d.tar", round);
  ShardWriter writer((dir / name).string());
  std::vector<int> left = need;
  nlohmann::json added = nlohmann::json::array();
  for (int i = 0; i < m; ++i) {
    if (!got[i]) continue;
    const int b = covisBucket(got[i]->covis[1].covis);
    if (left[b] <= 0) continue;
    --left[b];
    const EncodedPair enc = encodePair(*got[i], false, 90);
    writer.add(enc);
    added.push_back({{"key", enc.key}, {"covis", got[i]->covis[1].covis}});
  }
  if (!added.empty()) writer.close();  // an empty round leaves no shard
  return added;
}

// The buckets still short, with what they have of what they need: " [0.05,0.10): 3/16".
std::string shortBuckets(const PoolProgress& p, const std::vector<int>& demand) {
  const std::vector<int> after = p.deficit(demand);
  std::string shortList;
  for (int b = 0; b < kCovisBuckets; ++b)
    if (after[b] > 0)
      shortList += " [" + centerName(b * 0.05) + "," + centerName((b + 1) * 0.05) +
                   "): " + std::to_string(p.have[b]) + "/" + std::to_string(demand[b]);
  return shortList;
}

}  // namespace

Pool buildPool(const SweepConfig& c, const std::vector<std::string>& sceneFiles,
               const std::vector<int>& demand) {
  const fs::path dir = fs::path(c.out) / "pool";
  makeDirs(dir.string());
  const std::string statePath = (dir / "pool.json").string();
  const nlohmann::json settings = poolSettings(c, sceneFiles, demand);
  PoolProgress p = readPoolProgress(statePath, settings);
  if (total(p.deficit(demand)) == 0) return p.pool;

  SamplerOptions so;
  so.minWalkScale = c.minWalkScale;
  auto scenes = loadSweepScenes(sceneFiles, c.load, so, "training");
  const auto start = SteadyClock::now();
  int idle = 0;
  while (true) {
    const std::vector<int> need = p.deficit(demand);
    const int missing = total(need);
    if (missing == 0) break;
    const int m = std::max(8, missing + missing / 4);
    const nlohmann::json added =
        samplePoolRound(c, scenes, so, need, m, p.nextIndex, p.rounds, dir);
    p.nextIndex += m;
    ++p.rounds;
    for (const auto& a : added) p.add(a["key"], a["covis"]);
    writePoolProgress(statePath, settings, p);
    sweepSay(c, "pool round " + std::to_string(p.rounds) + ": " +
                    std::to_string(p.pool.keys.size()) + " pairs, " +
                    std::to_string(total(p.deficit(demand))) + " still needed (" +
                    std::to_string(static_cast<int>(secondsSince(start))) + " s)");
    idle = added.empty() ? idle + 1 : 0;
    if (idle >= 3 || p.rounds >= 400)
      throw Error(statePath, "cannot fill the covis buckets:" + shortBuckets(p, demand) +
                                 " (the scenes rarely give such pairs; drop those centres or "
                                 "lower --pairs-per-set)");
  }
  return p.pool;
}

}  // namespace paircast
