// make_scenes: writes the procedural scenes paircast ships (scenes/<name>/<name>.obj), any
// number of random ones, furnished with Sweet Home 3D models (--furnish), or a procedural scan in
// a scan dataset's own format (--scan).
#include <cstdio>
#include <filesystem>

#include "furnish/furnish.h"
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
  bool furnish = false, shell = false;
  std::string models = "all";
  FurnishOptions furnishOptions;
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
  app.add_flag("--furnish", furnish,
               "Furnish the rooms with Sweet Home 3D models (Debian's sweethome3d-furniture) "
               "instead of boxes, and write credits.json beside each scene");
  app.add_flag("--shell", shell,
               "Only the rooms of the plans: the walls, floors and ceiling that --furnish "
               "furnishes, with no furniture (to measure what the furniture adds)");
  app.add_option("--models", models,
                 "With --furnish: the catalogue models to use: train, heldout (a fifth of them, "
                 "for held-out scenes) or all")
      ->check(CLI::IsMember({"train", "heldout", "all"}));
  app.add_option("--catalogues", furnishOptions.catalogDir,
                 "With --furnish: the folder of .sh3f catalogues (default: Debian's)");
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
    if (furnish && shell) throw OptionError("shell", "--shell and --furnish exclude each other");
    if (!furnish && (models != "all" || furnishOptions.catalogDir != kDebianFurnitureDir))
      throw OptionError("models", "--models and --catalogues need --furnish");
    if (random > 0) {
      layouts.clear();
      for (int i = 0; i < random; ++i) {
        const std::string name = "random_" + std::to_string(seed) + "_" + std::to_string(i);
        layouts.push_back(randomLayout(name, seed * 100003 + static_cast<uint64_t>(i) + 1, rooms));
      }
    }
    std::unique_ptr<FurnitureLibrary> library;
    if (furnish && !list) {
      furnishOptions.models = parseModelSet(models);
      library = std::make_unique<FurnitureLibrary>(furnishOptions);
    }
    size_t warned = 0;
    for (const LayoutSpec& layout : layouts) {
      if (library) {
        const FurnishedScene scene = furnishLayout(layout, *library);
        for (; warned < library->warnings.size(); ++warned)
          std::fprintf(stderr, "make_scenes: warning: %s\n", library->warnings[warned].c_str());
        const std::string path = writeFurnishedScene(scene, out, layout.name);
        std::printf("%s: %s, %zu models\n", path.c_str(),
                    computeStats(scene.mesh).summary().c_str(), scene.placements.size());
        continue;
      }
      if (list) {
        std::printf("%s: %zu rooms, %zu doors\n", layout.name.c_str(), layout.rooms.size(),
                    layout.doors.size());
        continue;
      }
      LayoutSpec spec = layout;
      spec.furnished = shell;
      const Mesh mesh = buildLayout(spec);
      const std::string path =
          (std::filesystem::path(out) / layout.name / (layout.name + ".obj")).string();
      writeObj(path, mesh);
      std::printf("%s: %s\n", path.c_str(), computeStats(mesh).summary().c_str());
    }
    return 0;
  });
}
