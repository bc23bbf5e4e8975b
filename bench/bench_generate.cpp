// bench_generate: for each scene, side by side in one run on the same threads:
//   - the render limit: 1 / (two RGB+depth renders at the output resolution), with --jobs workers
//     rendering views of that scene on one core each, as generate_pairs' workers do;
//   - generate_pairs' accepted pairs/s with screening (the default; --runs runs of indices enough
//     for --pairs pairs, as a pilot run finds the scene's yield, each judged against the limit
//     measured just before and after it, and the median counts) and without,
//     the efficiency
//     (pairs/s / limit), the stage table (screening, the full renders kept and those wasted on
//     views that end in no sample, JPEG, covis, poses, writing) with the count of full renders
//     per pair, and the scene's load and build figures;
//   - the false-rejection rate of screening (an audited run: screened-out candidates are also
//     rendered at full resolution, and those that would have been kept are counted);
//   - depth-only against RGB+depth render time.
// Then the co-visibility cost per pair on one core against CroCo's kd-tree method
// (../shared/tools/ref_covis.py), on the same depth maps, with their agreement.
#include <unistd.h>

#include <omp.h>
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include <algorithm>
#include <atomic>
#include <optional>
#include <thread>

#include "covis/covisibility.h"
#include "dataset/generate_job.h"
#include "dataset/pair_generator.h"
#include "dataset/shard.h"
#include "dataset/viewpoint_sampler.h"
#include "render/obj_writer.h"
#include "render/procedural_scene.h"
#include "render/ray_caster.h"
#include "render/scan_scene.h"
#include "tools/pair_flags.h"
#include "util/atomic_file.h"
#include "util/image_io.h"

using namespace paircast;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct SceneArg {
  std::string path;
  UpAxis up;
};

std::string sharedDir() {
  return (fs::path(PAIRCAST_SOURCE_DIR).parent_path() / "shared").string();
}

// Parses "SUMMARY ref_covis official: v12=.. v21=.. covis=.. ms=.. | reproj: ..." into numbers.
nlohmann::json runRefCovis(const std::string& stem) {
  const std::string tool = sharedDir() + "/tools/ref_covis.py";
  const std::string cmd = "/usr/bin/python3 " + tool + " --depth1 " + stem +
                          "_1_depth.exr --cam1 " + stem + "_1_camera_params.json --depth2 " + stem +
                          "_2_depth.exr --cam2 " + stem +
                          "_2_camera_params.json 2>&1 | grep '^SUMMARY' | tail -1";
  std::string line;
  if (FILE* p = popen(cmd.c_str(), "r")) {
    char buf[2048];
    while (fgets(buf, sizeof buf, p)) line += buf;
    pclose(p);
  }
  nlohmann::json out;
  const size_t bar = line.find('|');
  if (bar == std::string::npos) return out;
  auto parse = [](const std::string& part) {
    nlohmann::json j;
    std::istringstream is(part);
    std::string tok;
    while (is >> tok) {
      const size_t eq = tok.find('=');
      if (eq != std::string::npos) j[tok.substr(0, eq)] = std::stod(tok.substr(eq + 1));
    }
    return j;
  };
  out["official"] = parse(line.substr(0, bar));
  out["reproj"] = parse(line.substr(bar + 1));
  return out;
}

// Seconds per render of `views` random views, `threads` workers each rendering its own views on
// one core (omp off), as generate_pairs' workers do: one round.
double secondsPerRender(const RayCaster& caster, const std::vector<Camera>& views, unsigned threads,
                        bool rgb) {
  std::atomic<size_t> next{0};
  const auto t0 = Clock::now();
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < threads; ++t)
    pool.emplace_back([&] {
      omp_set_num_threads(1);
      Frame frame;
      ImageF depth;
      RenderOptions ro;  // what generate_pairs renders: colour and depth
      ro.normals = false;
      ro.ids = false;
      for (size_t i; (i = next++) < views.size();) {
        if (rgb)
          caster.render(views[i], ro, frame);
        else
          caster.renderDepth(views[i], depth);
      }
    });
  for (auto& t : pool) t.join();
  return std::chrono::duration<double>(Clock::now() - t0).count() / views.size();
}

