#include "render/scene_loader.h"

#include <Eigen/Geometry>
#include <assimp/Importer.hpp>

#include <cctype>
#include <cmath>
#include <filesystem>

#include "render/assimp_import.h"
#include "render/gltf_checks.h"
#include "render/ply_reader.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace fs = std::filesystem;

UpAxis parseUpAxis(const std::string& text) {
  if (text == "y" || text == "Y") return UpAxis::Y;
  if (text == "z" || text == "Z") return UpAxis::Z;
  if (text == "auto") return UpAxis::Auto;
  throw Error("invalid up axis '" + text + "' (use y, z or auto)");
}

Eigen::Vector3f upVector(UpAxis up) {
  PAIRCAST_CHECK_MSG(up != UpAxis::Auto, "the up axis is resolved when the scene is loaded");
  return up == UpAxis::Y ? Eigen::Vector3f::UnitY() : Eigen::Vector3f::UnitZ();
}

UpAxis guessUpAxis(const Mesh& mesh, const std::string& path) {
  const float cos30 = std::cos(static_cast<float>(M_PI) / 6.0f);
  double across[2] = {0.0, 0.0};  // area of surfaces across y, across z
  Eigen::AlignedBox3f bounds;     // of those surfaces, whatever their direction
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3f& a = mesh.positions[t[0]];
    const Eigen::Vector3f n = (mesh.positions[t[1]] - a).cross(mesh.positions[t[2]] - a);
    const float area = 0.5f * n.norm();
    if (!(area > 0.0f)) continue;
    if (std::abs(n.y()) >= cos30 * 2.0f * area) across[0] += area;
    if (std::abs(n.z()) >= cos30 * 2.0f * area) across[1] += area;
    for (int k = 0; k < 3; ++k) bounds.extend(mesh.positions[t[k]]);
  }
  if (across[1] > 1.25 * across[0]) return UpAxis::Z;
  if (across[0] > 1.25 * across[1]) return UpAxis::Y;
  // Many rooms' walls can rival the floors and ceilings; a storey is still lower than it is deep.
  const Eigen::Vector3f extent =
      bounds.isEmpty() ? Eigen::Vector3f(Eigen::Vector3f::Zero()) : Eigen::Vector3f(bounds.sizes());
  if (extent.z() < 0.8f * extent.y()) return UpAxis::Z;
  if (extent.y() < 0.8f * extent.z()) return UpAxis::Y;
  throw Error(path, "cannot tell the up axis (" + std::to_string(across[0]) + " m^2 across y, " +
                        std::to_string(across[1]) + " m^2 across z, and " +
                        std::to_string(extent.y()) + " m along y, " + std::to_string(extent.z()) +
                        " m along z): pass --up y or --up z");
}

bool isSupportedSceneFile(const std::string& path) {
  Assimp::Importer importer;
  std::string ext = fs::path(path).extension().string();
  return !ext.empty() && importer.IsExtensionSupported(ext);
}

namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The checks before anything is read: a file (not a folder), not empty, within the size limit,
// of a format assimp has an importer for; and a positive scale. Returns the file's size.
uint64_t checkSceneFile(const std::string& path, const LoadOptions& options) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(path, "no such file");
  if (fs::is_directory(path, ec)) throw Error(path, "is a folder, not a scene file");
  const uint64_t bytes = fs::file_size(path, ec);
  if (ec) throw Error(path, "cannot read file size: " + ec.message());
  if (bytes == 0) throw Error(path, "file is empty");
  if (bytes > options.maxFileBytes)
    throw Error(path, "file is larger than the limit (" + std::to_string(bytes) + " bytes)");
  if (!(options.scale > 0) || !std::isfinite(options.scale))
    throw Error(path, "scale must be a positive number");
  if (!isSupportedSceneFile(path))
    throw Error(path, "unsupported scene format '" + fs::path(path).extension().string() +
                          "' (glb, gltf, obj, ply, fbx, dae, ifc, ... are supported)");
  return bytes;
}

// The glTF checks for a .glb or .gltf file; none for other formats.
GltfCheck checkGltf(const std::string& path, const std::string& ext, uint64_t bytes) {
  if (ext == ".glb") return checkGlbHeader(path, bytes);
  if (ext == ".gltf") return checkGltfJson(path, readFile(path));  // within maxFileBytes
  return GltfCheck{};
}

// The checks every loader ends with: no triangles, bad indices, non-finite vertices; and the up
// axis, when it is to be guessed.
Scene checked(Scene& scene) {
  if (scene.mesh.numTriangles() == 0) throw Error(scene.path, "scene has no triangles");
  scene.mesh.validate(scene.path);
  if (scene.up == UpAxis::Auto) scene.up = guessUpAxis(scene.mesh, scene.path);
  return std::move(scene);
}

}  // namespace

Scene loadScene(const std::string& path, const LoadOptions& options) {
  const uint64_t bytes = checkSceneFile(path, options);
  Scene out;
  out.path = path;
  out.name = fs::path(path).stem().string();
  out.up = options.up;

  const std::string ext = lower(fs::path(path).extension().string());
  if (ext == ".ply") {
    const PlyHeader header = checkPlyHeader(path, bytes, options);
    if (options.plyFastPath && plyFastPathApplies(header)) {
      readBinaryPly(path, header, options, out.mesh);
      return checked(out);
    }
  }
  const GltfCheck gltf = checkGltf(path, ext, bytes);
  if (!gltf.basisExtension.empty())
    out.warnings.push_back(path + ": textures use " + gltf.basisExtension +
                           " (Basis Universal), which paircast cannot decode: rendering with base "
                           "colours; for textures use the plain .glb with JPEG textures (HM3D "
                           "ships both)");
  AssimpImport how;
  how.noTextures = !gltf.basisExtension.empty();
  how.linearVertexColors = ext == ".glb" || ext == ".gltf";
  importWithAssimp(path, options, how, out);
  return checked(out);
}

}  // namespace paircast
