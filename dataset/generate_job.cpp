// generate_pairs in stages: plan the work (scenes, what a killed run already finished), load each
// scene when a worker first needs it and check that it has valid views, make samples on the
// workers, write them in order on the calling thread (journal, shards, CroCo files), then
// summarise from the journal.
#include "dataset/generate_job.h"

#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
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
#include <unordered_set>

#include "dataset/croco_layout.h"
#include "dataset/habitat_frame.h"
#include "dataset/journal.h"
#include "dataset/run_stats.h"
#include "dataset/shard.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"
#include "util/progress_line.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

using Clock = SteadyClock;
constexpr auto since = secondsSince;

// OpenMP's thread count of the calling thread, set for a scope and put back after it.
class OmpThreads {
 public:
  explicit OmpThreads(int n) : before_(omp_get_max_threads()) { omp_set_num_threads(n); }
  ~OmpThreads() { omp_set_num_threads(before_); }
  OmpThreads(const OmpThreads&) = delete;
  OmpThreads& operator=(const OmpThreads&) = delete;

 private:
  int before_;
};

constexpr int kHistogramBins = 20;
// A scene is skipped as having no valid views when this many of its first indices (or all it has,
// if fewer) have no sample: one index's failure says little, since a scene whose floor is only
// partly valid fails most of its indices and still makes many pairs (docs/dataset.md).
constexpr uint64_t kViewCheckIndices = 32;

int histogramBin(double covis) {
  return std::clamp(static_cast<int>(covis * kHistogramBins), 0, kHistogramBins - 1);
}

void histogramAdd(std::vector<uint64_t>& h, double covis) {
  h[histogramBin(covis)]++;
}

// The candidates' covis as the journal keeps them: their histogram bins, a letter each ('A' is
// bin 0), all that the summary needs.
std::string candidateBins(const std::vector<float>& covis) {
  std::string bins;
  for (float c : covis) bins += static_cast<char>('A' + histogramBin(static_cast<double>(c)));
  return bins;
}

// The journal's key of a record: its sample key, or "" for a line that is not a record.
std::string recordKey(const nlohmann::json& r) {
  const auto scene = r.find("scene"), index = r.find("index");
  if (scene == r.end() || !scene->is_string() || index == r.end() || !index->is_number_unsigned())
    return "";
  return sampleKey(scene->get<std::string>(), index->get<uint64_t>());
}

// Whether a journal record is of an index known to have no sample.
bool recordFailed(const nlohmann::json& r) {
  return r.value("failed", false);
}

// Resident memory of the process, bytes (0 when /proc is not there).
uint64_t residentBytes() {
  std::ifstream in("/proc/self/statm");
  uint64_t pages = 0, resident = 0;
  if (!(in >> pages >> resident)) return 0;
  return resident * static_cast<uint64_t>(::sysconf(_SC_PAGESIZE));
}

// What one generate() call gave: a sample or none, and what it cost either way.
struct Attempt {
  std::optional<PairSample> sample;
  GenerationCost spent;
};

// Per-scene state, created once by the first worker that needs it, and freed when the worker
// that finishes its last sample is done with it: items are in scene order, so a run over
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
  nlohmann::json stats;            // scene_stats entry, once loaded
  // [indices checked] the attempts the check for valid views made (null where it read the
  // journal), each taken by its item's worker. Filled once, before any item of the scene is made,
  // and never resized after: workers touch only their own index's slot.
  std::vector<std::optional<Attempt>> checked;

  void release() {
    checked.clear();
    generator.reset();
    sampler.reset();
    caster.reset();
    scene.reset();
  }
};

struct Item {
  size_t scene;
  uint64_t index;
  bool forShard, forCroco;
};

struct Result {
  bool done = false;     // slot filled
  nlohmann::json note;   // for the journal; null when nothing is recorded (skipped scene)
  nlohmann::json entry;  // its CroCo metadata entry, when its CroCo files were written
  std::optional<EncodedPair> pair;  // for the shard
};

// CroCo's metadata entry of one sample, from its record.
nlohmann::json multiviewEntry(const nlohmann::json& rec, const std::string& source) {
  nlohmann::json positions = nlohmann::json::array();
  for (const auto& c : rec.at("cameras")) {
    const Camera cam = cameraFromJson(c, source);
    positions.push_back({cam.t_cam2world.x(), cam.t_cam2world.y(), cam.t_cam2world.z()});
  }
  const nlohmann::json& orientations = rec.at("orientations");
  return {{"positions", positions},
          {"orientations", orientations},
          {"covisibility_ratios", rec.at("covisibility_ratios")},
          {"valid_fractions", rec.at("valid_fractions")},
          {"pairwise_visibility_ratios", rec.at("pairwise_visibility_ratios")}};
}