struct RenderLimit {
  double rgbDepthSeconds = 0, depthSeconds = 0, screenDepthSeconds = 0;
  double pairsPerSecond() const { return 1.0 / (2.0 * rgbDepthSeconds); }
};

// The scene, its BVH and views as the sampler places them (reference views), at `resolution`
// and hfov 60, loaded once and measured as often as asked.
class RenderProbe {
 public:
  RenderProbe(const SceneArg& arg, int resolution)
      : scene_(load(arg)), caster_(scene_.mesh), sampler_(scene_, caster_, {}) {
    Rng rng(7);
    const Camera K = Camera::fromHfov(resolution, resolution, 60);
    // Views as generate_pairs renders them in full: those with enough valid pixels (on an open
    // floor most random views are sky, which renders for nothing). A scene without any is one
    // generate_pairs skips; it is measured on random views.
    const double minValid = PairOptions{}.minValidFraction;
    ImageF depth;
    for (int tries = 0; views_.size() < 64 && tries < 64 * 100; ++tries) {
      const Camera view = sampler_.sampleView(K, rng);
      caster_.renderDepth(view, depth);
      if (validFraction(depth) >= minValid) add(view, resolution);
    }
    while (views_.size() < 64) add(sampler_.sampleView(K, rng), resolution);
  }
  // The mean of 7 rounds, each of the three renders in turn, so that a change of machine load
  // touches all three alike: the sustained rate over about a second, as a generation run
  // sustains its own. (The best round is 5-12 % faster on these machines, a spell no run of
  // seconds keeps.)
  RenderLimit measure(unsigned threads) const {
    constexpr int kRounds = 7;
    RenderLimit r;
    for (int round = 0; round < kRounds; ++round) {
      r.rgbDepthSeconds += secondsPerRender(caster_, views_, threads, true) / kRounds;
      r.depthSeconds += secondsPerRender(caster_, views_, threads, false) / kRounds;
      r.screenDepthSeconds += secondsPerRender(caster_, smallViews_, threads, false) / kRounds;
    }
    return r;
  }

 private:
  // A view at the output resolution, and the same at a quarter of it.
  void add(const Camera& view, int resolution) {
    views_.push_back(view);
    Camera small = Camera::fromHfov(resolution / 4, resolution / 4, 60);
    small.R_cam2world = view.R_cam2world;
    small.t_cam2world = view.t_cam2world;
    smallViews_.push_back(small);
  }
  static Scene load(const SceneArg& arg) {
    LoadOptions lo;
    lo.up = arg.up;
    return loadScene(arg.path, lo);
  }
  Scene scene_;
  RayCaster caster_;
  ViewpointSampler sampler_;
  std::vector<Camera> views_, smallViews_;
};

// A screened generation run and the limit it is judged against.
struct FramedRun {
  nlohmann::json summary;
  RenderLimit limit;
  double efficiency() const {
    return summary["pairs_per_second"].get<double>() / limit.pairsPerSecond();
  }
};

// The faster of two measurements, render by render.
RenderLimit best(const RenderLimit& a, const RenderLimit& b) {
  return {std::min(a.rgbDepthSeconds, b.rgbDepthSeconds), std::min(a.depthSeconds, b.depthSeconds),
          std::min(a.screenDepthSeconds, b.screenDepthSeconds)};
}

// The funnel of summary.json as one line: "name entered>turned down (false rejections) ms/pair".
std::string funnelText(const nlohmann::json& funnel, const std::vector<std::string>& names,
                       double pairs) {
  std::string text;
  for (size_t k = 0; k < funnel.size(); ++k) {
    const auto& f = funnel[k];
    if (f["entered"].get<size_t>() == 0) continue;
    char part[160];
    std::snprintf(part, sizeof part, "%s%s %zu>%zu (%zu) %.3f ms", text.empty() ? "" : " | ",
                  k < names.size() ? names[k].c_str() : "stage", f["entered"].get<size_t>(),
                  f["turned_down"].get<size_t>(), f["false_rejections"].get<size_t>(),
                  1e3 * f["seconds"].get<double>() / std::max(pairs, 1.0));
    text += part;
  }
  return text;
}

