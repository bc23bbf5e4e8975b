// make_scenes: writes the procedural scenes paircast ships (scenes/<name>/<name>.obj).
#include <cstdio>
#include <filesystem>

#include "render/obj_writer.h"
#include "render/procedural_scene.h"
#include "tool_main.h"

using namespace paircast;

int main(int argc, char** argv) {
  std::string out = "scenes";
  bool list = false;
  CLI::App app{"Write the shipped procedural indoor scenes as OBJ + MTL + PNG textures"};
  app.add_option("--out", out, "Output folder (default: scenes)");
  app.add_flag("--list", list, "Only list the scenes");
  return runTool("make_scenes", app, argc, argv, [&] {
    for (const LayoutSpec& layout : shippedLayouts()) {
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
