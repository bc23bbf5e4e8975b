// Small furnished indoor scenes, generated in code: rooms with textured floors and walls, doors
// between them, a ceiling, and furniture-like shapes (tables, chairs, sofas, beds, shelves of
// books, cabinets, lamps, rugs, paintings). Y up, metres. Deterministic for a given seed: the
// random draws use only integer hashing, so every platform builds the same mesh.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "render/mesh.h"

namespace paircast {

// Box builders shared by the generator and the tests. UVs are in metres times `uvScale`, so
// textures tile at a fixed size whatever the box.
void addBox(Mesh& mesh, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int material,
            float uvScale = 1.0f);

enum class RoomKind { Living, Bedroom, Kitchen, Office, Hall };

struct RoomSpec {
  float x0, z0, x1, z1;  // floor rectangle, metres
  RoomKind kind;
};

struct DoorSpec {
  int roomA, roomB;  // adjacent rooms sharing a wall
  float at;          // door centre along the shared wall
  float width = 0.9f;
};

struct LayoutSpec {
  std::string name;
  std::vector<RoomSpec> rooms;
  std::vector<DoorSpec> doors;
  float height = 2.7f;  // floor to ceiling
  uint64_t seed = 1;
  // Leave out furniture that stands in front of a door. Off for the shipped layouts, whose
  // committed files (and the figures measured on them) predate it.
  bool clearDoorways = false;
  // A shell for make_scenes --furnish (furnish/furnish.h): no box furniture and no paintings,
  // and each room's wall and floor texture drawn from the seed (kind, variant and tint).
  bool furnished = false;
};

// The walls' thickness; a room's rectangle is its walls' centre lines.
constexpr float kWallThickness = 0.1f;

// The height of every door opening (the lintel's underside).
constexpr float kDoorHeight = 2.1f;

// Where each of the layout's doors is: the centre of its opening on the floor, whether its wall
// runs along z (the line x = const) or along x, and its width.
struct DoorOpening {
  float x, z;
  bool alongZ;
  float width;
};
std::vector<DoorOpening> doorOpenings(const LayoutSpec& layout);

// The floor before each door that furniture leaves free: (x0, z0, x1, z1), `depth` m deep on
// both sides of the wall and 0.1 m wider than the door on each side.
std::vector<Eigen::Vector4f> doorwayKeepOuts(const LayoutSpec& layout, float depth = 0.8f);

// The scenes paircast ships (scenes/<name>/<name>.obj): "room", "apartment", "studio".
std::vector<LayoutSpec> shippedLayouts();
// A random floor plan, deterministic in `seed`: a rectangle of 5-12 m by 4-9 m split into 1-5
// rooms (each side at least 3 m) of random kinds, every room reachable through doors. For more
// training scenes than the shipped three (make_scenes --random N). With `rooms` > 0, a building of
// exactly that many rooms instead (make_scenes --rooms): a rectangle of 12-20 m^2 a room, as
// HM3D's and Matterport3D's houses are, split the same way.
LayoutSpec randomLayout(const std::string& name, uint64_t seed, int rooms = 0);
constexpr int kMaxLayoutRooms = 64;
// Builds the mesh of a layout: structure, textures, furniture.
Mesh buildLayout(const LayoutSpec& layout);

// A procedural texture (8-bit sRGB), by kind: "wood", "tiles", "carpet", "plaster",
// "wallpaper", "brick", "fabric", "paper", "marble"; `seed` varies it.
Texture makeTexture(const std::string& kind, uint64_t seed, int size = 256);

}  // namespace paircast