// The scenes the default run adds to scenes/ and ../shared: a building of `rooms` rooms and, when
// asked, a scan of `scanTriangles` triangles, written under `dir`.
std::vector<SceneArg> generatedScenes(const std::string& dir, int rooms, size_t scanTriangles) {
  std::vector<SceneArg> out;
  if (rooms > 0) {
    const LayoutSpec layout =
        randomLayout("building_" + std::to_string(rooms) + "_rooms", 7 * 100003 + 1, rooms);
    const std::string path = dir + "/" + layout.name + "/" + layout.name + ".obj";
    writeObj(path, buildLayout(layout));
    out.push_back({path, UpAxis::Y});
  }
  if (scanTriangles > 0) {
    ScanSpec spec;  // make_scenes --scan scannet's
    spec.seed = 0;
    spec.triangles = scanTriangles;
    out.push_back({writeScan(spec, dir), UpAxis::Z});
  }
  return out;
}

// The unscreened run's pair options: the defaults, with screening off.
PairOptions unscreened() {
  PairOptions o;
  o.screenResolution = 0;
  return o;
}

nlohmann::json generate(const SceneArg& arg, const std::string& out, int pairs, unsigned threads,
                        const PairOptions& pair, bool audit) {
  GenerateConfig c;
  c.scenes = {arg.path};
  c.load.up = arg.up;
  c.out = out;
  c.pairsPerScene = pairs;
  c.jobs = static_cast<int>(threads);
  c.progress = false;
  c.pair = pair;
  c.pair.auditScreening = audit;
  return runGenerate(c);
}

// Indices enough for about `pairs` pairs, from the share of a pilot run's indices (a fifth as
// many, screened, not timed) that found one: most scenes find one at every index, simple_room at
// 37 %, and there 1000 indices would make 370 pairs, over which the scene's load and checks, paid
// once a run, weigh three times what they do in a run of 1000 pairs. At most 10 times `pairs`.
int indicesFor(const SceneArg& arg, const std::string& out, int pairs, unsigned threads,
               const PairOptions& pair) {
  const int pilot = std::max(100, pairs / 5);
  const nlohmann::json one = generate(arg, out, pilot, threads, pair, false);
  fs::remove_all(out);
  const double yield = one["pairs_this_run"].get<double>() / pilot;
  if (!(yield > 0)) return pairs;  // skipped: the runs say why
  return static_cast<int>(std::min(10.0 * pairs, std::ceil(pairs / std::min(1.0, yield))));
}

// The run's figures as the Markdown tables of docs/benchmarks.md: rates, then the stage table.
void printStageTable(const nlohmann::json& results) {
  std::printf(
      "\n| scene | triangles | pairs/s | limit | efficiency | unscreened | screened / unscreened "
      "| false rejections | full renders / pair |\n| --- | --- | --- | --- | --- | --- | --- | "
      "--- | --- |\n");
  for (const auto& r : results)
    std::printf("| %s | %zu | %.1f | %.1f | **%.2f** | %.1f | %.2fx | %.4f | %.2f |\n",
                r["scene"].get<std::string>().c_str(), r["scene_stats"]["triangles"].get<size_t>(),
                r["pairs_per_second"].get<double>(), r["limit_pairs_per_second"].get<double>(),
                r["efficiency"].get<double>(), r["unscreened_pairs_per_second"].get<double>(),
                r["screening_speedup"].get<double>(), r["false_rejection_rate"].get<double>(),
                r["renders"]["per_pair"].get<double>());
  std::printf(
      "\n| scene | screening | full renders kept | full renders wasted | JPEG | covis | poses | "
      "writing |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const auto& r : results) {
    const auto& t = r["time_split"];
    std::printf("| %s | %.1f %% | %.1f %% | %.1f %% | %.1f %% | %.1f %% | %.1f %% | %.1f %% |\n",
                r["scene"].get<std::string>().c_str(), 100 * t["screen"].get<double>(),
                100 * t["render_kept"].get<double>(), 100 * t["render_wasted"].get<double>(),
                100 * t["encode"].get<double>(), 100 * t["covis"].get<double>(),
                100 * t["sampling"].get<double>(), 100 * t["write"].get<double>());
  }
  std::fflush(stdout);
}