// "pairs-000042.tar", or "pairs-<part>-000042.tar" for part "-<part>" of several machines.
std::string shardName(const std::string& part, size_t n) {
  char name[64];
  std::snprintf(name, sizeof name, "pairs%s-%06zu.tar", part.c_str(), n);
  return name;
}

// The keys of the shards that already exist, stopping at the first gap; each shard is listed in
// `list`. A shard under its final name is whole (it is renamed into place): its headers are
// enough.
std::unordered_set<std::string> completedShards(const std::string& out, const std::string& part,
                                                std::vector<nlohmann::json>& list) {
  std::unordered_set<std::string> keys;
  for (size_t s = 0;; ++s) {
    const std::string path = (fs::path(out) / shardName(part, s)).string();
    if (!fs::exists(path)) break;
    const std::vector<std::string> shard = ShardIndex::keys(path);
    keys.insert(shard.begin(), shard.end());
    list.push_back({{"pairs", shard.size()}});
  }
  return keys;
}

// "[generate_pairs] 120/500 pairs  38.1 pairs/s  acceptance 6%  ETA 0m10s"
std::string progressText(size_t done, size_t total, size_t accepted, size_t candidates,
                         double seconds) {
  const double rate = done / std::max(seconds, 1e-9);
  const int eta = rate > 0 ? static_cast<int>((total - done) / rate) : 0;
  char line[160];
  std::snprintf(line, sizeof line,
                "[generate_pairs] %zu/%zu pairs  %.1f pairs/s  acceptance %.0f%%  ETA %dm%02ds",
                done, total, accepted / std::max(seconds, 1e-9),
                candidates ? 100.0 * accepted / candidates : 0.0, eta / 60, eta % 60);
  return line;
}

// One run of the job. The constructor plans it; run() makes and writes what is missing;
// summarise() assembles the outputs from the journal, so a resumed run reports everything.
class GenerateRun {
 public:
  explicit GenerateRun(const GenerateConfig& cfg);
  void run();
  nlohmann::json summarise();

 private:
  // Planning.
  void planScenes();
  void openOutputs();
  void planItems();
  std::string crocoStem(const SceneJob& s, uint64_t k) const {
    return (fs::path(cfg_.out) / s.name / crocoIndex(k)).string();
  }
  std::string outPath(const std::string& stem, const std::string& ext) const {
    return (fs::path(cfg_.out) / (stem + part_ + ext)).string();
  }
  // The journal of a scene's CroCo metadata entries, .paircast/metadata<part>/<scene>.jsonl.
  std::string entriesPath(const SceneJob& s) const {
    return (fs::path(cfg_.out) / ".paircast" / ("metadata" + part_) / (s.name + ".jsonl")).string();
  }
  std::unique_ptr<Journal> openEntries(const SceneJob& s) const;
  // Whether a file at the top of --out is this part's: its shards, index, pairs.txt, summary.
  bool ownsFile(const std::string& name) const;
  // Workers.
  void worker();
  bool waitForWindow(size_t i);
  void finishItem(size_t i, Result r);
  Result makeItem(const Item& item);
  void prepareScene(SceneJob& job);
  void loadScene(SceneJob& job);
  void checkViews(SceneJob& job);
  bool hasSample(SceneJob& job, uint64_t index);
  void skipScene(SceneJob& job);
  Attempt generateAt(const SceneJob& job, uint64_t index) const;
  Attempt takeAttempt(SceneJob& job, uint64_t index) const;
  Result failedResult(const SceneJob& job, const Item& item, const GenerationCost& spent);
  Result keptResult(const SceneJob& job, const Item& item, const PairSample& sample,
                    const GenerationCost& spent);
  void fail();
  // The writer, on the calling thread.
  void writeInOrder();
  void writeResult(const Item& item, const Result& r);
  void addToShard(const EncodedPair& pair);
  void closeShard();
  // Summary.
  void writeCredits(const std::set<std::string>& skippedPaths);
  void writeShardIndex(const nlohmann::json& perScene);
  void summariseScene(const SceneJob& job, nlohmann::json& perScene, std::string& pairsTxt);
  void writeSceneMetadata(const SceneJob& job, const std::string& up,
                          nlohmann::json multiviews) const;
  void tallyCandidates(const nlohmann::json& note);
  std::map<uint64_t, nlohmann::json> readEntries(const SceneJob& job) const;
  nlohmann::json summaryJson(double seconds) const;

