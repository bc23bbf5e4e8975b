// bench_generate: accepted pairs/s of generate_pairs at 256x256 per scene, with the time split,
// and the co-visibility cost per pair on one core against CroCo's kd-tree method
// (../shared/tools/ref_covis.py), on the same depth maps, with their agreement.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "covis/covisibility.h"
#include "dataset/generate_job.h"
#include "dataset/shard.h"
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

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> sceneArgs;
  std::string up = "y";
  int pairs = 100, jobs = 0, refPairs = 5;
  CLI::App app{"Pair generation speed and co-visibility cost"};
  app.add_option("--scenes", sceneArgs, "Scenes (default: scenes/ and ../shared/scenes)");
  app.add_option("--up", up, "Up axis of --scenes")->check(CLI::IsMember({"y", "z"}));
  app.add_option("--pairs", pairs, "Accepted pairs per scene");
  app.add_option("--jobs", jobs, "Worker threads (default: all cores)");
  app.add_option("--ref-pairs", refPairs, "Pairs compared with ref_covis.py");
  CLI11_PARSE(app, argc, argv);
  try {
    std::vector<SceneArg> scenes;
    if (sceneArgs.empty()) {
      for (const auto& p : expandSceneList({std::string(PAIRCAST_SOURCE_DIR) + "/scenes"}))
        scenes.push_back({p, UpAxis::Y});
      if (fs::exists(sharedDir() + "/scenes/simple_room.glb"))
        scenes.push_back({sharedDir() + "/scenes/simple_room.glb", UpAxis::Z});
      if (fs::exists(sharedDir() + "/scenes/stage_floor1.glb"))
        scenes.push_back({sharedDir() + "/scenes/stage_floor1.glb", UpAxis::Y});
    } else {
      for (const auto& p : expandSceneList(sceneArgs)) scenes.push_back({p, parseUpAxis(up)});
    }
    const std::string tmp =
        (fs::temp_directory_path() / ("bench_generate_" + std::to_string(::getpid()))).string();
    const unsigned threads = jobs > 0 ? jobs : std::max(1u, std::thread::hardware_concurrency());
    std::printf("threads: %u, %d pairs per scene, 256x256, hfov 60, covis >= 0.5\n", threads,
                pairs);
    nlohmann::json results = nlohmann::json::array();
    std::vector<std::string> depthStems;
    for (size_t s = 0; s < scenes.size(); ++s) {
      GenerateConfig c;
      c.scenes = {scenes[s].path};
      c.load.up = scenes[s].up;
      c.out = tmp + "/gen" + std::to_string(s);
      c.pairsPerScene = pairs;
      c.jobs = static_cast<int>(threads);
      c.progress = false;
      const nlohmann::json sum = runGenerate(c);
      const std::string name = fs::path(scenes[s].path).filename().string();
      if (!sum["skipped_scenes"].empty()) {
        std::printf("%-22s skipped: %s\n", name.c_str(),
                    sum["skipped_scenes"][0]["reason"].get<std::string>().c_str());
        continue;
      }
      const auto& split = sum["time_split"];
      std::printf(
          "%-22s %7.1f accepted pairs/s  acceptance %4.1f%%  time: render %4.1f%%  covis "
          "%4.1f%%  encode %4.1f%%  write %4.1f%%\n",
          name.c_str(), sum["pairs_per_second"].get<double>(),
          100 * sum["acceptance"].get<double>(), 100 * split["render"].get<double>(),
          100 * split["covis"].get<double>(), 100 * split["encode"].get<double>(),
          100 * split["write"].get<double>());
      results.push_back({{"scene", name},
                         {"pairs_per_second", sum["pairs_per_second"]},
                         {"acceptance", sum["acceptance"]},
                         {"time_split", split}});
      // A few pairs with depth, for the co-visibility comparison.
      c.out = tmp + "/depth" + std::to_string(s);
      c.pairsPerScene = refPairs;
      c.shards = false;
      c.croco = true;
      c.saveDepth = true;
      runGenerate(c);
      for (int k = 0; k < refPairs; ++k) {
        char idx[16];
        std::snprintf(idx, sizeof idx, "%08d", k);
        const std::string stem =
            c.out + "/" + sanitizeName(fs::path(scenes[s].path).stem().string()) + "/" + idx;
        if (fs::exists(stem + "_1_depth.exr")) depthStems.push_back(stem);
      }
    }

    // Co-visibility on one core: ours, best of several passes over the same pairs.
    double oursMs = 0, worstDiff = 0, officialMs = 0;
    int compared = 0;
    if (!depthStems.empty()) {
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
        const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count() /
                          (20 * loaded.size());
        if (sink >= 0) best = std::min(best, ms);
      }
      oursMs = best;
      std::printf("covis (ours, reprojection, 1 core): %.3f ms per 256x256 pair\n", oursMs);
      const bool haveRef =
          fs::exists(sharedDir() + "/tools/ref_covis.py") &&
          std::system("/usr/bin/python3 -c 'import sklearn, numpy' 2>/dev/null") == 0;
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
      if (compared) {
        officialMs /= compared;
        std::printf("covis (CroCo kd-tree, ref_covis.py): %.1f ms per pair: ours is %.0fx faster\n",
                    officialMs, officialMs / oursMs);
        std::printf(
            "agreement with ref_covis.py reprojection over %d pairs: max |covis difference| %.4f\n",
            compared, worstDiff);
      } else {
        std::printf(
            "ref_covis.py comparison skipped (needs ../shared/tools and python3-sklearn)\n");
      }
    }
    fs::remove_all(tmp);
    nlohmann::json last = {{"scenes", results}, {"covis_ms_per_pair", oursMs}};
    if (compared) {
      last["covis_ms_kdtree"] = officialMs;
      last["covis_speedup"] = officialMs / oursMs;
      last["covis_max_diff_reproj"] = worstDiff;
    }
    std::printf("%s\n", last.dump().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_generate: error: %s\n", e.what());
    return 1;
  }
}