// What a run of the benchmark measures, as its command line sets it.
struct BenchOptions {
  std::vector<std::string> scenes;
  std::string up = "y";
  // A real run makes thousands of pairs a scene: 1000 keep the scene's load and BVH build, which
  // every run pays once a scene, to a few percent of the run, as there.
  int pairs = 1000, plainPairs = 200, auditPairs = 200, jobs = 0, refPairs = 5, runs = 3;
  int buildingRooms = 8;
  size_t scanTriangles = ScanSpec{}.triangles;
  PairOptions pair;  // the screened runs' (the defaults, screening as the flags set it)
};

void addBenchFlags(CLI::App& app, BenchOptions& o) {
  app.add_option("--scenes", o.scenes, "Scenes (default: scenes/ and ../shared/scenes)");
  app.add_option("--up", o.up, "Up axis of --scenes: y, z or auto")
      ->check(CLI::IsMember({"y", "z", "auto"}));
  app.add_option("--pairs", o.pairs, "Accepted pairs per scene");
  app.add_option("--plain-pairs", o.plainPairs,
                 "Pairs of the unscreened run (its rate is several times lower)");
  app.add_option("--jobs", o.jobs, "Worker threads (default: all cores)");
  app.add_option("--ref-pairs", o.refPairs, "Pairs compared with ref_covis.py");
  app.add_option(
         "--runs", o.runs,
         "Screened generation runs per scene, each framed by limit measurements; the median counts")
      ->check(CLI::Range(1, 100));
  app.add_option("--audit-pairs", o.auditPairs,
                 "Pairs of the audited run for the false-rejection rate");
  addScreenFlags(app, o.pair);
  app.add_option("--building-rooms", o.buildingRooms,
                 "Default run: also a make_scenes floor plan of this many rooms (0: none)")
      ->check(CLI::Range(0, kMaxLayoutRooms));
  app.add_option("--scan-triangles", o.scanTriangles,
                 "Default run: also a ScanNet-style scan of this many triangles (0: none)");
}

// The scenes to measure: --scenes, else scenes/, ../shared's two and the generated ones.
std::vector<SceneArg> benchScenes(const BenchOptions& o, const std::string& tmp) {
  std::vector<SceneArg> scenes;
  if (!o.scenes.empty()) {
    for (const auto& p : expandSceneList(o.scenes)) scenes.push_back({p, parseUpAxis(o.up)});
    return scenes;
  }
  for (const auto& p : expandSceneList({std::string(PAIRCAST_SOURCE_DIR) + "/scenes"}))
    scenes.push_back({p, UpAxis::Y});
  if (fs::exists(sharedDir() + "/scenes/simple_room.glb"))
    scenes.push_back({sharedDir() + "/scenes/simple_room.glb", UpAxis::Z});
  if (fs::exists(sharedDir() + "/scenes/stage_floor1.glb"))
    scenes.push_back({sharedDir() + "/scenes/stage_floor1.glb", UpAxis::Y});
  for (const SceneArg& made : generatedScenes(tmp + "/scenes", o.buildingRooms, o.scanTriangles))
    scenes.push_back(made);
  return scenes;
}

// A scene's generation runs: the screened run of median efficiency with its limit, the
// unscreened run and the audited one.
struct SceneRuns {
  int indices = 0;
  FramedRun median;
  nlohmann::json plain, audit;
};

