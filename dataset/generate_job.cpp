#include "dataset/generate_job.h"

#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "dataset/shard.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

using Clock = SteadyClock;
constexpr auto since = secondsSince;

constexpr int kHistogramBins = 20;

std::string fmtIndex(uint64_t i) {
  char b[32];
  std::snprintf(b, sizeof b, "%08llu", static_cast<unsigned long long>(i));
  return b;
}

std::string bytesView(const std::vector<unsigned char>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size());
}

// Habitat's quaternion (w, x, y, z) of a pose, as CroCo's metadata stores it: the rotation of
// habitat's camera axes (x right, y up, z back), i.e. R_cam2world * diag(1, -1, -1).
nlohmann::json habitatQuaternion(const Eigen::Matrix3d& R) {
  const Eigen::Matrix3d H = R * Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Eigen::Quaterniond q(H);
  return {q.w(), q.x(), q.y(), q.z()};
}

void histogramAdd(std::vector<uint64_t>& h, double covis) {
  int b = static_cast<int>(covis * kHistogramBins);
  h[std::clamp(b, 0, kHistogramBins - 1)]++;
}

// Per-scene state, created once by the first worker that needs it, and freed when the worker
// that finishes its last pair is done with it: items are in scene order, so a run over
// thousands of scenes holds only the few its workers are on.
struct SceneJob {
  std::string path, name;
  std::once_flag once;
  std::unique_ptr<Scene> scene;
  std::unique_ptr<RayCaster> caster;
  std::unique_ptr<ViewpointSampler> sampler;
  std::unique_ptr<PairGenerator> generator;
  std::string error;               // why the scene is skipped; empty when usable
  std::atomic<size_t> pending{0};  // items of this run not yet finished

  void release() {
    generator.reset();
    sampler.reset();
    caster.reset();
    scene.reset();
  }
};

struct Result {
  bool done = false;  // slot filled
  bool skip = false;  // nothing to write (failed pair or skipped scene)
  std::optional<EncodedPair> pair;
};

// Reads the keys of the shards that already exist, in order, stopping at the first gap.
std::vector<std::vector<std::string>> completedShards(const std::string& out,
                                                      const std::string& prefix) {
  std::vector<std::vector<std::string>> shards;
  for (int s = 0;; ++s) {
    char name[64];
    std::snprintf(name, sizeof name, "%s-%06d.tar", prefix.c_str(), s);
    const std::string path = (fs::path(out) / name).string();
    if (!fs::exists(path)) break;
    shards.push_back(shardKeys(path));
  }
  return shards;
}

void removeTemporaries(const std::string& dir) {
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (it->is_regular_file(ec) && name.size() > 1 && name[0] == '.' &&
        name.find(".tmp.") != std::string::npos)
      fs::remove(it->path(), ec);
  }
}

class ProgressLine {
 public:
  ProgressLine(bool enabled, size_t total)
      : enabled_(enabled), tty_(isatty(2)), total_(total), start_(Clock::now()) {}
  // On a terminal the line is redrawn twice a second; in a log, one line every 10 s.
  void update(size_t done, size_t accepted, size_t candidates, bool force = false) {
    if (!enabled_ || (!force && since(last_) < (tty_ ? 0.5 : 10.0))) return;
    last_ = Clock::now();
    const double t = since(start_);
    const double rate = done / std::max(t, 1e-9);
    const double eta = rate > 0 ? (total_ - done) / rate : 0;
    std::fprintf(
        stderr, "%s[generate_pairs] %zu/%zu pairs  %.1f pairs/s  acceptance %.0f%%  ETA %dm%02ds%s",
        tty_ ? "\r" : "", done, total_, accepted / std::max(t, 1e-9),
        candidates ? 100.0 * accepted / candidates : 0.0, static_cast<int>(eta) / 60,
        static_cast<int>(eta) % 60, tty_ && !force ? "   " : "\n");
  }