  const GenerateConfig& cfg_;
  const Clock::time_point start_ = Clock::now();
  std::string part_;  // "-<shard index>" with several machines, else ""
  std::vector<std::unique_ptr<SceneJob>> scenes_;
  std::unique_ptr<Journal> journal_;
  std::unordered_set<std::string> inShards_;  // keys of the completed shards
  std::vector<Item> items_;
  int jobs_ = 1;

  // Workers hand results to the writer through a window of slots.
  std::vector<Result> results_;
  std::mutex mu_;
  std::condition_variable produced_, consumed_;
  size_t nextToWrite_ = 0;
  std::atomic<size_t> nextItem_{0};
  std::atomic<bool> stop_{false};
  std::exception_ptr failure_;
  std::mutex loadMu_;  // scenes load one at a time, so that their memory can be measured

  RunStats stats_;  // counters and the time split
  std::mutex warnMu_;
  std::vector<nlohmann::json> skipped_;
  std::atomic<int> scenesLoaded_{0}, scenesPeak_{0};

  // Shards being written.
  std::unique_ptr<ShardWriter> shard_;
  std::vector<nlohmann::json> shardList_;
  // The CroCo metadata entries of the scene being written.
  std::unique_ptr<Journal> entries_;
  size_t entriesScene_ = 0;

  // Summary tallies.
  std::vector<uint64_t> histogram_ = std::vector<uint64_t>(kHistogramBins, 0);
  std::vector<uint64_t> candidateHistogram_ = std::vector<uint64_t>(kHistogramBins, 0);
  uint64_t pairs_ = 0, tried_ = 0;
};

GenerateRun::GenerateRun(const GenerateConfig& cfg) : cfg_(cfg) {
  cfg.validate();
  part_ = cfg.numShards > 1 ? "-" + std::to_string(cfg.shardIndex) : "";
  jobs_ =
      cfg.jobs > 0 ? cfg.jobs : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  planScenes();
  openOutputs();
  if (cfg.shards) inShards_ = completedShards(cfg.out, part_, shardList_);
  planItems();
}

// The output folder, cleared of this part's temporaries, and the journal.
void GenerateRun::openOutputs() {
  makeDirs(cfg_.out);
  // Temporaries left by a killed run of this part, on this machine or another: only this part's
  // files, the other parts writing into the same folder (their scene folders are theirs too).
  removeStaleTemporaries(cfg_.out, [this](const std::string& name) { return ownsFile(name); });
  const fs::path bookkeeping = fs::path(cfg_.out) / ".paircast";
  makeDirs(bookkeeping.string());
  const std::string journalName = "journal" + part_ + ".jsonl";
  removeStaleTemporaries(bookkeeping.string(),
                         [&](const std::string& name) { return name == journalName; });
  journal_ =
      std::make_unique<Journal>((bookkeeping / journalName).string(), recordKey, recordFailed);
}

