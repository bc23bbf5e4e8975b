// Scenes that assimp reads (glb, gltf, obj + mtl, ply, fbx, dae, ifc, ...): read through a
// file system that opens only regular files within the size limit, with assimp's flaws worked
// around, and converted to our Mesh (node transforms applied, faces triangulated, materials,
// textures and vertex colours kept).
#pragma once

#include <string>

#include "render/scene_loader.h"

namespace paircast {

// How to read a file, besides the LoadOptions.
struct AssimpImport {
  bool noTextures = false;          // base colours only (the textures are Basis Universal)
  bool linearVertexColors = false;  // the file's vertex colours are linear (glTF), not sRGB
};

// Reads `path` with assimp into out.mesh, adding warnings (textures skipped) to out.warnings.
// Throws paircast::Error naming `path` when assimp cannot read it, or the scene is incomplete or
// over the limits. The caller checks the result (triangles, indices, finite vertices).
void importWithAssimp(const std::string& path, const LoadOptions& options, const AssimpImport& how,
                      Scene& out);

}  // namespace paircast