 private:
  bool enabled_, tty_;
  size_t total_;
  Clock::time_point start_, last_{};
};

}  // namespace

std::vector<std::string> expandSceneList(const std::vector<std::string>& args) {
  std::vector<std::string> out;
  for (const auto& arg : args) {
    std::error_code ec;
    if (fs::is_directory(arg, ec)) {
      std::vector<std::string> found;
      for (auto it = fs::recursive_directory_iterator(arg, ec);
           it != fs::recursive_directory_iterator(); it.increment(ec)) {
        if (!it->is_regular_file(ec)) continue;
        const std::string ext = it->path().extension().string();
        if (ext == ".mtl" || ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".json" ||
            ext == ".txt" || ext == ".md" || ext == ".bin" || ext == ".exr")
          continue;
        if (isSupportedSceneFile(it->path().string())) found.push_back(it->path().string());
      }
      std::sort(found.begin(), found.end());
      out.insert(out.end(), found.begin(), found.end());
    } else if (fs::is_regular_file(arg, ec) && fs::path(arg).extension() == ".txt") {
      std::ifstream in(arg);
      std::string line;
      const fs::path base = fs::path(arg).parent_path();
      while (std::getline(in, line)) {
        line.erase(0, line.find_first_not_of(" \t"));
        line.erase(line.find_last_not_of(" \t\r") + 1);
        if (line.empty() || line[0] == '#') continue;
        out.push_back(fs::path(line).is_absolute() ? line : (base / line).string());
      }
    } else if (fs::exists(arg, ec)) {
      out.push_back(arg);
    } else {
      throw Error(arg, "no such scene file, folder or list");
    }
  }
  return out;
}

std::vector<std::string> uniqueSceneNames(const std::vector<std::string>& files) {
  std::vector<std::string> out;
  std::set<std::string> taken;
  for (const auto& f : files) {
    const std::string stem = sanitizeName(fs::path(f).stem().string());
    std::string name = stem;
    for (int k = 2; taken.count(name); ++k) name = stem + "_" + std::to_string(k);
    taken.insert(name);
    out.push_back(name);
  }
  return out;
}