// Runs the scene's generation runs in folders named after `out`; nullopt (with a line saying why)
// when the scene is skipped.
std::optional<SceneRuns> runScene(const SceneArg& scene, const std::string& name,
                                  const std::string& out, unsigned threads, const BenchOptions& o) {
  // Each screened run is framed by measurements of the limit and judged against the faster
  // of the two: the machine's speed drifts by tens of percent over seconds, and a run and
  // its frame see the same spell. The run of median efficiency counts.
  const RenderProbe probe(scene, 256);
  SceneRuns r;
  r.indices = indicesFor(scene, out + "-pilot", o.pairs, threads, o.pair);
  std::vector<FramedRun> framed;
  RenderLimit edge = probe.measure(threads);
  for (int run = 0; run < o.runs; ++run) {
    fs::remove_all(out);
    nlohmann::json one = generate(scene, out, r.indices, threads, o.pair, false);
    const bool skipped = !one["skipped_scenes"].empty();
    const RenderLimit next = probe.measure(threads);
    framed.push_back({std::move(one), best(edge, next)});
    edge = next;
    if (skipped) break;  // a scene without valid views is skipped every time
  }
  std::sort(framed.begin(), framed.end(),
            [](const FramedRun& a, const FramedRun& b) { return a.efficiency() < b.efficiency(); });
  r.median = framed[framed.size() / 2];
  if (!r.median.summary["skipped_scenes"].empty()) {
    std::printf("%-22s skipped: %s\n", name.c_str(),
                r.median.summary["skipped_scenes"][0]["reason"].get<std::string>().c_str());
    return std::nullopt;
  }
  r.plain = generate(scene, out + "-plain", o.plainPairs, threads, unscreened(), false);
  r.audit = generate(scene, out + "-audit", o.auditPairs, threads, o.pair, true);
  return r;
}

// Prints a scene's figures and returns them as its entry of the results.
nlohmann::json sceneResult(const std::string& name, const SceneRuns& runs, unsigned threads,
                           const ScreenPlan& plan) {
  const nlohmann::json& sum = runs.median.summary;
  const RenderLimit& limit = runs.median.limit;
  const nlohmann::json& audit = runs.audit;
  const double rate = sum["pairs_per_second"].get<double>();
  const double plainRate = runs.plain["pairs_per_second"].get<double>();
  const auto& screening = audit["screening"];
  const double falseRate =
      screening["screened"].get<double>() > 0
          ? screening["false_rejections"].get<double>() / screening["screened"].get<double>()
          : 0.0;
  const auto& stats = sum["scene_stats"][0];
  const auto& split = sum["time_split"];
  // The run's kept renders against the limit's: above 1 when the machine ran slower during
  // the run than in the faster of its frames, or the renders there paid for what else ran.
  const double keptMs = 1e3 * sum["time_seconds"]["render_kept"].get<double>() /
                        std::max(1.0, sum["renders"]["kept"].get<double>());
  const double limitMs = 1e3 * limit.rgbDepthSeconds * threads;
  std::printf(
      "%-22s %9zu tris  load %.2f s  build %.2f s  %.0f MB  %d indices\n"
      "    %7.1f pairs/s  limit %6.1f pairs/s  efficiency %.2f  unscreened %6.1f pairs/s "
      "(x%.2f)  acceptance %4.1f%%\n"
      "    screening turned down %.0f views, references and candidates (%.0f candidates "
      "tried; %.0f indices without a sample), false rejections %.4f (%.0f of %.0f)\n    "
      "RGB+depth / depth-only render %.2fx (%.2f / %.2f ms; depth at 1/4 size %.3f ms)\n"
      "    stages: screening %4.1f%%  full renders kept %4.1f%%  full renders wasted %4.1f%%  "
      "JPEG %4.1f%%  covis %4.1f%%  poses %4.1f%%  writing %4.1f%%\n"
      "    full renders: %.0f, %.0f kept, %.2f per pair; wasted: %.0f references, %.0f "
      "candidates\n",
      name.c_str(), stats["triangles"].get<size_t>(), stats["load_seconds"].get<double>(),
      stats["build_seconds"].get<double>(), stats["bytes"].get<double>() / 1e6, runs.indices, rate,
      limit.pairsPerSecond(), rate / limit.pairsPerSecond(), plainRate, rate / plainRate,
      100 * sum["acceptance"].get<double>(), screening["screened"].get<double>(),
      screening["candidates_this_run"].get<double>(), sum["failed_pairs"].get<double>(), falseRate,
      screening["false_rejections"].get<double>(), screening["screened"].get<double>(),
      limit.rgbDepthSeconds / limit.depthSeconds, 1e3 * limit.rgbDepthSeconds,
      1e3 * limit.depthSeconds, 1e3 * limit.screenDepthSeconds, 100 * split["screen"].get<double>(),
      100 * split["render_kept"].get<double>(), 100 * split["render_wasted"].get<double>(),
      100 * split["encode"].get<double>(), 100 * split["covis"].get<double>(),
      100 * split["sampling"].get<double>(), 100 * split["write"].get<double>(),
      sum["renders"]["full"].get<double>(), sum["renders"]["kept"].get<double>(),
      sum["renders"]["per_pair"].get<double>(), sum["renders"]["wasted_references"].get<double>(),
      sum["renders"]["wasted_candidates"].get<double>());
  std::printf("    a kept render took %.2f ms of a core in the run, %.2f in the limit (%.2fx)\n",
              keptMs, limitMs, keptMs / limitMs);
  // The audited run's funnel: what each stage turned down, wrongly, and its worker time per
  // pair.
  const double auditPairsMade = audit["pairs_this_run"].get<double>();
  std::printf(
      "    audited funnel, candidates: %s\n    audited funnel, references: %s\n",
      funnelText(screening["candidate_funnel"], plan.candidateNames(), auditPairsMade).c_str(),
      funnelText(screening["reference_funnel"], plan.referenceNames(), auditPairsMade).c_str());
  const auto& fast = sum["screening"];
  std::printf("    funnel, candidates: %s\n    funnel, references: %s\n",
              funnelText(fast["candidate_funnel"], plan.candidateNames(),
                         sum["pairs_this_run"].get<double>())
                  .c_str(),
              funnelText(fast["reference_funnel"], plan.referenceNames(),
                         sum["pairs_this_run"].get<double>())
                  .c_str());
  std::fflush(stdout);
  return {{"scene", name},
          {"indices", runs.indices},
          {"pairs", sum["pairs_this_run"]},
          {"pairs_per_second", rate},
          {"limit_pairs_per_second", limit.pairsPerSecond()},
          {"efficiency", rate / limit.pairsPerSecond()},
          {"kept_render_over_limit", keptMs / limitMs},
          {"unscreened_pairs_per_second", plainRate},
          {"screening_speedup", rate / plainRate},
          {"false_rejection_rate", falseRate},
          {"rgb_depth_over_depth", limit.rgbDepthSeconds / limit.depthSeconds},
          {"acceptance", sum["acceptance"]},
          {"scene_stats", stats},
          {"time_split", split},
          {"renders", sum["renders"]},
          {"funnel", sum["screening"]},
          {"audited_funnel", screening}};
}

