// Fuzz entry points for render/: scene files through loadScene, camera JSON through
// cameraFromJson. See fuzz_inputs.h.
#pragma once

#include <nlohmann/json.hpp>

#include "fuzz/fuzz_inputs.h"
#include "render/scene_loader.h"
#include "util/camera.h"

namespace paircast::fuzz {

// Small limits keep each run fast; the checks that enforce them are part of what is tested.
inline LoadOptions fuzzLoadOptions() {
  LoadOptions o;
  o.maxTriangles = 1'000'000;
  o.maxVertices = 3'000'000;
  o.maxFileBytes = 16u << 20;
  return o;
}

// `extension` picks the importer, as the file name does for users: ".obj", ".ply", ".glb".
inline bool runSceneInput(std::string_view bytes, const std::string& extension,
                          const std::string& dir = scratchDir()) {
  const std::string path = writeInput(bytes, dir, "input" + extension);
  return acceptedOrRefused([&] { loadScene(path, fuzzLoadOptions()); });
}

inline bool runCameraJsonInput(std::string_view bytes) {
  return acceptedOrRefused([&] {
    const nlohmann::json j = nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, false);
    if (j.is_discarded()) throw Error("input", "not valid JSON");  // as readCameraJson says
    cameraFromJson(j, "input");
  });
}

}  // namespace paircast::fuzz