bool GenerateRun::ownsFile(const std::string& name) const {
  if (name == "index" + part_ + ".json" || name == "pairs" + part_ + ".txt" ||
      name == "summary" + part_ + ".json" || name == "credits" + part_ + ".json")
    return true;
  // pairs<part>-NNNNNN.tar
  const std::string prefix = "pairs" + part_ + "-", suffix = ".tar";
  if (name.size() <= prefix.size() + suffix.size() || name.rfind(prefix, 0) != 0 ||
      name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
    return false;
  const std::string n = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
  return n.find_first_not_of("0123456789") == std::string::npos;
}

// Scenes: expand, name uniquely, keep this machine's part.
void GenerateRun::planScenes() {
  const std::vector<std::string> all = expandSceneList(cfg_.scenes);
  if (all.empty()) throw OptionError("scenes", "no scene files found in the scene list");
  const std::vector<std::string> names = uniqueSceneNames(all);
  for (size_t i = 0; i < all.size(); ++i) {
    if (static_cast<int>(i % cfg_.numShards) != cfg_.shardIndex) continue;
    auto job = std::make_unique<SceneJob>();
    job->path = all[i];
    job->name = names[i];
    scenes_.push_back(std::move(job));
  }
  if (scenes_.empty())  // a Slurm array with more tasks than scenes, say
    throw Error("part " + std::to_string(cfg_.shardIndex) + " of " +
                std::to_string(cfg_.numShards) + " has no scene: the scene list has " +
                std::to_string(all.size()) + " scene(s) for " + std::to_string(cfg_.numShards) +
                " parts (use at most " + std::to_string(all.size()) + " parts)");
}

// What is left: samples in neither a completed shard nor the journal (with their files).
void GenerateRun::planItems() {
  const std::string lastView = "_" + std::to_string(cfg_.pair.views) + ".jpeg";
  for (size_t s = 0; s < scenes_.size(); ++s) {
    SceneJob& job = *scenes_[s];
    removeStaleTemporaries((fs::path(cfg_.out) / job.name).string());  // the part's own folder
    const std::unique_ptr<Journal> entries =
        cfg_.croco && fs::exists(entriesPath(job)) ? openEntries(job) : nullptr;
    for (uint64_t k = 0; k < static_cast<uint64_t>(cfg_.pairsPerScene); ++k) {
      const std::string key = sampleKey(job.name, k);
      const Journal::Has noted = journal_->has(key);
      if (noted == Journal::Has::kMarked) continue;  // known to have no sample
      const bool shardDone = !cfg_.shards || inShards_.count(key);
      const bool crocoDone =
          !cfg_.croco || (noted == Journal::Has::kYes && entries && entries->contains(key) &&
                          fs::exists(crocoStem(job, k) + lastView));
      if (shardDone && crocoDone) continue;
      items_.push_back({s, k, !shardDone, !crocoDone});
      job.pending++;
    }
  }
  inShards_ = {};  // no longer needed
}

std::unique_ptr<Journal> GenerateRun::openEntries(const SceneJob& s) const {
  makeDirs(fs::path(entriesPath(s)).parent_path().string());
  return std::make_unique<Journal>(entriesPath(s), recordKey);
}

void GenerateRun::run() {
  results_.resize(items_.size());
  std::vector<std::thread> threads;
  for (int t = 0; t < jobs_; ++t) threads.emplace_back([this] { worker(); });
  try {
    writeInOrder();
  } catch (...) {
    fail();
  }
  for (auto& t : threads) t.join();
  if (entries_) entries_->sync();
  entries_.reset();
  journal_->sync();
  if (failure_) std::rethrow_exception(failure_);
}

void GenerateRun::fail() {
  std::lock_guard<std::mutex> lock(mu_);
  if (!failure_) failure_ = std::current_exception();
  stop_ = true;
  produced_.notify_all();
  consumed_.notify_all();
}

void GenerateRun::worker() {
  // OpenMP's thread count is per thread: each worker renders on one core.
  omp_set_num_threads(1);
  try {
    while (!stop_) {
      const size_t i = nextItem_++;
      if (i >= items_.size() || !waitForWindow(i)) return;
      finishItem(i, makeItem(items_[i]));
    }
  } catch (...) {
    fail();
  }
}

// Waits until item i is within the window of slots ahead of the writer; false when the run stops.
bool GenerateRun::waitForWindow(size_t i) {
  const size_t window = static_cast<size_t>(4 * jobs_ + 4);
  std::unique_lock<std::mutex> lock(mu_);
  consumed_.wait(lock, [&] { return stop_ || i < nextToWrite_ + window; });
  return !stop_;
}

// Frees the item's scene when it was the scene's last, and hands the result to the writer.
void GenerateRun::finishItem(size_t i, Result r) {
  SceneJob& job = *scenes_[items_[i].scene];
  if (--job.pending == 0) {  // no other worker holds an item of it
    if (job.scene) --scenesLoaded_;
    job.release();
  }
  std::lock_guard<std::mutex> lock(mu_);
  results_[i] = std::move(r);
  // The writer waits for item nextToWrite_ alone: waking it for another would only switch it in
  // and out of a core the workers need.
  if (i == nextToWrite_) produced_.notify_all();
}

// One sample: generated (or taken from the scene's check), encoded, its CroCo files written; the
// journal record and shard entry go to the writer.
Result GenerateRun::makeItem(const Item& item) {
  SceneJob& job = *scenes_[item.scene];
  prepareScene(job);
  if (!job.error.empty()) {
    Result skipped;  // nothing recorded: a resumed run checks the scene again
    skipped.done = true;
    return skipped;
  }
  const Attempt a = takeAttempt(job, item.index);
  Result r =
      a.sample ? keptResult(job, item, *a.sample, a.spent) : failedResult(job, item, a.spent);
  r.done = true;
  return r;
}

// Once per scene, by the first worker that needs it: load it and check that it has valid views,
// or skip it whole.
void GenerateRun::prepareScene(SceneJob& job) {
  std::call_once(job.once, [&] {
    try {
      loadScene(job);
      checkViews(job);
    } catch (const Error& e) {
      job.error = e.what();
    }
    if (!job.error.empty()) skipScene(job);
  });
}

// Loads the mesh, builds the BVH and the floor map, and measures them (scene_stats).
void GenerateRun::loadScene(SceneJob& job) {
  std::lock_guard<std::mutex> lock(loadMu_);
  const uint64_t before = residentBytes();
  auto t0 = Clock::now();
  job.scene = std::make_unique<Scene>(paircast::loadScene(job.path, cfg_.load));
  const int now = ++scenesLoaded_;
  for (int peak = scenesPeak_; now > peak && !scenesPeak_.compare_exchange_weak(peak, now);) {
  }
  job.scene->name = job.name;
  const double loadSeconds = since(t0);
  for (const auto& w : job.scene->warnings) {
    std::lock_guard<std::mutex> warn(warnMu_);
    std::fprintf(stderr, "%sgenerate_pairs: warning: %s: %s\n", cfg_.progress ? "\n" : "",
                 job.path.c_str(), w.c_str());
  }
  t0 = Clock::now();
  job.caster = std::make_unique<RayCaster>(job.scene->mesh);
  {
    // The floor map's rays on every core: the workers wait for the first scene, and a later
    // scene's overlap with their renders is brief.
    const OmpThreads all(jobs_);
    job.sampler = std::make_unique<ViewpointSampler>(*job.scene, *job.caster, cfg_.pair.sampler);
  }
  job.stats = {{"scene", job.name},
               {"triangles", job.scene->mesh.numTriangles()},
               {"load_seconds", loadSeconds},
               {"build_seconds", since(t0)},
               {"bytes", residentBytes() - std::min(before, residentBytes())},
               {"warnings", job.scene->warnings}};
  PairOptions po = cfg_.pair;
  po.keepDepth = cfg_.saveDepth || cfg_.saveFlow;
  job.generator = std::make_unique<PairGenerator>(*job.scene, *job.caster, *job.sampler, po);
}

// The scene has valid views unless its first kViewCheckIndices indices all have no sample. The
// check stops at the first index with one, so a scene whose index 0 has a sample costs what it
// always did; what it generates is kept for the items, so no index is made twice.
void GenerateRun::checkViews(SceneJob& job) {
  const uint64_t n = std::min<uint64_t>(kViewCheckIndices, cfg_.pairsPerScene);
  for (uint64_t k = 0; k < n; ++k)
    if (hasSample(job, k)) return;
  job.checked.clear();  // failures only, of a scene that writes nothing
  job.error = "no valid views (no sample found for " +
              (n == 1 ? "index 0" : "indices 0 to " + std::to_string(n - 1)) + ")";
}

// Whether `index` has a sample: as the journal has it (a resumed run), else generated and kept in
// job.checked for its item.
bool GenerateRun::hasSample(SceneJob& job, uint64_t index) {
  const Journal::Has noted = journal_->has(sampleKey(job.name, index));
  if (noted != Journal::Has::kNo) return noted == Journal::Has::kYes;
  job.checked.resize(index + 1);
  job.checked[index] = generateAt(job, index);
  return job.checked[index]->sample.has_value();
}

void GenerateRun::skipScene(SceneJob& job) {
  std::lock_guard<std::mutex> lock(warnMu_);
  std::fprintf(stderr, "%sgenerate_pairs: warning: skipping scene %s: %s\n",
               cfg_.progress ? "\n" : "", job.path.c_str(), job.error.c_str());
  skipped_.push_back({{"scene", job.path}, {"reason", job.error}});
}

Attempt GenerateRun::generateAt(const SceneJob& job, uint64_t index) const {
  Attempt a;
  a.sample = job.generator->generate(cfg_.seed, index, &a.spent);
  return a;
}

// The attempt the scene's check made at `index`, else a new one (the same: a sample is a pure
// function of seed, scene and index).
Attempt GenerateRun::takeAttempt(SceneJob& job, uint64_t index) const {
  if (index >= job.checked.size() || !job.checked[index]) return generateAt(job, index);
  Attempt a = std::move(*job.checked[index]);
  job.checked[index].reset();
  return a;
}

// The journal's note of an index known to have no sample.
Result GenerateRun::failedResult(const SceneJob& job, const Item& item,
                                 const GenerationCost& spent) {
  stats_.addIndex(spent, false, 0.0, 0.0);
  Result r;
  r.note = {{"failed", true},
            {"scene", job.name},
            {"index", item.index},
            {"candidates", candidateBins(spent.candidateCovis)}};
  return r;
}

// The sample encoded, its CroCo files written, its note, metadata entry and shard entry made.
Result GenerateRun::keptResult(const SceneJob& job, const Item& item, const PairSample& sample,
                               const GenerationCost& spent) {
  auto t0 = Clock::now();
  EncodedPair enc = encodePair(sample, cfg_.saveDepth, cfg_.jpegQuality, cfg_.saveFlow);
  enc.record["candidate_covis"] = sample.candidateCovis;
  enc.record["screened"] = spent.screened;
  enc.record["up"] = job.scene->up == UpAxis::Z ? "z" : "y";  // resolved (--up auto)
  const double encode = since(t0);
  t0 = Clock::now();
  if (item.forCroco) {
    makeDirs((fs::path(cfg_.out) / job.name).string());
    writeCrocoSample(crocoStem(job, item.index), enc, sample.camera);
  }
  stats_.addIndex(spent, true, encode, since(t0));
  Result r;
  r.note = {{"scene", job.name},
            {"index", item.index},
            {"candidates", candidateBins(sample.candidateCovis)},
            {"up", enc.record["up"]}};
  if (enc.record.contains("covis")) r.note["covis"] = enc.record["covis"];
  if (item.forCroco) r.entry = multiviewEntry(enc.record, sampleKey(job.name, item.index));
  if (item.forShard) r.pair = std::move(enc);
  return r;
}

// Takes results in item order: journal first, then the shard, so that every sample of a
// completed shard is in the journal.
void GenerateRun::writeInOrder() {
  ProgressLine progress(cfg_.progress);
  const auto started = Clock::now();
  auto show = [&](size_t done, bool last) {
    if (last || progress.due())
      progress.show(
          progressText(done, items_.size(), stats_.accepted(), stats_.candidates(), since(started)),
          last);
  };
  for (size_t i = 0; i < items_.size(); ++i) {
    Result r;
    {
      std::unique_lock<std::mutex> lock(mu_);
      produced_.wait(lock, [&] { return stop_ || results_[i].done; });
      if (stop_ && !results_[i].done) return;
      r = std::move(results_[i]);
      results_[i] = Result{};
      nextToWrite_ = i + 1;
      consumed_.notify_all();
    }
    const auto t0 = Clock::now();
    writeResult(items_[i], r);
    stats_.addWrite(since(t0));
    show(i + 1, false);
  }
  if (shard_ && !stop_) closeShard();
  show(items_.size(), true);
}

// The sample's metadata entry, then its journal note, then its shard entry.
void GenerateRun::writeResult(const Item& item, const Result& r) {
  if (!r.entry.is_null()) {
    if (!entries_ || entriesScene_ != item.scene) {
      if (entries_) entries_->sync();
      entries_ = openEntries(*scenes_[item.scene]);
      entriesScene_ = item.scene;
    }
    entries_->append({{"scene", scenes_[item.scene]->name},
                      {"index", item.index},
                      {"entry", r.entry.dump()}});  // as text: a quick line to index
  }
  if (!r.note.is_null()) journal_->append(r.note);
  if (r.pair) addToShard(*r.pair);
}

void GenerateRun::addToShard(const EncodedPair& pair) {
  if (!shard_)
    shard_ = std::make_unique<ShardWriter>(
        (fs::path(cfg_.out) / shardName(part_, shardList_.size())).string());
  shard_->add(pair);
  if (static_cast<int>(shard_->samples()) >= cfg_.shardSize ||
      shard_->bytes() >= cfg_.shardMaxBytes)
    closeShard();
}

void GenerateRun::closeShard() {
  if (entries_) entries_->sync();
  journal_->sync();
  shard_->close();
  shardList_.push_back({{"pairs", shard_->samples()}});
  shard_.reset();
}

nlohmann::json GenerateRun::summarise() {
  journal_->reopen();
  std::string pairsTxt;
  nlohmann::json perScene = nlohmann::json::object();
  std::set<std::string> skippedPaths;
  for (const auto& s : skipped_) skippedPaths.insert(s["scene"].get<std::string>());
  for (const auto& job : scenes_)
    if (!skippedPaths.count(job->path)) summariseScene(*job, perScene, pairsTxt);
  if (cfg_.croco) writeFileAtomic(outPath("pairs", ".txt"), pairsTxt);
  if (cfg_.shards) writeShardIndex(perScene);
  writeCredits(skippedPaths);
  const nlohmann::json summary = summaryJson(since(start_));
  writeFileAtomic(outPath("summary", ".json"), summary.dump(1) + "\n");
  return summary;
}

// credits.json: the credits.json found beside each scene used (make_scenes --furnish writes
// them), by scene name, so that data rendered from CC-BY models carries its attributions. None
// when no scene has credits. A credits file that cannot be read is a warning, and its entry
// says why.
void GenerateRun::writeCredits(const std::set<std::string>& skippedPaths) {
  nlohmann::json scenes = nlohmann::json::object();
  for (const auto& job : scenes_) {
    const fs::path file = fs::path(job->path).parent_path() / "credits.json";
    std::error_code ec;
    if (skippedPaths.count(job->path) || !fs::is_regular_file(file, ec)) continue;
    try {
      scenes[job->name] = nlohmann::json::parse(readFile(file.string()));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "generate_pairs: warning: %s: unreadable credits: %s\n",
                   file.string().c_str(), e.what());
      scenes[job->name] = {{"unreadable", file.string()}};
    }
  }
  if (scenes.empty()) return;
  writeFileAtomic(outPath("credits", ".json"), nlohmann::json{{"scenes", scenes}}.dump(1) + "\n");
}