// A few pairs of the scene with depth, in CroCo's layout under `out`, for the co-visibility
// comparison: the stems of those written.
std::vector<std::string> depthPairStems(const SceneArg& scene, const std::string& out,
                                        unsigned threads, int refPairs) {
  GenerateConfig c;
  c.scenes = {scene.path};
  c.load.up = scene.up;
  c.jobs = static_cast<int>(threads);
  c.progress = false;
  c.out = out;
  c.pairsPerScene = refPairs;
  c.shards = false;
  c.croco = true;
  c.saveDepth = true;
  runGenerate(c);
  std::vector<std::string> stems;
  for (int k = 0; k < refPairs; ++k) {
    char idx[16];
    std::snprintf(idx, sizeof idx, "%08d", k);
    const std::string stem =
        c.out + "/" + sanitizeName(fs::path(scene.path).stem().string()) + "/" + idx;
    if (fs::exists(stem + "_1_depth.exr")) stems.push_back(stem);
  }
  return stems;
}

// Co-visibility on one core, ours (best of several passes over the same pairs) against
// ref_covis.py's kd-tree where it runs, with their agreement: covis_ms_per_pair (0 without
// pairs), and covis_ms_kdtree, covis_speedup and covis_max_diff_reproj when compared.
nlohmann::json compareCovis(const std::vector<std::string>& depthStems) {
  nlohmann::json out = {{"covis_ms_per_pair", 0.0}};
  if (depthStems.empty()) return out;
  struct Pair {
    Camera c1, c2;
    ImageF d1, d2;
  };
  std::vector<Pair> loaded;
  for (const auto& stem : depthStems)
    loaded.push_back({readCameraJson(stem + "_1_camera_params.json"),
                      readCameraJson(stem + "_2_camera_params.json"),
                      readImageF(stem + "_1_depth.exr"), readImageF(stem + "_2_depth.exr")});
  double best = 1e30;
  for (int round = 0; round < 5; ++round) {
    const auto t0 = Clock::now();
    double sink = 0;
    for (int rep = 0; rep < 20; ++rep)
      for (const auto& p : loaded) sink += computeCovisibility(p.c1, p.d1, p.c2, p.d2).covis;
    const double ms =
        std::chrono::duration<double, std::milli>(Clock::now() - t0).count() / (20 * loaded.size());
    if (sink >= 0) best = std::min(best, ms);
  }
  const double oursMs = best;
  out["covis_ms_per_pair"] = oursMs;
  std::printf("covis (ours, reprojection, 1 core): %.3f ms per 256x256 pair\n", oursMs);
  const bool haveRef = fs::exists(sharedDir() + "/tools/ref_covis.py") &&
                       std::system("/usr/bin/python3 -c 'import sklearn, numpy' 2>/dev/null") == 0;
  double worstDiff = 0, officialMs = 0;
  int compared = 0;
  if (haveRef) {
    for (size_t k = 0; k < loaded.size(); ++k) {
      const nlohmann::json ref = runRefCovis(depthStems[k]);
      if (!ref.contains("reproj")) continue;
      const CovisResult r =
          computeCovisibility(loaded[k].c1, loaded[k].d1, loaded[k].c2, loaded[k].d2);
      worstDiff = std::max(worstDiff, std::abs(r.covis - ref["reproj"]["covis"].get<double>()));
      officialMs += ref["official"]["ms"].get<double>();
      ++compared;
    }
  }
  if (!compared) {
    std::printf("ref_covis.py comparison skipped (needs ../shared/tools and python3-sklearn)\n");
    return out;
  }
  officialMs /= compared;
  std::printf("covis (CroCo kd-tree, ref_covis.py): %.1f ms per pair: ours is %.0fx faster\n",
              officialMs, officialMs / oursMs);
  std::printf(
      "agreement with ref_covis.py reprojection over %d pairs: max |covis difference| %.4f\n",
      compared, worstDiff);
  out["covis_ms_kdtree"] = officialMs;
  out["covis_speedup"] = officialMs / oursMs;
  out["covis_max_diff_reproj"] = worstDiff;
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  BenchOptions o;
  CLI::App app{"Pair generation speed and co-visibility cost"};
  addBenchFlags(app, o);
  CLI11_PARSE(app, argc, argv);
  try {
    const std::string tmp =
        (fs::temp_directory_path() / ("bench_generate_" + std::to_string(::getpid()))).string();
    const std::vector<SceneArg> scenes = benchScenes(o, tmp);
    const unsigned threads =
        o.jobs > 0 ? o.jobs : std::max(1u, std::thread::hardware_concurrency());
    std::printf(
        "threads: %u, %d pairs per scene (unscreened %d, audited %d), 256x256, hfov 60, covis "
        ">= 0.5\n",
        threads, o.pairs, o.plainPairs, o.auditPairs);
    const ScreenPlan plan = screenPlan(o.pair);  // the funnels' slot names
    nlohmann::json results = nlohmann::json::array();
    std::vector<std::string> depthStems;
    for (size_t s = 0; s < scenes.size(); ++s) {
      const std::string name = fs::path(scenes[s].path).filename().string();
      const std::optional<SceneRuns> runs =
          runScene(scenes[s], name, tmp + "/gen" + std::to_string(s), threads, o);
      if (!runs) continue;
      results.push_back(sceneResult(name, *runs, threads, plan));
      if (o.refPairs < 1) continue;
      for (auto& stem :
           depthPairStems(scenes[s], tmp + "/depth" + std::to_string(s), threads, o.refPairs))
        depthStems.push_back(std::move(stem));
    }
    printStageTable(results);
    nlohmann::json last = compareCovis(depthStems);
    fs::remove_all(tmp);
    last["scenes"] = results;
    std::printf("%s\n", last.dump().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_generate: error: %s\n", e.what());
    return 1;
  }
}