nlohmann::json runGenerate(const GenerateConfig& cfg) {
  const auto start = Clock::now();
  if (cfg.out.empty()) throw Error("--out is required");
  if (cfg.pairsPerScene < 1) throw Error("--pairs-per-scene must be at least 1");
  if (cfg.numShards < 1 || cfg.shardIndex < 0 || cfg.shardIndex >= cfg.numShards)
    throw Error("--shard-index must be in [0, --num-shards)");
  if (!cfg.shards && !cfg.croco) throw Error("--format must be shards, croco or both");
  if (cfg.shardSize < 1) throw Error("--shard-size must be at least 1");
  if (!(cfg.pair.minCovis >= 0 && cfg.pair.minCovis <= cfg.pair.maxCovis && cfg.pair.maxCovis <= 1))
    throw Error("the covis band must satisfy 0 <= --min-covis <= --max-covis <= 1");

  // Scenes: expand, name uniquely, keep this machine's part.
  const std::vector<std::string> all = expandSceneList(cfg.scenes);
  if (all.empty()) throw Error("no scene files found in --scenes");
  const std::vector<std::string> names = uniqueSceneNames(all);
  std::vector<std::unique_ptr<SceneJob>> scenes;
  for (size_t i = 0; i < all.size(); ++i) {
    if (static_cast<int>(i % cfg.numShards) != cfg.shardIndex) continue;
    auto job = std::make_unique<SceneJob>();
    job->path = all[i];
    job->name = names[i];
    scenes.push_back(std::move(job));
  }

  makeDirs(cfg.out);
  removeStaleTemporaries(cfg.out);  // left by a killed run
  removeTemporaries(cfg.out);
  const std::string part = cfg.numShards > 1 ? "-" + std::to_string(cfg.shardIndex) : "";
  const std::string shardPrefix = "pairs" + part;
  const fs::path recordsDir = fs::path(cfg.out) / ".paircast" / "records";

  auto recordPath = [&](const SceneJob& s, uint64_t k) {
    return (recordsDir / s.name / (fmtIndex(k) + ".json")).string();
  };
  auto crocoStem = [&](const SceneJob& s, uint64_t k) {
    return (fs::path(cfg.out) / s.name / fmtIndex(k)).string();
  };
  auto readRecord = [&](const std::string& path) -> nlohmann::json {
    std::error_code ec;
    if (!fs::exists(path, ec)) return nullptr;
    auto j = nlohmann::json::parse(readFile(path), nullptr, false);
    return j.is_discarded() ? nlohmann::json(nullptr) : j;
  };

  // What is already done: pairs in completed shards, and pairs with a record (and files).
  std::set<std::string> inShards;
  std::vector<std::vector<std::string>> doneShards;
  if (cfg.shards) {
    doneShards = completedShards(cfg.out, shardPrefix);
    for (const auto& keys : doneShards) inShards.insert(keys.begin(), keys.end());
  }
  struct Item {
    size_t scene;
    uint64_t index;
    bool forShard, forCroco;
  };
  std::vector<Item> items;
  size_t totalItems = 0;
  for (size_t s = 0; s < scenes.size(); ++s) {
    makeDirs((recordsDir / scenes[s]->name).string());
    removeStaleTemporaries((recordsDir / scenes[s]->name).string());
    removeStaleTemporaries((fs::path(cfg.out) / scenes[s]->name).string());
    for (uint64_t k = 0; k < static_cast<uint64_t>(cfg.pairsPerScene); ++k) {
      ++totalItems;
      const nlohmann::json rec = readRecord(recordPath(*scenes[s], k));
      if (rec.is_object() && rec.value("failed", false)) continue;  // known to have no pair
      const bool shardDone = !cfg.shards || inShards.count(sampleKey(scenes[s]->name, k));
      const bool crocoDone =
          !cfg.croco || (rec.is_object() && fs::exists(crocoStem(*scenes[s], k) + "_2.jpeg"));
      if (!shardDone || !crocoDone) {
        items.push_back({s, k, !shardDone, !crocoDone});
        scenes[s]->pending++;
      }
    }
  }

  // Workers generate and encode pairs in any order; the writer appends them to shards in order.
  const int jobs = cfg.jobs > 0 ? cfg.jobs : std::max(1u, std::thread::hardware_concurrency());
  const size_t window = static_cast<size_t>(4 * jobs + 4);
  std::vector<Result> results(items.size());
  std::mutex mu;
  std::condition_variable produced, consumed;
  size_t nextToWrite = 0;
  std::atomic<size_t> nextItem{0};
  std::atomic<bool> stop{false};
  std::exception_ptr failure;
  std::atomic<size_t> accepted{0}, failedPairs{0}, candidates{0};
  std::mutex timeMu;
  double tRender = 0, tCovis = 0, tEncode = 0, tWrite = 0;
  std::mutex warnMu;
  std::vector<nlohmann::json> skipped;
  std::atomic<int> scenesLoaded{0}, scenesPeak{0};

  auto prepareScene = [&](SceneJob& job) {
    std::call_once(job.once, [&] {
      try {
        job.scene = std::make_unique<Scene>(loadScene(job.path, cfg.load));
        const int now = ++scenesLoaded;
        for (int peak = scenesPeak; now > peak && !scenesPeak.compare_exchange_weak(peak, now);) {
        }
        job.scene->name = job.name;
        job.caster = std::make_unique<RayCaster>(job.scene->mesh);
        job.sampler = std::make_unique<ViewpointSampler>(*job.scene, *job.caster, cfg.pair.sampler);
        PairOptions po = cfg.pair;
        po.keepDepth = cfg.saveDepth;
        job.generator = std::make_unique<PairGenerator>(*job.scene, *job.caster, *job.sampler, po);
        // A scene whose first pair cannot be made has no usable views: skip it whole.
        const nlohmann::json rec0 = readRecord(recordPath(job, 0));
        if (!rec0.is_object() && !job.generator->generate(cfg.seed, 0))
          job.error = "no valid views (no pair found for index 0)";
        if (rec0.is_object() && rec0.value("failed", false))
          job.error = "no valid views (no pair found for index 0)";
      } catch (const Error& e) {
        job.error = e.what();
      }
      if (!job.error.empty()) {
        std::lock_guard<std::mutex> lock(warnMu);
        std::fprintf(stderr, "%sgenerate_pairs: warning: skipping scene %s: %s\n",
                     cfg.progress ? "\n" : "", job.path.c_str(), job.error.c_str());
        skipped.push_back({{"scene", job.path}, {"reason", job.error}});
      }
    });
  };

  auto worker = [&]() {
    try {
      while (!stop) {
        const size_t i = nextItem++;
        if (i >= items.size()) return;
        {
          std::unique_lock<std::mutex> lock(mu);
          consumed.wait(lock, [&] { return stop || i < nextToWrite + window; });
          if (stop) return;
        }
        const Item& item = items[i];
        SceneJob& job = *scenes[item.scene];
        prepareScene(job);
        Result r;
        r.done = true;
        if (!job.error.empty()) {
          r.skip = true;
        } else {
          std::vector<float> tried;
          auto sample = job.generator->generate(cfg.seed, item.index, &tried);
          candidates += tried.size();
          if (!sample) {
            ++failedPairs;
            nlohmann::json rec = {{"failed", true},
                                  {"scene", job.name},
                                  {"index", item.index},
                                  {"candidate_covis", tried}};
            writeFileAtomic(recordPath(job, item.index), rec.dump() + "\n", Durability::NoSync);
            r.skip = true;
          } else {
            auto t0 = Clock::now();
            EncodedPair enc = encodePair(*sample, cfg.saveDepth, cfg.jpegQuality);
            enc.record["candidate_covis"] = sample->candidateCovis;
            const double encode = since(t0);
            t0 = Clock::now();
            if (item.forCroco) {
              makeDirs((fs::path(cfg.out) / job.name).string());
              const std::string stem = crocoStem(job, item.index);
              for (int k = 0; k < 2; ++k) {
                const std::string view = "_" + std::to_string(k + 1);
                writeFileAtomic(stem + view + ".jpeg", bytesView(enc.jpeg[k]), Durability::NoSync);
                if (cfg.saveDepth) {
                  writeFileAtomic(stem + view + "_depth.exr", bytesView(enc.depthExr[k]),
                                  Durability::NoSync);
                  nlohmann::json cam = cameraToJson(sample->camera[k]);
                  cam.erase("width");
                  cam.erase("height");
                  writeFileAtomic(stem + view + "_camera_params.json", cam.dump() + "\n",
                                  Durability::NoSync);
                }
              }
            }
            writeFileAtomic(recordPath(job, item.index), enc.record.dump() + "\n",
                            Durability::NoSync);
            {
              std::lock_guard<std::mutex> lock(timeMu);
              tRender += sample->renderSeconds;
              tCovis += sample->covisSeconds;
              tEncode += encode;
              tWrite += since(t0);
            }
            ++accepted;
            if (item.forShard) r.pair = std::move(enc);
          }
        }
        if (--job.pending == 0) {  // no other worker holds an item of it
          if (job.scene) --scenesLoaded;
          job.release();
        }
        std::lock_guard<std::mutex> lock(mu);
        results[i] = std::move(r);
        produced.notify_all();
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(mu);
      if (!failure) failure = std::current_exception();
      stop = true;
      produced.notify_all();
      consumed.notify_all();
    }
  };

  // Nested parallelism off: each worker renders its own pairs on one core.
  omp_set_max_active_levels(1);
  const int ompThreadsBefore = omp_get_max_threads();
  omp_set_num_threads(1);
  std::vector<std::thread> threads;
  for (int t = 0; t < jobs; ++t) threads.emplace_back(worker);

  ProgressLine progress(cfg.progress, items.size());
  std::unique_ptr<ShardWriter> shard;
  int shardNumber = static_cast<int>(doneShards.size());
  std::vector<nlohmann::json> shardList;
  for (size_t s = 0; s < doneShards.size(); ++s)
    shardList.push_back({{"pairs", doneShards[s].size()}});
  auto shardPath = [&](int n) {
    char name[64];
    std::snprintf(name, sizeof name, "%s-%06d.tar", shardPrefix.c_str(), n);
    return (fs::path(cfg.out) / name).string();
  };
  try {
    for (size_t i = 0; i < items.size(); ++i) {
      Result r;
      {
        std::unique_lock<std::mutex> lock(mu);
        produced.wait(lock, [&] { return stop || results[i].done; });
        if (stop && !results[i].done) break;
        r = std::move(results[i]);
        results[i] = Result{};
        nextToWrite = i + 1;
        consumed.notify_all();
      }
      if (r.pair && cfg.shards) {
        auto t0 = Clock::now();
        if (!shard) shard = std::make_unique<ShardWriter>(shardPath(shardNumber));
        shard->add(*r.pair);
        if (static_cast<int>(shard->samples()) >= cfg.shardSize ||
            shard->bytes() >= cfg.shardMaxBytes) {
          shard->close();
          shardList.push_back({{"pairs", shard->samples()}});
          shard.reset();
          ++shardNumber;
        }
        std::lock_guard<std::mutex> lock(timeMu);
        tWrite += since(t0);
      }
      progress.update(i + 1, accepted, candidates);
    }
    if (shard && !stop) {
      shard->close();
      shardList.push_back({{"pairs", shard->samples()}});
      shard.reset();
    }
  } catch (...) {
    std::lock_guard<std::mutex> lock(mu);
    if (!failure) failure = std::current_exception();
    stop = true;
    consumed.notify_all();
  }
  for (auto& t : threads) t.join();
  omp_set_num_threads(ompThreadsBefore);
  if (failure) std::rethrow_exception(failure);
  progress.update(items.size(), accepted, candidates, true);

  // Outputs assembled from the per-pair records, so that a resumed run reports everything.
  std::vector<uint64_t> histogram(kHistogramBins, 0), candidateHistogram(kHistogramBins, 0);
  uint64_t pairs = 0, tried = 0;
  std::string pairsTxt;
  nlohmann::json perScene = nlohmann::json::object();
  std::set<std::string> skippedNames;
  for (const auto& s : skipped) skippedNames.insert(s["scene"].get<std::string>());
  for (const auto& jobPtr : scenes) {
    const SceneJob& job = *jobPtr;
    if (skippedNames.count(job.path)) continue;
    nlohmann::json multiviews = nlohmann::json::object();
    uint64_t scenePairs = 0;
    for (uint64_t k = 0; k < static_cast<uint64_t>(cfg.pairsPerScene); ++k) {
      const nlohmann::json rec = readRecord(recordPath(job, k));
      if (!rec.is_object()) continue;
      for (const auto& c : rec.value("candidate_covis", nlohmann::json::array())) {
        histogramAdd(candidateHistogram, c.get<double>());
        ++tried;
      }
      if (rec.value("failed", false)) continue;
      ++pairs;
      ++scenePairs;
      histogramAdd(histogram, rec["covis"].get<double>());
      if (!cfg.croco) continue;
      const Camera c1 = cameraFromJson(rec["camera1"], recordPath(job, k));
      const Camera c2 = cameraFromJson(rec["camera2"], recordPath(job, k));
      const double f1 = rec["valid_fraction1"], f2 = rec["valid_fraction2"];
      multiviews[fmtIndex(k)] = {
          {"positions",
           {{c1.t_cam2world.x(), c1.t_cam2world.y(), c1.t_cam2world.z()},
            {c2.t_cam2world.x(), c2.t_cam2world.y(), c2.t_cam2world.z()}}},
          {"orientations", {habitatQuaternion(c1.R_cam2world), habitatQuaternion(c2.R_cam2world)}},
          {"covisibility_ratios", {f1, rec["covis"]}},
          {"valid_fractions", {f1, f2}},
          {"pairwise_visibility_ratios", {{f1, rec["v_ij"]}, {rec["v_ji"], f2}}}};
      pairsTxt +=
          job.name + "/" + fmtIndex(k) + "_1.jpeg " + job.name + "/" + fmtIndex(k) + "_2.jpeg\n";
    }
    perScene[job.name] = scenePairs;
    if (cfg.croco) {
      nlohmann::json meta = {{"scene", job.path},
                             {"views_count", 2},
                             {"size", cfg.pairsPerScene},
                             {"generate_depth", cfg.saveDepth},
                             {"resolution", cfg.pair.resolution},
                             {"hfov", cfg.pair.hfov},
                             {"minimum_covisibility", cfg.pair.minCovis},
                             {"maximum_covisibility", cfg.pair.maxCovis},
                             {"seed", cfg.seed},
                             {"generator", "paircast"},
                             {"multiviews", multiviews}};
      makeDirs((fs::path(cfg.out) / job.name).string());
      writeFileAtomic((fs::path(cfg.out) / job.name / "metadata.json").string(),
                      meta.dump() + "\n");
    }
  }
  if (cfg.croco)
    writeFileAtomic((fs::path(cfg.out) / ("pairs" + part + ".txt")).string(), pairsTxt);
  if (cfg.shards) {
    for (size_t s = 0; s < shardList.size(); ++s) {
      char name[64];
      std::snprintf(name, sizeof name, "%s-%06zu.tar", shardPrefix.c_str(), s);
      shardList[s]["name"] = name;
    }
    nlohmann::json index = {{"format", "paircast-shards"},
                            {"format_version", kShardVersion},
                            {"pairs", pairs},
                            {"shards", shardList},
                            {"pairs_per_scene", perScene},
                            {"covis_histogram", histogram},
                            {"depth", cfg.saveDepth},
                            {"resolution", cfg.pair.resolution},
                            {"hfov", cfg.pair.hfov},
                            {"seed", cfg.seed}};
    writeFileAtomic((fs::path(cfg.out) / ("index" + part + ".json")).string(),
                    index.dump(1) + "\n");
  }
  const double seconds = since(start);
  const double split = std::max(tRender + tCovis + tEncode + tWrite, 1e-12);
  nlohmann::json summary = {
      {"pairs", pairs},
      {"candidates", tried},
      {"acceptance", tried ? static_cast<double>(pairs) / tried : 0.0},
      {"seconds", seconds},
      {"pairs_this_run", accepted.load()},
      {"pairs_per_second", accepted / std::max(seconds, 1e-9)},
      {"failed_pairs", failedPairs.load()},
      {"covis_histogram", histogram},
      {"candidate_covis_histogram", candidateHistogram},
      {"time_split",
       {{"render", tRender / split},
        {"covis", tCovis / split},
        {"encode", tEncode / split},
        {"write", tWrite / split}}},
      {"time_seconds",
       {{"render", tRender}, {"covis", tCovis}, {"encode", tEncode}, {"write", tWrite}}},
      {"skipped_scenes", skipped},
      {"scenes_in_memory_max", scenesPeak.load()},
      {"jobs", jobs}};
  writeFileAtomic((fs::path(cfg.out) / ("summary" + part + ".json")).string(),
                  summary.dump(1) + "\n");
  return summary;
}

}  // namespace paircast
