// Checks of glTF and binary glTF (GLB) files before assimp reads them: assimp 5.2.5 trusts what
// they state (chunk lengths, media types, index widths), and a bad file made it allocate
// gigabytes, read address 1, or render garbled geometry silently.
#pragma once

#include <cstdint>
#include <string>

namespace paircast {

// What the checks found that loading needs to know.
struct GltfCheck {
  std::string basisExtension;  // the Basis Universal extension the textures use, or ""
};

// assimp 5.2.5 takes strchr(mimeType, '/') + 1 for an embedded image without checking it, so a
// media type without '/' makes it read address 1 (fuzz_scene_glb found it). The glTF JSON is
// parsed here first: it must be valid JSON (UTF-8 included), and every image's media type
// (mimeType, or that of a data: URI) must be "type/subtype".
//
// It also looks at the extensions the habitat datasets use that assimp 5.2.5 does not decode:
// EXT_meshopt_compression buffers are refused (assimp would read the uncompressed fallback,
// often empty or garbage, and render garbled geometry silently); Basis Universal textures
// (GOOGLE_texture_basis, KHR_texture_basisu) are reported, so that the scene renders with its
// base colours and one warning. KHR_draco_mesh_compression primitives with 32-bit indices are
// refused (see checkDracoIndices in gltf_checks.cpp). Throws paircast::Error naming `path`.
GltfCheck checkGltfJson(const std::string& path, const std::string& text);

// A binary glTF states its chunk lengths up front, and assimp allocates a chunk before reading
// it: a 1 KB file claiming a 4 GB JSON chunk made it ask for 4 GB (fuzz_scene_glb found it).
// Lengths the file cannot hold are refused here, and the JSON chunk goes through
// checkGltfJson; files without the glTF magic are left to assimp.
GltfCheck checkGlbHeader(const std::string& path, uint64_t fileBytes);

}  // namespace paircast
