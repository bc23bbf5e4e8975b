// Furnished homes: the procedural floor plans (render/procedural_scene.h) with real furniture
// models from Sweet Home 3D catalogues (furnish/catalog.h) in place of boxes.
//
// Each room gets a type from its kind (living room, bedroom, kitchen, office; a hall under
// 12 m^2 becomes a bathroom, a larger one a living room) and models of the matching catalogue
// category. Each model is turned by its catalogue's modelRotation, scaled to its catalogue size
// and set on the floor (or at its catalogue elevation): against a wall, its back to it, or free
// standing, turned by a multiple of 90 degrees; about half the door openings get a door of the
// catalogue, scaled to the opening; small pieces stand on the tops of tables,
// counters and cabinets (isTabletop, canHold). Floor footprints never overlap each other, the
// walls, the floor before each door, or a free square at the room's centre where cameras can stand;
// they cover at most kMaxCover of the room's floor. All draws hash the layout's seed, so a seed
// gives the same scene, byte for byte.
#pragma once

#include <Eigen/Core>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "furnish/catalog.h"
#include "render/mesh.h"
#include "render/procedural_scene.h"

namespace paircast {

constexpr float kMaxCover = 0.35f;      // of a room's floor under furniture, at most
constexpr float kFreeCentre = 1.2f;     // side of the free square at each room's centre, m
constexpr float kFurnitureGap = 0.02f;  // between footprints, and between a footprint and a wall

struct FurnishOptions {
  std::string catalogDir = kDebianFurnitureDir;
  ModelSet models = ModelSet::All;
  size_t maxModelTriangles = 60000;  // heavier models are left out
};

// Small pieces (both sides under 0.35 m, lower than 0.45 m, standing on the floor in the
// catalogue: cups, lamps, plants) stand on the tops of tables, counters and cabinets, never on
// the floor.
bool isTabletop(const CatalogModel& m);
// Whether small pieces may stand on `m`: a top 0.5-1.2 m high, sides of 0.3 m or more, and no
// dropOnTopElevation (the catalogue gives one for seats and beds).
bool canHold(const CatalogModel& m);

// One model in a scene: its footprint is [x0, x1] x [z0, z1], its base at height y.
struct Placement {
  size_t model;  // index into FurnitureLibrary::models()
  int room;
  float x, z;   // centre of the footprint
  int quarter;  // turns of 90 degrees about +y; 0 faces +z
  float x0, z0, x1, z1;
  float y = 0;    // the base: the floor, the catalogue's elevation, or the top of the host
  int host = -1;  // the placement (index in the scene's) it stands on, or -1
  int door = -1;  // the door opening (index in the layout's doors) it closes, or -1
  float widthScale = 1, heightScale = 1, depthScale = 1;  // a door's: catalogue size to opening
};

// The door models: "Doors and windows" entries named a door, at most 1.2 m wide (no garage,
// elevator or double doors).
bool isDoor(const CatalogModel& m);
constexpr float kClosedDoorShare = 0.5f;  // of the openings that get a door

// The catalogues' models and, loaded on demand, their meshes normalised to the catalogue's size:
// x in [-width/2, width/2], y in [0, height], z in [-depth/2, depth/2], front towards +z.
class FurnitureLibrary {
 public:
  explicit FurnitureLibrary(const FurnishOptions& options);
  ~FurnitureLibrary();
  FurnitureLibrary(const FurnitureLibrary&) = delete;
  FurnitureLibrary& operator=(const FurnitureLibrary&) = delete;

  const std::vector<CatalogModel>& models() const { return models_; }
  const FurnishOptions& options() const { return options_; }
  // The models of `category` in the option's set, by index.
  std::vector<size_t> ofCategory(const std::string& category) const;
  // Loads the given models not loaded yet, one pass over each catalogue. A model that cannot be
  // read, or is over the triangle limit, is marked unusable, with a warning naming its entry.
  void load(const std::set<size_t>& indices);
  // The normalised mesh of a loaded model, or nullptr when it is unusable.
  const Mesh* mesh(size_t index) const;
  bool unusable(size_t index) const { return unusable_.count(index) > 0; }
  // Warnings so far (catalogues and models skipped); each once.
  std::vector<std::string> warnings;

 private:
  Mesh normalised(const CatalogModel& m, const std::string& objPath) const;

  FurnishOptions options_;
  std::vector<CatalogModel> models_;
  std::string scratch_;  // extracted model folders, removed with the library
  std::map<size_t, Mesh> meshes_;
  std::set<size_t> unusable_;
};

struct FurnishedScene {
  Mesh mesh;
  std::vector<Placement> placements;
  nlohmann::json credits;  // credits.json: each model used, its catalogue, creator and licence
};

// The room type a furnished room gets, as a catalogue category ("Living room", "Bathroom", ...).
std::string roomCategory(const RoomSpec& room);

// The layout's shell (LayoutSpec::furnished) with the library's models placed in every room.
FurnishedScene furnishLayout(const LayoutSpec& layout, FurnitureLibrary& library);

// Writes <out>/<name>/<name>.obj (+ MTL and textures) and credits.json beside it; returns the
// .obj's path.
std::string writeFurnishedScene(const FurnishedScene& scene, const std::string& out,
                                const std::string& name);

}  // namespace paircast
