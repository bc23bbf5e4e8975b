// Replays the fuzz targets' seeds and kept findings (fuzz/corpus/<target>/,
// tests/regressions/<target>/) through the targets' own entry points (fuzz/render_inputs.h).
// A crash or a sanitizer report here is a regression.
#include <gtest/gtest.h>

#include "fuzz/render_inputs.h"
#include "test_paths.h"

namespace paircast {
namespace {

TEST(RegressionInputs, SceneObj) {
  const std::string dir = testing::scratchDir("obj");
  testing::replayFuzzInputs(
      "fuzz_scene_obj", [&](const std::string& b) { return fuzz::runSceneInput(b, ".obj", dir); });
}

TEST(RegressionInputs, ScenePly) {
  const std::string dir = testing::scratchDir("ply");
  testing::replayFuzzInputs(
      "fuzz_scene_ply", [&](const std::string& b) { return fuzz::runSceneInput(b, ".ply", dir); });
}

TEST(RegressionInputs, SceneGlb) {
  const std::string dir = testing::scratchDir("glb");
  testing::replayFuzzInputs(
      "fuzz_scene_glb", [&](const std::string& b) { return fuzz::runSceneInput(b, ".glb", dir); });
}

TEST(RegressionInputs, CameraJson) {
  testing::replayFuzzInputs("fuzz_camera_json",
                            [](const std::string& b) { return fuzz::runCameraJsonInput(b); });
}

}  // namespace
}  // namespace paircast
