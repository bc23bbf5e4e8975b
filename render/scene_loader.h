// Mesh scenes from files through assimp: glb, gltf, obj (+mtl), ply, fbx, dae, ifc and the
// other formats assimp reads. Node transforms are applied, faces triangulated, and materials
// (base colour factor, base-colour or diffuse texture, vertex colours) kept per triangle.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "render/mesh.h"

namespace paircast {

// Which world axis points up in the file. Positions are never rotated: poses stay in the
// file's own frame, and the samplers use up to find floors and level the cameras.
// Auto is only an option: loadScene resolves it with guessUpAxis, and a Scene's axis is y or z.
enum class UpAxis { Y, Z, Auto };
UpAxis parseUpAxis(const std::string& text);  // "y", "z" or "auto"; throws paircast::Error
Eigen::Vector3f upVector(UpAxis up);          // of y or z

// The up axis of a mesh whose file does not say (--up auto): the one of y and z with the larger
// area of surfaces across it (within 30 degrees), since a building's floors and ceilings
// outweigh its walls along one axis. When neither leads by 25% (the walls of many small rooms),
// the axis along which the mesh is at least 20% shorter: a storey is lower than it is deep.
// Throws paircast::Error naming `path`, and asking for --up, when neither cue decides.
UpAxis guessUpAxis(const Mesh& mesh, const std::string& path);
// What auto does, for the tools' --up help.
inline constexpr const char* kUpAutoHelp =
    "auto (the axis with the larger floor and ceiling area, else the one along which the scene is "
    "at least 20% shorter)";

// The limits guard against hostile or broken files: they are checked before assimp allocates
// (file sizes, and the element counts a PLY header claims) and again after import.
struct LoadOptions {
  UpAxis up = UpAxis::Y;
  double scale = 1.0;                  // multiplies every position (file units -> metres)
  size_t maxTriangles = 50'000'000;    // refuse larger scenes instead of exhausting memory
  size_t maxVertices = 150'000'000;    // likewise for vertices
  uint64_t maxFileBytes = 4ull << 30;  // refuse larger files (the scene and every file it names)
  // Binary little-endian PLY files (as ScanNet and Replica ship) are read by our own reader,
  // straight into the Mesh, without assimp's generic per-property containers; false forces assimp.
  bool plyFastPath = true;
};

struct Scene {
  std::string path;
  std::string name;  // file stem, used for output folders
  UpAxis up = UpAxis::Y;
  Mesh mesh;
  std::vector<std::string> warnings;  // e.g. textures that could not be read
  Eigen::Vector3f upVector() const { return paircast::upVector(up); }
};

// Loads a scene. Throws paircast::Error naming `path` when the file is missing, of an
// unsupported type, corrupt, empty (no triangles), too large, or has non-finite vertices.
// Files the scene names (materials, buffers, textures) are opened only when they are regular
// files (no devices or FIFOs) within maxFileBytes; a texture that fails is a warning.
Scene loadScene(const std::string& path, const LoadOptions& options = {});

// True when assimp has an importer for the extension of `path`.
bool isSupportedSceneFile(const std::string& path);

}  // namespace paircast