// index.json: the shards, and what every pair in them has in common.
void GenerateRun::writeShardIndex(const nlohmann::json& perScene) {
  for (size_t s = 0; s < shardList_.size(); ++s) shardList_[s]["name"] = shardName(part_, s);
  const nlohmann::json index = {{"format", "paircast-shards"},
                                {"format_version", kShardVersion},
                                {"pairs", pairs_},
                                {"views", cfg_.pair.views},
                                {"shards", shardList_},
                                {"pairs_per_scene", perScene},
                                {"covis_histogram", histogram_},
                                {"depth", cfg_.saveDepth},
                                {"flow", cfg_.saveFlow},
                                {"covis_masks", cfg_.pair.covisMasks},
                                {"resolution", cfg_.pair.resolution},
                                {"hfov", cfg_.pair.hfov},
                                {"motion", motionJson(cfg_.pair.sampler)},
                                {"seed", cfg_.seed}};
  writeFileAtomic(outPath("index", ".json"), index.dump(1) + "\n");
}

// Adds a journal note's candidates to the candidate histogram (their covis, in a journal that
// an older generate_pairs wrote).
void GenerateRun::tallyCandidates(const nlohmann::json& note) {
  for (const auto& c : note.value("candidate_covis", nlohmann::json::array())) {
    histogramAdd(candidateHistogram_, c.get<double>());
    ++tried_;
  }
  const auto bins = note.find("candidates");
  if (bins == note.end() || !bins->is_string()) return;
  for (const char b : bins->get_ref<const std::string&>()) {
    candidateHistogram_[std::clamp(b - 'A', 0, kHistogramBins - 1)]++;
    ++tried_;
  }
}

