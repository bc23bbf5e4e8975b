// make_scenes: writes the procedural scenes paircast ships (scenes/<name>/<name>.obj), any
// number of random ones, or a procedural scan in a scan dataset's own format (--scan).
#include <cstdio>
#include <filesystem>

#include "render/obj_writer.h"
#include "render/procedural_scene.h"
#include "render/scan_scene.h"
#include "tool_main.h"

using namespace paircast;

int main(int argc, char** argv) {
  std::string out = "scenes";
  bool list = false;
  int random = 0, rooms = 0;
  uint64_t seed = 0;
  std::string scan;
  size_t triangles = ScanSpec{}.triangles;
  CLI::App app{"Write the shipped procedural indoor scenes as OBJ + MTL + PNG textures"};
  app.add_option("--out", out, "Output folder (default: scenes)");
  app.add_option("--random", random,
                 "Write N random floor plans (random_<seed>_<i>) instead of the shipped scenes")
      ->check(CLI::Range(1, 100000));
  app.add_option("--rooms", rooms,
                 "With --random: buildings of exactly this many rooms (default: 1-5 rooms, "
                 "5-12 m by 4-9 m)")
      ->check(CLI::Range(1, kMaxLayoutRooms));
  app.add_option("--seed", seed, "Seed of the random floor plans or of the scan");
  app.add_flag("--list", list, "Only list the scenes");
  app.add_option("--scan", scan,
                 "Write one procedural scan as the dataset ships it: scannet (binary PLY, vertex "
                 "RGBA), replica (PLY, quad faces), mp3d (OBJ + MTL + JPEG textures); all z up")
      ->check(CLI::IsMember({"scannet", "replica", "mp3d"}));
  app.add_option("--triangles", triangles, "Triangles of the --scan (default 1300000)")
      ->check(CLI::Range(size_t{1000}, size_t{100'000'000}));
  return runTool("make_scenes", app, argc, argv, [&] {
    if (!scan.empty()) {
      ScanSpec spec;
      spec.kind = parseScanKind(scan);
      spec.triangles = triangles;
      spec.seed = seed;
      MeshStats stats;
      const std::string path = writeScan(spec, out, &stats);
      std::printf("%s: %s (z up: render with --up z)\n", path.c_str(), stats.summary().c_str());
      return 0;
    }
    std::vector<LayoutSpec> layouts = shippedLayouts();
    if (rooms > 0 && random == 0) throw OptionError("rooms", "--rooms needs --random N");
    if (random > 0) {
      layouts.clear();
      for (int i = 0; i < random; ++i) {
        const std::string name = "random_" + std::to_string(seed) + "_" + std::to_string(i);
        layouts.push_back(randomLayout(name, seed * 100003 + static_cast<uint64_t>(i) + 1, rooms));
      }
    }
    for (const LayoutSpec& layout : layouts) {
      if (list) {
        std::printf("%s: %zu rooms, %zu doors\n", layout.name.c_str(), layout.rooms.size(),
                    layout.doors.size());
        continue;
      }
      const Mesh mesh = buildLayout(layout);
      const std::string path =
          (std::filesystem::path(out) / layout.name / (layout.name + ".obj")).string();
      writeObj(path, mesh);
      std::printf("%s: %s\n", path.c_str(), computeStats(mesh).summary().c_str());
    }
    return 0;
  });
}
