// Writes a Mesh as Wavefront OBJ + MTL, with its textures as PNG files in textures/ beside it,
// so that any tool (Blender, assimp, Open3D) opens the scene. Kd holds the linear base colour,
// as assimp reads it back. The bytes depend only on the mesh.
#pragma once

#include <string>

#include "render/mesh.h"

namespace paircast {

// Writes <path> (the .obj), <stem>.mtl and textures/<name>.<textureFormat> ("png", or "jpg" as
// Matterport's meshes ship). Atomic per file.
void writeObj(const std::string& path, const Mesh& mesh, const std::string& textureFormat = "png");

}  // namespace paircast
