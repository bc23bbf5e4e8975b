// bench_load: where the time of a big scene goes before the first pair: loading the file, the
// BVH, the floor map; and the process's peak resident memory. Generates procedural scans
// (make_scenes --scan) when no scene is given. Prints one JSON line per scene.
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "dataset/floor_map.h"
#include "render/ray_caster.h"
#include "render/scan_scene.h"
#include "render/scene_loader.h"
#include "util/timer.h"

using namespace paircast;

namespace {

double peakRssMiB() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;  // Linux reports KiB
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> scenes;
  std::string up = "z", kinds = "scannet", out = "/tmp/paircast_bench_load";
  size_t triangles = ScanSpec{}.triangles;
  bool assimp = false;
  CLI::App app{"Load, BVH and floor-map time and peak RSS of big scenes"};
  app.add_option("--scene", scenes, "Scene files (default: generate scans)");
  app.add_option("--up", up, "Up axis of --scene files (y, z or auto)");
  app.add_option("--scan", kinds, "Scan kind to generate: scannet, replica or mp3d");
  app.add_option("--triangles", triangles, "Triangles of the generated scan");
  app.add_option("--out", out, "Where generated scans go");
  app.add_flag("--assimp", assimp, "Read PLY files with assimp, not the binary fast path");
  CLI11_PARSE(app, argc, argv);
  try {
    if (scenes.empty()) {
      ScanSpec spec;
      spec.kind = parseScanKind(kinds);
      spec.triangles = triangles;
      const auto start = SteadyClock::now();
      scenes.push_back(writeScan(spec, out));
      std::fprintf(stderr, "wrote %s in %.2f s\n", scenes.back().c_str(), secondsSince(start));
    }
    for (const std::string& path : scenes) {
      LoadOptions lo;
      lo.up = parseUpAxis(up);
      lo.plyFastPath = !assimp;
      auto start = SteadyClock::now();
      const Scene scene = loadScene(path, lo);
      const double load = secondsSince(start);
      start = SteadyClock::now();
      RayCaster caster(scene.mesh);
      const double bvh = secondsSince(start);
      start = SteadyClock::now();
      FloorMap floor(scene, caster);
      const double floorSeconds = secondsSince(start);
      const double mtri = scene.mesh.numTriangles() / 1e6;
      nlohmann::json j = {{"scene", path},
                          {"triangles", scene.mesh.numTriangles()},
                          {"load_seconds", load},
                          {"bvh_seconds", bvh},
                          {"floor_seconds", floorSeconds},
                          {"seconds_per_mtri", (load + bvh + floorSeconds) / mtri},
                          {"floor_area_m2", floor.area()},
                          {"peak_rss_mib", peakRssMiB()}};
      std::printf("%s\n", j.dump().c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_load: %s\n", e.what());
    return 1;
  }
  return 0;
}
