// generate_pairs --from-metadata: renders the poses of metadata.json files (CroCo's released
// ones, or paircast's own) into CroCo's layout, as CroCo's generate_from_metadata.py does with
// habitat-sim. docs/dataset.md, "Replaying metadata", and docs/conventions.md, "Habitat".
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "render/frame.h"
#include "render/scene_loader.h"

namespace paircast {

struct ReplayConfig {
  std::vector<std::string> metadata;  // metadata.json files, or folders searched recursively
  std::string sceneRoot;              // scene paths are looked up under it ("" : as written)
  std::string out;
  LoadOptions load;      // --scale; load.up unless the metadata says (paircast's)
  bool upGiven = false;  // --up was given: it wins over the metadata's "up"
  int jpegQuality = 90;
  RenderOptions render;
  bool progress = true;
};

// The scene file a metadata.json names: its "scene" path as written, under `sceneRoot`, or under
// the metadata's folder (for a relative path); an absolute path that does not exist is also tried
// with its leading folders dropped, under `sceneRoot`. A ".basis.glb" falls back to the ".glb"
// beside it (HM3D ships both; Basis textures are not decoded). nullopt when nothing exists.
std::optional<std::string> resolveScenePath(const std::string& scene,
                                            const std::string& metadataFile,
                                            const std::string& sceneRoot);

// Renders every sample of every metadata file; returns the summary (also <out>/summary.json).
// A metadata file whose scene is missing or unreadable, or whose JSON is malformed, is skipped
// with a warning and listed in "skipped".
nlohmann::json runReplay(const ReplayConfig& config);

}  // namespace paircast
