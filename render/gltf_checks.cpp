#include "render/gltf_checks.h"

#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

#include "util/error.h"

namespace paircast {
namespace {

// EXT_meshopt_compression is refused; a Basis Universal texture extension is noted in `check`.
void checkExtensions(const std::string& path, const nlohmann::json& j, GltfCheck& check) {
  for (const char* key : {"extensionsUsed", "extensionsRequired"}) {
    const auto list = j.find(key);
    if (list == j.end() || !list->is_array()) continue;
    for (const auto& name : *list) {
      if (!name.is_string()) continue;
      const std::string ext = name.get<std::string>();
      if (ext == "EXT_meshopt_compression" || ext == "KHR_meshopt_compression")
        throw Error(path, "cannot load scene: it uses " + ext +
                              " (meshoptimizer-compressed buffers), which paircast does not "
                              "decode; export the scene without it (as the habitat datasets' "
                              "plain .glb files are)");
      if (ext == "GOOGLE_texture_basis" || ext == "KHR_texture_basisu") check.basisExtension = ext;
    }
  }
}

// Debian's assimp 5.2.5 decodes KHR_draco_mesh_compression, but drops the decoded indices when
// they are 32-bit (SetDecodedIndexBuffer_Draco returns before attaching them when their size
// matches Draco's own), and then fails with "Invalid accessor without data". Such files are
// refused here with the reason; 8- and 16-bit indices decode.
void checkDracoIndices(const std::string& path, const nlohmann::json& j) {
  const auto meshes = j.find("meshes");
  const auto accessors = j.find("accessors");
  if (meshes == j.end() || !meshes->is_array() || accessors == j.end() || !accessors->is_array())
    return;
  for (const auto& mesh : *meshes) {
    if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array())
      continue;
    for (const auto& prim : mesh["primitives"]) {
      if (!prim.is_object() || !prim.contains("indices") || !prim["indices"].is_number_unsigned() ||
          !prim.contains("extensions") || !prim["extensions"].is_object() ||
          !prim["extensions"].contains("KHR_draco_mesh_compression"))
        continue;
      const uint64_t index = prim["indices"].get<uint64_t>();
      if (index >= accessors->size() || !(*accessors)[index].is_object()) continue;
      const auto& type = (*accessors)[index].value("componentType", nlohmann::json());
      if (type.is_number() && type == 5125)
        throw Error(path,
                    "cannot load scene: a KHR_draco_mesh_compression primitive has 32-bit "
                    "indices, which assimp 5.2.5 drops when it decodes them; re-encode it "
                    "with 16-bit indices or without Draco");
    }
  }
}

// The media type an image states (its mimeType, or that of its data: URI) into `type`; false
// when it states none.
bool imageMediaType(const nlohmann::json& image, std::string& type) {
  if (image.is_object() && image.contains("mimeType")) {
    type = image["mimeType"].is_string() ? image["mimeType"].get<std::string>() : "";
    return true;
  }
  if (image.is_object() && image.contains("uri") && image["uri"].is_string() &&
      image["uri"].get<std::string>().rfind("data:", 0) == 0) {
    const std::string uri = image["uri"];
    type = uri.substr(5, uri.find_first_of(";,") - 5);
    return true;
  }
  return false;
}

void checkImageMediaTypes(const std::string& path, const nlohmann::json& j) {
  const auto images = j.find("images");
  if (images == j.end()) return;
  if (!images->is_array()) throw Error(path, "cannot load scene: glTF 'images' is not an array");
  for (size_t i = 0; i < images->size(); ++i) {
    std::string type;
    const bool has = imageMediaType((*images)[i], type);
    const size_t slash = type.find('/');
    if (has && (slash == std::string::npos || slash == 0 || slash + 1 == type.size()))
      throw Error(path, "cannot load scene: glTF image " + std::to_string(i) + " has media type '" +
                            type.substr(0, 64) + "', not type/subtype");
  }
}

uint32_t le32(const unsigned char* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// A version-1 GLB (after its 12-byte header, read): magic, version, length, content length,
// content format.
void checkGlbVersion1(const std::string& path, uint64_t fileBytes, std::ifstream& in,
                      unsigned char (&header)[20]) {
  if (in.read(reinterpret_cast<char*>(header + 12), 8) && le32(header + 12) > fileBytes - 20)
    throw Error(path, "cannot load scene: GLB header claims a " +
                          std::to_string(le32(header + 12)) +
                          "-byte scene, more than the file holds");
}

// A version-2 GLB's chunks (length, type, data), from byte 12; its first chunk, when JSON, goes
// through checkGltfJson.
GltfCheck checkGlbChunks(const std::string& path, uint64_t fileBytes, std::ifstream& in) {
  unsigned char header[8];
  GltfCheck check;
  for (uint64_t offset = 12; offset + 8 <= fileBytes;) {
    in.seekg(static_cast<std::streamoff>(offset));
    if (!in.read(reinterpret_cast<char*>(header), 8)) return check;
    const uint64_t chunk = le32(header);
    if (chunk > fileBytes - offset - 8)
      throw Error(path, "cannot load scene: GLB chunk at byte " + std::to_string(offset) +
                            " claims " + std::to_string(chunk) + " bytes, but only " +
                            std::to_string(fileBytes - offset - 8) + " follow");
    if (offset == 12 && std::memcmp(header + 4, "JSON", 4) == 0) {
      std::string json(chunk, '\0');
      if (!in.read(json.data(), static_cast<std::streamsize>(chunk)))
        throw Error(path, "cannot load scene: cannot read the GLB's JSON chunk");
      check = checkGltfJson(path, json);
    }
    offset += 8 + chunk;
  }
  return check;
}

}  // namespace

GltfCheck checkGltfJson(const std::string& path, const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object())
    throw Error(path, "cannot load scene: the glTF JSON is not a valid JSON object");
  GltfCheck check;
  checkExtensions(path, j, check);
  checkDracoIndices(path, j);
  checkImageMediaTypes(path, j);
  return check;
}

GltfCheck checkGlbHeader(const std::string& path, uint64_t fileBytes) {
  std::ifstream in(path, std::ios::binary);
  unsigned char header[20];
  if (!in.read(reinterpret_cast<char*>(header), 12) || std::memcmp(header, "glTF", 4) != 0)
    return GltfCheck{};
  const uint32_t version = le32(header + 4), length = le32(header + 8);
  if (length > fileBytes)
    throw Error(path, "cannot load scene: GLB header claims " + std::to_string(length) +
                          " bytes, the file has " + std::to_string(fileBytes));
  if (version == 1) {
    checkGlbVersion1(path, fileBytes, in, header);
    return GltfCheck{};
  }
  return checkGlbChunks(path, fileBytes, in);
}

}  // namespace paircast