// The metadata entries of a scene's CroCo samples by index, read once in order (the last line of
// an index wins). Planning opened the file as a journal, which cut a torn last line.
std::map<uint64_t, nlohmann::json> GenerateRun::readEntries(const SceneJob& job) const {
  std::map<uint64_t, nlohmann::json> entries;
  std::ifstream in(entriesPath(job));
  for (std::string line; std::getline(in, line);) {
    nlohmann::json r = nlohmann::json::parse(line, nullptr, false);
    if (!r.is_object() || !r.contains("entry") || !r["entry"].is_string() || !r.contains("index") ||
        !r["index"].is_number_unsigned())
      continue;
    entries[r["index"].get<uint64_t>()] =
        nlohmann::json::parse(r["entry"].get_ref<const std::string&>(), nullptr, false);
  }
  return entries;
}

// Tallies one scene's records, and writes its metadata.json and pairs.txt lines (CroCo layout).
void GenerateRun::summariseScene(const SceneJob& job, nlohmann::json& perScene,
                                 std::string& pairsTxt) {
  nlohmann::json multiviews = nlohmann::json::object();
  uint64_t scenePairs = 0;
  std::string up = cfg_.load.up == UpAxis::Z ? "z" : "y";
  std::map<uint64_t, nlohmann::json> entries;
  if (cfg_.croco) entries = readEntries(job);
  for (uint64_t k = 0; k < static_cast<uint64_t>(cfg_.pairsPerScene); ++k) {
    const std::string key = sampleKey(job.name, k);
    const nlohmann::json rec = journal_->find(key);
    if (!rec.is_object()) continue;
    tallyCandidates(rec);
    if (rec.value("failed", false)) continue;
    ++pairs_;
    ++scenePairs;
    if (rec.contains("covis")) histogramAdd(histogram_, rec["covis"].get<double>());
    up = rec.value("up", up);
    if (!cfg_.croco) continue;
    const auto entry = entries.find(k);
    if (entry == entries.end()) throw Error(entriesPath(job), "no metadata entry for " + key);
    multiviews[crocoIndex(k)] = std::move(entry->second);
    pairsTxt += crocoPairLines(job.name, crocoIndex(k), cfg_.pair.views);
  }
  perScene[job.name] = scenePairs;
  if (cfg_.croco) writeSceneMetadata(job, up, std::move(multiviews));
}

