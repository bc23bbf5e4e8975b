// render_view: renders one view of a scene (RGB, z-depth, normals), or N random views.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "dataset/viewpoint_sampler.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "tool_main.h"
#include "util/atomic_file.h"
#include "util/image_io.h"

using namespace paircast;

namespace {

struct Args {
  std::string scene, up = "y", camera, rgb, depth, normals, out;
  double scale = 1.0, hfov = 60.0;
  int random = 0, resolution = 256, supersample = 1;
  uint64_t seed = 0;
};

void writeFrame(const Frame& frame, const std::string& rgb, const std::string& depth,
                const std::string& normals) {
  if (!rgb.empty()) writeImage(rgb, frame.rgb);
  if (!depth.empty()) writeExr(depth, frame.depth);
  if (!normals.empty()) writeExr(normals, frame.normals);
}

int run(const Args& a) {
  LoadOptions load;
  load.up = parseUpAxis(a.up);
  load.scale = a.scale;
  Scene scene = loadScene(a.scene, load);
  for (const auto& w : scene.warnings)
    std::fprintf(stderr, "render_view: warning: %s\n", w.c_str());
  std::printf("%s: %s\n", a.scene.c_str(), computeStats(scene.mesh).summary().c_str());
  RayCaster caster(scene.mesh);
  RenderOptions options;
  options.supersample = a.supersample;
  options.normals = !a.normals.empty() || a.random > 0;
  Frame frame;

  if (a.random == 0) {
    Camera camera = readCameraJson(a.camera);
    caster.render(camera, options, frame);
    writeFrame(frame, a.rgb, a.depth, a.normals);
    std::printf("rendered %dx%d, %.1f%% of pixels hit\n", camera.width, camera.height,
                100.0 * frame.validFraction());
    return 0;
  }

  makeDirs(a.out);
  SamplerOptions sopts;
  ViewpointSampler sampler(scene, caster, sopts);
  Camera intrinsics = Camera::fromHfov(a.resolution, a.resolution, a.hfov);
  for (int i = 0; i < a.random; ++i) {
    Rng rng(mixSeed(a.seed, scene.name, static_cast<uint64_t>(i)));
    Camera camera = sampler.sampleView(intrinsics, rng);
    caster.render(camera, options, frame);
    char stem[32];
    std::snprintf(stem, sizeof stem, "%06d", i);
    const std::string base = (std::filesystem::path(a.out) / stem).string();
    writeFrame(frame, base + ".png", base + "_depth.exr", base + "_normals.exr");
    writeCameraJson(base + ".json", camera);
  }
  std::printf("wrote %d views to %s\n", a.random, a.out.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  CLI::App app{"Render RGB, z-depth and normals of a mesh scene with Embree"};
  app.add_option("--scene", a.scene, "Scene file (glb, gltf, obj, ply, fbx, dae, ifc, ...)")
      ->required();
  app.add_option("--up", a.up, std::string("Up axis of the scene: y, z, or ") + kUpAutoHelp)
      ->check(CLI::IsMember({"y", "z", "auto"}));
  app.add_option("--scale", a.scale, "Multiply positions by this (file units to metres)");
  auto* cam = app.add_option("--camera", a.camera,
                             "Camera JSON (CroCo's camera_params keys + width, height)");
  app.add_option("--rgb", a.rgb, "Output RGB (.png or .jpg)");
  app.add_option("--depth", a.depth, "Output z-depth (.exr, float32, 0 on a miss)");
  app.add_option("--normals", a.normals, "Output world normals (.exr)");
  auto* rnd = app.add_option("--random", a.random, "Render N random views inside the scene")
                  ->check(CLI::Range(1, 1000000));
  app.add_option("--out", a.out, "Output folder for --random");
  app.add_option("--resolution", a.resolution, "Image size for --random")
      ->check(CLI::Range(8, 8192));
  app.add_option("--hfov", a.hfov, "Horizontal field of view for --random, degrees")
      ->check(CLI::Range(1.0, 179.0));
  app.add_option("--seed", a.seed, "Random seed for --random");
  app.add_option("--supersample", a.supersample, "s x s colour samples per pixel")
      ->check(CLI::Range(1, 4));
  cam->excludes(rnd);
  return runTool("render_view", app, argc, argv, [&] {
    if (a.random == 0 && a.camera.empty()) throw Error("give --camera CAM.json or --random N");
    if (a.random > 0 && a.out.empty()) throw Error("--random needs --out DIR");
    if (a.random == 0 && a.rgb.empty() && a.depth.empty() && a.normals.empty())
      throw Error("nothing to write: give --rgb, --depth or --normals");
    return run(a);
  });
}