// The scene's metadata.json (CroCo layout): the job's settings and its samples' entries.
void GenerateRun::writeSceneMetadata(const SceneJob& job, const std::string& up,
                                     nlohmann::json multiviews) const {
  const nlohmann::json meta = {{"scene", job.path},
                               {"views_count", cfg_.pair.views},
                               {"size", cfg_.pairsPerScene},
                               {"generate_depth", cfg_.saveDepth},
                               {"generate_flow", cfg_.saveFlow},
                               {"resolution", cfg_.pair.resolution},
                               {"hfov", cfg_.pair.hfov},
                               {"minimum_covisibility", cfg_.pair.minCovis},
                               {"maximum_covisibility", cfg_.pair.maxCovis},
                               {"motion", motionJson(cfg_.pair.sampler)},
                               {"seed", cfg_.seed},
                               {"generator", "paircast"},
                               {"up", up},
                               {"multiviews", multiviews}};
  makeDirs((fs::path(cfg_.out) / job.name).string());
  writeFileAtomic((fs::path(cfg_.out) / job.name / "metadata.json").string(), meta.dump() + "\n");
}

// summary.json: this run's statistics, and what the journal says of the whole job.
nlohmann::json GenerateRun::summaryJson(double seconds) const {
  nlohmann::json sceneStats = nlohmann::json::array();
  for (const auto& job : scenes_)
    if (!job->stats.is_null()) sceneStats.push_back(job->stats);
  nlohmann::json summary = stats_.toJson(seconds);
  summary["screening"]["resolution"] = screenResolution(cfg_.pair);
  summary["screening"]["audited"] = cfg_.pair.auditScreening;
  summary.update({{"pairs", pairs_},
                  {"views", cfg_.pair.views},
                  {"candidates", tried_},
                  {"acceptance", tried_ ? static_cast<double>(pairs_) / tried_ : 0.0},
                  {"seconds", seconds},
                  {"covis_histogram", histogram_},
                  {"candidate_covis_histogram", candidateHistogram_},
                  {"skipped_scenes", skipped_},
                  {"scene_stats", sceneStats},
                  {"scenes_in_memory_max", scenesPeak_.load()},
                  {"jobs", jobs_}});
  return summary;
}

}  // namespace

nlohmann::json runGenerate(const GenerateConfig& config) {
  GenerateRun run(config);
  run.run();
  return run.summarise();
}

void GenerateConfig::validate() const {
  if (out.empty()) throw OptionError("out", "an output folder is required");
  if (pairsPerScene < 1) throw OptionError("pairs_per_scene", "pairs per scene must be at least 1");
  if (numShards < 1 || shardIndex < 0 || shardIndex >= numShards)
    throw OptionError("shard_index", "the part index must be in [0, number of parts), got " +
                                         std::to_string(shardIndex) + " of " +
                                         std::to_string(numShards));
  if (!shards && !croco) throw OptionError("format", "choose shards, the CroCo layout, or both");
  if (shardSize < 1) throw OptionError("shard_size", "pairs per shard must be at least 1");
  if (jpegQuality < 1 || jpegQuality > 100)
    throw OptionError("jpeg_quality", "JPEG quality must be in 1..100");
  pair.validate();
}

}  // namespace paircast
