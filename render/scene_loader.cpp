#include "render/scene_loader.h"

#include <assimp/DefaultIOSystem.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <Eigen/Geometry>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

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
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3f& a = mesh.positions[t[0]];
    const Eigen::Vector3f n = (mesh.positions[t[1]] - a).cross(mesh.positions[t[2]] - a);
    const float area = 0.5f * n.norm();
    if (!(area > 0.0f)) continue;
    if (std::abs(n.y()) >= cos30 * 2.0f * area) across[0] += area;
    if (std::abs(n.z()) >= cos30 * 2.0f * area) across[1] += area;
  }
  if (across[1] > 1.25 * across[0]) return UpAxis::Z;
  if (across[0] > 1.25 * across[1]) return UpAxis::Y;
  throw Error(path, "cannot tell the up axis (" + std::to_string(across[0]) + " m^2 across y, " +
                        std::to_string(across[1]) + " m^2 across z): pass --up y or --up z");
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

// Why a file a scene names may not be opened, or "" when it may: only regular files (a scene
// naming /dev/zero or a FIFO must not hang or fill memory) within the size limit.
std::string refusalOf(const std::string& file, uint64_t maxBytes) {
  std::error_code ec;
  const fs::file_status st = fs::status(file, ec);  // follows symlinks: the target counts
  if (ec || !fs::exists(st)) return "no such file";
  if (!fs::is_regular_file(st)) return "not a regular file";
  const uint64_t bytes = fs::file_size(file, ec);
  if (ec) return "cannot read file size: " + ec.message();
  if (bytes > maxBytes)
    return "file is larger than the limit (" + std::to_string(bytes) + " bytes)";
  return "";
}

// assimp opens the scene and every file it names (mtllib, .bin buffers, external textures)
// through this: read-only, and only what refusalOf allows.
class LimitedIOSystem : public Assimp::DefaultIOSystem {
 public:
  explicit LimitedIOSystem(uint64_t maxBytes) : maxBytes_(maxBytes) {}
  bool Exists(const char* file) const override { return refusalOf(file, maxBytes_).empty(); }
  Assimp::IOStream* Open(const char* file, const char* mode = "rb") override {
    if (std::strpbrk(mode, "wa+") || !refusalOf(file, maxBytes_).empty()) return nullptr;
    return DefaultIOSystem::Open(file, mode);
  }

 private:
  uint64_t maxBytes_;
};

// Bytes one value of a PLY property type takes at least: its size in binary files, a digit and
// a separator in ASCII ones. 0 for an unknown type.
uint64_t plyValueBytes(const std::string& type, bool ascii) {
  static const std::map<std::string, uint64_t> sizes = {
      {"char", 1},  {"uchar", 1},   {"int8", 1},   {"uint8", 1},  {"short", 2}, {"ushort", 2},
      {"int16", 2}, {"uint16", 2},  {"int", 4},    {"uint", 4},   {"int32", 4}, {"uint32", 4},
      {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
  auto it = sizes.find(type);
  if (it == sizes.end()) return 0;
  return ascii ? 2 : it->second;
}

struct PlyProperty {
  std::string name;
  std::string type;       // of the value, or of a list's items
  std::string countType;  // of a list's length; empty for a scalar property
};
struct PlyElement {
  std::string name;
  uint64_t count = 0;
  uint64_t minBytes = 0;  // per instance
  std::vector<PlyProperty> properties;
};
struct PlyHeader {
  uint64_t bytes = 0;  // up to and including the end_header line
  std::string format;  // ascii, binary_little_endian or binary_big_endian
  std::vector<PlyElement> elements;
};

// Reads a PLY header strictly, and throws paircast::Error on anything but the keywords of the
// format, spaces and tabs: assimp 5.2.5 loops forever when it does not see end_header, and it
// splits lines differently from us (fuzz_scene_ply found "end_header\v" and a missing one).
PlyHeader readPlyHeader(const std::string& path) {
  constexpr uint64_t kMaxHeaderBytes = 1 << 16;
  std::ifstream in(path, std::ios::binary);
  PlyHeader h;
  std::string line;
  bool ended = false, ascii = false, hasFormat = false;
  for (int number = 1; !ended && h.bytes < kMaxHeaderBytes && std::getline(in, line); ++number) {
    h.bytes += line.size() + 1;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t'))
      line.pop_back();
    auto bad = [&](const std::string& why) {
      return Error(path,
                   "cannot load scene: PLY header line " + std::to_string(number) + ": " + why);
    };
    if (std::any_of(line.begin(), line.end(), [](char c) {
          return (static_cast<unsigned char>(c) < 0x20 && c != '\t') || c == 0x7f;
        }))
      throw bad("holds a control character");
    std::istringstream stream(line);
    std::vector<std::string> w;
    for (std::string t; stream >> t;) w.push_back(t);
    const std::string word = w.empty() ? "" : w[0];
    // Names are identifiers: assimp reads a name that starts with digits as the count
    // ("element 5555555555face 3" made it allocate 30 GB; fuzz_scene_ply found it).
    auto checkName = [&](const std::string& name) {
      if (name.empty() || !(std::isalpha(static_cast<unsigned char>(name[0])) || name[0] == '_') ||
          !std::all_of(name.begin(), name.end(), [](char c) {
            return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
          }))
        throw bad("'" + name + "' is not a name (letters, digits, '_' or '-', not first a digit)");
    };
    if (number == 1) {
      if (line != "ply") throw bad("not a PLY file (the first line is not 'ply')");
    } else if (line == "end_header") {
      ended = true;
    } else if (word == "comment" || word == "obj_info") {
      continue;
    } else if (word == "format") {
      if (w.size() != 3 || w[2] != "1.0") throw bad("expected 'format <type> 1.0'");
      if (w[1] != "ascii" && w[1] != "binary_little_endian" && w[1] != "binary_big_endian")
        throw bad("unknown format '" + w[1] + "'");
      ascii = w[1] == "ascii";
      h.format = w[1];
      hasFormat = true;
    } else if (word == "element") {
      if (!hasFormat) throw bad("element before the format line");
      if (w.size() != 3 || w[2].find_first_not_of("0123456789") != std::string::npos)
        throw bad("expected 'element <name> <count>'");
      checkName(w[1]);
      PlyElement e;
      e.name = w[1];
      errno = 0;
      e.count = std::strtoull(w[2].c_str(), nullptr, 10);
      if (errno == ERANGE) e.count = UINT64_MAX;
      h.elements.push_back(e);
    } else if (word == "property") {
      if (h.elements.empty()) throw bad("property before any element");
      const bool list = w.size() > 1 && w[1] == "list";
      if (w.size() != (list ? 5u : 3u))
        throw bad(list ? "expected 'property list <count type> <item type> <name>'"
                       : "expected 'property <type> <name>'");
      checkName(w.back());
      const std::string& type = w[list ? 2 : 1];
      if (list && plyValueBytes(w[3], ascii) == 0) throw bad("unknown type '" + w[3] + "'");
      const uint64_t bytes = plyValueBytes(type, ascii);  // a list may be empty: only its count
      if (bytes == 0) throw bad("unknown type '" + type + "'");
      h.elements.back().minBytes += bytes;
      h.elements.back().properties.push_back({w.back(), w[list ? 3 : 1], list ? type : ""});
    } else {
      throw bad("unknown keyword '" + word + "'");
    }
  }
  if (!ended)
    throw Error(path, "cannot load scene: PLY header has no end_header line in its first " +
                          std::to_string(kMaxHeaderBytes) + " bytes");
  return h;
}

// A PLY header states its element counts before the data, and assimp allocates (and zeroes)
// that many vertices before reading one: a 200-byte file claiming 3e8 vertices made it touch
// 9 GB for 195 s. Counts the rest of the file cannot hold, and counts over the limits, are
// refused here.
PlyHeader checkPlyHeader(const std::string& path, uint64_t fileBytes, const LoadOptions& options) {
  PlyHeader h = readPlyHeader(path);
  const uint64_t body = fileBytes > h.bytes ? fileBytes - h.bytes : 0;
  for (const PlyElement& e : h.elements) {
    const uint64_t atMost = body / std::max<uint64_t>(e.minBytes, 1);
    if (e.count > atMost)
      throw Error(path, "cannot load scene: PLY header claims " + std::to_string(e.count) + " '" +
                            e.name + "' elements, but the " + std::to_string(body) +
                            " bytes after the header hold at most " + std::to_string(atMost) +
                            " (truncated or corrupt file)");
    if (e.name == "vertex" && e.count > options.maxVertices)
      throw Error(path, "PLY header claims " + std::to_string(e.count) +
                            " vertices, more than the limit of " +
                            std::to_string(options.maxVertices));
    if (e.name == "face" && e.count > options.maxTriangles)
      throw Error(path, "PLY header claims " + std::to_string(e.count) +
                            " faces, more than the limit of " +
                            std::to_string(options.maxTriangles));
  }
  return h;
}

// The binary little-endian PLY files that scans ship (ScanNet's *_vh_clean_2.ply, Replica's
// mesh.ply) are read here directly: assimp's PLY importer keeps every property of every vertex
// in generic containers and took most of the load time and memory of a million-triangle scan.
enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

PlyType plyType(const std::string& type) {
  static const std::map<std::string, PlyType> types = {
      {"char", PlyType::Int8},      {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
      {"uint8", PlyType::UInt8},    {"short", PlyType::Int16},     {"int16", PlyType::Int16},
      {"ushort", PlyType::UInt16},  {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
      {"int32", PlyType::Int32},    {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
      {"float", PlyType::Float32},  {"float32", PlyType::Float32}, {"double", PlyType::Float64},
      {"float64", PlyType::Float64}};
  return types.at(type);  // readPlyHeader accepted only these
}

size_t plySize(PlyType t) {
  static constexpr size_t sizes[] = {1, 1, 2, 2, 4, 4, 4, 8};
  return sizes[static_cast<int>(t)];
}

// A value of type T from unaligned bytes.
template <class T>
T loadUnaligned(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

double plyRead(PlyType t, const char* p) {
  switch (t) {
    case PlyType::Int8:
      return static_cast<int8_t>(*p);
    case PlyType::UInt8:
      return static_cast<uint8_t>(*p);
    case PlyType::Int16:
      return loadUnaligned<int16_t>(p);
    case PlyType::UInt16:
      return loadUnaligned<uint16_t>(p);
    case PlyType::Int32:
      return loadUnaligned<int32_t>(p);
    case PlyType::UInt32:
      return loadUnaligned<uint32_t>(p);
    case PlyType::Float32:
      return loadUnaligned<float>(p);
    case PlyType::Float64:
      return loadUnaligned<double>(p);
  }
  return 0;
}

bool isIntegerType(PlyType t) {
  return t != PlyType::Float32 && t != PlyType::Float64;
}

// Whether the fast reader handles the file: binary little-endian, one vertex element with x y z,
// one face element whose only list is the vertex indices, and no other lists.
bool plyFastPathApplies(const PlyHeader& h) {
  if (h.format != "binary_little_endian") return false;
  int vertexElements = 0, faceElements = 0;
  for (const PlyElement& e : h.elements) {
    int lists = 0, xyz = 0;
    for (const PlyProperty& p : e.properties) {
      if (!p.countType.empty()) {
        if (e.name != "face" || (p.name != "vertex_indices" && p.name != "vertex_index") ||
            !isIntegerType(plyType(p.type)) || !isIntegerType(plyType(p.countType)))
          return false;
        ++lists;
      }
      xyz += p.name == "x" || p.name == "y" || p.name == "z";
    }
    if (e.name == "vertex") {
      ++vertexElements;
      if (xyz != 3) return false;
    } else if (e.name == "face") {
      ++faceElements;
      if (lists != 1) return false;
    } else if (lists != 0) {
      return false;
    }
  }
  return vertexElements == 1 && faceElements == 1;
}

// Reads the body of a PLY file plyFastPathApplies accepted into `mesh` (positions scaled, sRGB
// 8-bit colours made linear, polygons fanned into triangles, one white material). Every count,
// length and index is checked against the bytes there are and the vertices read.
void readBinaryPly(const std::string& path, const PlyHeader& h, const LoadOptions& options,
                   Mesh& mesh) {
  const std::string data = readFile(path);  // within maxFileBytes, checked by the caller
  const char* const end = data.data() + data.size();
  const char* p = data.data() + std::min<uint64_t>(h.bytes, data.size());
  auto truncated = [&](const PlyElement& e, uint64_t index) {
    return Error(path, "cannot load scene: PLY file is truncated: it ends in '" + e.name +
                           "' element " + std::to_string(index) + " of " + std::to_string(e.count));
  };
  const float scale = static_cast<float>(options.scale);
  std::array<float, 256> linear;
  for (int i = 0; i < 256; ++i) linear[i] = srgbToLinear(i / 255.0f);
  mesh.addMaterial(Material{});
  uint64_t vertexCount = 0;
  bool verticesRead = false;
  for (const PlyElement& e : h.elements) {
    std::vector<PlyType> types;
    std::vector<size_t> offsets;
    size_t stride = 0;
    for (const PlyProperty& prop : e.properties) {
      types.push_back(plyType(prop.type));
      offsets.push_back(stride);
      stride += prop.countType.empty() ? plySize(types.back()) : 0;
    }
    if (e.name != "face") {  // fixed-size records
      if (e.count > static_cast<uint64_t>(end - p) / std::max<size_t>(stride, 1))
        throw truncated(e, static_cast<uint64_t>(end - p) / std::max<size_t>(stride, 1));
      if (e.name == "vertex") {
        int x = -1, y = -1, z = -1, r = -1, g = -1, b = -1;
        for (size_t k = 0; k < e.properties.size(); ++k) {
          const std::string& n = e.properties[k].name;
          const int ik = static_cast<int>(k);
          if (n == "x") x = ik;
          if (n == "y") y = ik;
          if (n == "z") z = ik;
          if (n == "red" || n == "diffuse_red") r = ik;
          if (n == "green" || n == "diffuse_green") g = ik;
          if (n == "blue" || n == "diffuse_blue") b = ik;
        }
        const bool rgb8 = r >= 0 && g >= 0 && b >= 0 && types[r] == PlyType::UInt8 &&
                          types[g] == PlyType::UInt8 && types[b] == PlyType::UInt8;
        const bool rgbFloat = !rgb8 && r >= 0 && g >= 0 && b >= 0;
        mesh.positions.resize(e.count);
        mesh.uvs.assign(e.count, Eigen::Vector2f::Zero());
        mesh.colors.resize(e.count);
        auto channel = [&](const char* rec, int k) {
          return srgbToLinear(std::clamp(static_cast<float>(plyRead(types[k], rec + offsets[k])) /
                                             (isIntegerType(types[k]) ? 255.0f : 1.0f),
                                         0.0f, 1.0f));
        };
        for (uint64_t i = 0; i < e.count; ++i, p += stride) {
          mesh.positions[i] = scale * Eigen::Vector3f(plyRead(types[x], p + offsets[x]),
                                                      plyRead(types[y], p + offsets[y]),
                                                      plyRead(types[z], p + offsets[z]));
          if (rgb8)
            mesh.colors[i] = {linear[static_cast<uint8_t>(p[offsets[r]])],
                              linear[static_cast<uint8_t>(p[offsets[g]])],
                              linear[static_cast<uint8_t>(p[offsets[b]])]};
          else if (rgbFloat)
            mesh.colors[i] = {channel(p, r), channel(p, g), channel(p, b)};
          else
            mesh.colors[i].setOnes();
        }
        vertexCount = e.count;
        verticesRead = true;
      } else {
        p += e.count * stride;
      }
      continue;
    }
    if (!verticesRead)
      throw Error(path, "cannot load scene: PLY faces come before the vertices they index");
    mesh.triangles.reserve(std::min<uint64_t>(e.count, options.maxTriangles));
    for (uint64_t f = 0; f < e.count; ++f) {
      for (size_t k = 0; k < types.size(); ++k) {
        if (e.properties[k].countType.empty()) {
          if (static_cast<size_t>(end - p) < plySize(types[k])) throw truncated(e, f);
          p += plySize(types[k]);
          continue;
        }
        const PlyType countType = plyType(e.properties[k].countType);
        if (static_cast<size_t>(end - p) < plySize(countType)) throw truncated(e, f);
        const double n = plyRead(countType, p);
        p += plySize(countType);
        if (n < 0 || n > static_cast<double>(end - p) / plySize(types[k])) throw truncated(e, f);
        const size_t corners = static_cast<size_t>(n), itemSize = plySize(types[k]);
        auto index = [&](size_t c) {
          const double v = plyRead(types[k], p + c * itemSize);
          if (v < 0 || v >= static_cast<double>(vertexCount))
            throw Error(path, "cannot load scene: PLY face " + std::to_string(f) +
                                  " has vertex index " + std::to_string(static_cast<int64_t>(v)) +
                                  ", but the file has " + std::to_string(vertexCount) +
                                  " vertices");
          return static_cast<int>(v);
        };
        // Points and lines are dropped, as assimp's SortByPType does; polygons become fans.
        for (size_t c = 2; c < corners; ++c) {
          if (mesh.triangles.size() >= options.maxTriangles)
            throw Error(path, "scene has more than " + std::to_string(options.maxTriangles) +
                                  " triangles (the limit)");
          mesh.triangles.emplace_back(index(0), index(c - 1), index(c));
        }
        p += corners * itemSize;
      }
    }
  }
  mesh.triangleMaterial.assign(mesh.triangles.size(), 0);
}

// assimp 5.2.5 takes strchr(mimeType, '/') + 1 for an embedded image without checking it, so a
// media type without '/' makes it read address 1 (fuzz_scene_glb found it). The glTF JSON is
// parsed here first: it must be valid JSON (UTF-8 included), and every image's media type
// (mimeType, or that of a data: URI) must be "type/subtype".
//
// It also looks at the extensions the habitat datasets use that assimp 5.2.5 does not decode:
// EXT_meshopt_compression buffers are refused (assimp would read the uncompressed fallback,
// often empty or garbage, and render garbled geometry silently); Basis Universal textures
// (GOOGLE_texture_basis, KHR_texture_basisu) are reported, so that the scene renders with its
// base colours and one warning. KHR_draco_mesh_compression is decoded by Debian's assimp.
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

struct GltfCheck {
  std::string basisExtension;  // the Basis Universal extension the textures use, or ""
};

GltfCheck checkGltfJson(const std::string& path, const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object())
    throw Error(path, "cannot load scene: the glTF JSON is not a valid JSON object");
  GltfCheck check;
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
  checkDracoIndices(path, j);
  const auto images = j.find("images");
  if (images == j.end()) return check;
  if (!images->is_array()) throw Error(path, "cannot load scene: glTF 'images' is not an array");
  for (size_t i = 0; i < images->size(); ++i) {
    const nlohmann::json& image = (*images)[i];
    std::string type;
    bool has = false;
    if (image.is_object() && image.contains("mimeType")) {
      has = true;
      type = image["mimeType"].is_string() ? image["mimeType"].get<std::string>() : "";
    } else if (image.is_object() && image.contains("uri") && image["uri"].is_string() &&
               image["uri"].get<std::string>().rfind("data:", 0) == 0) {
      has = true;
      const std::string uri = image["uri"];
      type = uri.substr(5, uri.find_first_of(";,") - 5);
    }
    const size_t slash = type.find('/');
    if (has && (slash == std::string::npos || slash == 0 || slash + 1 == type.size()))
      throw Error(path, "cannot load scene: glTF image " + std::to_string(i) + " has media type '" +
                            type.substr(0, 64) + "', not type/subtype");
  }
  return check;
}

uint32_t le32(const unsigned char* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// A binary glTF states its chunk lengths up front, and assimp allocates a chunk before reading
// it: a 1 KB file claiming a 4 GB JSON chunk made it ask for 4 GB (fuzz_scene_glb found it).
// Lengths the file cannot hold are refused here; files without the glTF magic are left to
// assimp.
GltfCheck checkGlbHeader(const std::string& path, uint64_t fileBytes) {
  std::ifstream in(path, std::ios::binary);
  unsigned char header[20];
  GltfCheck check;
  if (!in.read(reinterpret_cast<char*>(header), 12) || std::memcmp(header, "glTF", 4) != 0)
    return check;
  const uint32_t version = le32(header + 4), length = le32(header + 8);
  if (length > fileBytes)
    throw Error(path, "cannot load scene: GLB header claims " + std::to_string(length) +
                          " bytes, the file has " + std::to_string(fileBytes));
  if (version == 1) {  // magic, version, length, content length, content format
    if (in.read(reinterpret_cast<char*>(header + 12), 8) && le32(header + 12) > fileBytes - 20)
      throw Error(path, "cannot load scene: GLB header claims a " +
                            std::to_string(le32(header + 12)) +
                            "-byte scene, more than the file holds");
    return check;
  }
  for (uint64_t offset = 12; offset + 8 <= fileBytes;) {  // chunks: length, type, data
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

// assimp's validation messages name its own structures: say what they mean for the file too.
std::string explainAssimpError(const std::string& message) {
  if (message.find("contains no faces") != std::string::npos ||
      message.find("No meshes remaining") != std::string::npos)
    return "scene has no triangles (assimp: " + message + ")";
  if (message.find("mIndices") != std::string::npos &&
      message.find("out of range") != std::string::npos)
    return "a face has a vertex index out of range (assimp: " + message + ")";
  return message;
}

// Converts one assimp material and its texture to ours, loading each texture file once.
class MaterialBuilder {
 public:
  MaterialBuilder(const aiScene* scene, const std::string& path, uint64_t maxFileBytes,
                  bool noTextures, Mesh& mesh, std::vector<std::string>& warnings)
      : scene_(scene),
        path_(path),
        dir_(fs::path(path).parent_path()),
        maxFileBytes_(maxFileBytes),
        noTextures_(noTextures),
        mesh_(mesh),
        warnings_(warnings) {}

  int build(const aiMaterial* in) {
    Material m;
    aiString name;
    if (in->Get(AI_MATKEY_NAME, name) == AI_SUCCESS) m.name = name.C_Str();
    aiColor4D color;
    if (in->Get(AI_MATKEY_BASE_COLOR, color) == AI_SUCCESS ||
        in->Get(AI_MATKEY_COLOR_DIFFUSE, color) == AI_SUCCESS) {
      m.baseColor = Eigen::Vector3f(color.r, color.g, color.b).cwiseMax(0.0f).cwiseMin(1.0f);
    }
    aiString texPath;
    if (noTextures_) return mesh_.addMaterial(m);
    if (in->GetTexture(aiTextureType_BASE_COLOR, 0, &texPath) == AI_SUCCESS ||
        in->GetTexture(aiTextureType_DIFFUSE, 0, &texPath) == AI_SUCCESS) {
      m.texture = texture(texPath.C_Str());
      // A texture is modulated by the factor; OBJ files often set Kd to 0 with a map_Kd.
      if (m.texture >= 0 && m.baseColor.maxCoeff() <= 0.0f) m.baseColor.setOnes();
    }
    return mesh_.addMaterial(m);
  }

 private:
  int texture(const std::string& ref) {
    auto it = cache_.find(ref);
    if (it != cache_.end()) return it->second;
    int index = -1;
    try {
      Texture t;
      t.name = ref;
      Image8 img;
      if (const aiTexture* emb = scene_->GetEmbeddedTexture(ref.c_str())) {
        if (emb->mHeight == 0) {  // compressed (png/jpg) bytes
          img =
              decodeImage8(emb->pcData, emb->mWidth, path_ + ":" + ref + "." + emb->achFormatHint);
        } else {  // raw BGRA texels
          img = Image8(emb->mWidth, emb->mHeight, 3);
          for (size_t i = 0; i < size_t(emb->mWidth) * emb->mHeight; ++i) {
            img.data[3 * i] = emb->pcData[i].r;
            img.data[3 * i + 1] = emb->pcData[i].g;
            img.data[3 * i + 2] = emb->pcData[i].b;
          }
        }
      } else {
        std::string rel = ref;
        for (auto& c : rel)
          if (c == '\\') c = '/';
        const std::string file = (dir_ / rel).string();
        const std::string refusal = refusalOf(file, maxFileBytes_);
        if (!refusal.empty()) throw Error(file, refusal);
        img = readImage8(file);
      }
      t.width = img.width;
      t.height = img.height;
      t.channels = 3;
      t.texels = std::move(img.data);
      mesh_.textures.push_back(std::move(t));
      index = static_cast<int>(mesh_.textures.size()) - 1;
    } catch (const Error& e) {
      // A missing texture should not lose the scene: fall back to the colour factor.
      warnings_.push_back(std::string("texture skipped: ") + e.what());
    }
    cache_[ref] = index;
    return index;
  }

  const aiScene* scene_;
  std::string path_;
  fs::path dir_;
  uint64_t maxFileBytes_;
  bool noTextures_;  // the textures are Basis Universal: base colours only, warned about once
  Mesh& mesh_;
  std::vector<std::string>& warnings_;
  std::map<std::string, int> cache_;
};

// Sets each mesh's primitive-type flags from its faces. Importers can get them wrong (assimp's
// PLY importer flags a mesh as holding polygons when it holds none), and TriangulateProcess then
// fails an ai_assert, which Debian's assimp 5.2.5 build turns into abort(): a bad file would kill
// the process (fuzz_scene_ply found it).
void setPrimitiveTypesFromFaces(aiScene* scene, const std::string& path) {
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    aiMesh* m = scene->mMeshes[i];
    unsigned types = 0;
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const unsigned n = m->mFaces[f].mNumIndices;
      // TriangulateProcess counts such a face as a triangle and fails the same assertion.
      if (n == 0) throw Error(path, "mesh " + std::to_string(i) + " has a face without vertices");
      types |= n == 1   ? aiPrimitiveType_POINT
               : n == 2 ? aiPrimitiveType_LINE
               : n == 3 ? aiPrimitiveType_TRIANGLE
                        : aiPrimitiveType_POLYGON;
    }
    m->mPrimitiveTypes = types;
  }
}

// What appendNode needs besides the node: the same for the whole tree.
struct AppendContext {
  const aiScene* scene;
  const std::string& path;
  const LoadOptions& options;
  const std::vector<int>& materialMap;
  bool linearVertexColors;
};

void appendNode(const AppendContext& ctx, const aiNode* node, const aiMatrix4x4& parent,
                Mesh& out) {
  const aiScene* scene = ctx.scene;
  const float scale = static_cast<float>(ctx.options.scale);
  const aiMatrix4x4 world = parent * node->mTransformation;
  for (unsigned k = 0; k < node->mNumMeshes; ++k) {
    const aiMesh* m = scene->mMeshes[node->mMeshes[k]];
    if (!(m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    // A mesh referenced by many nodes is instanced once per node: check before growing.
    if (out.triangles.size() + m->mNumFaces > ctx.options.maxTriangles ||
        out.positions.size() + m->mNumVertices > ctx.options.maxVertices)
      throw Error(ctx.path, "scene has more than " + std::to_string(ctx.options.maxTriangles) +
                                " triangles or " + std::to_string(ctx.options.maxVertices) +
                                " vertices (the limits) after instancing");
    const int base = static_cast<int>(out.positions.size());
    for (unsigned i = 0; i < m->mNumVertices; ++i) {
      aiVector3D p = world * m->mVertices[i];
      out.positions.emplace_back(p.x * scale, p.y * scale, p.z * scale);
      if (m->HasTextureCoords(0))
        out.uvs.emplace_back(m->mTextureCoords[0][i].x, m->mTextureCoords[0][i].y);
      else
        out.uvs.emplace_back(0.0f, 0.0f);
      if (m->HasVertexColors(0)) {
        const aiColor4D& c = m->mColors[0][i];
        Eigen::Vector3f rgb = Eigen::Vector3f(c.r, c.g, c.b).cwiseMax(0.0f).cwiseMin(1.0f);
        if (!ctx.linearVertexColors)
          rgb =
              Eigen::Vector3f(srgbToLinear(rgb.x()), srgbToLinear(rgb.y()), srgbToLinear(rgb.z()));
        out.colors.push_back(rgb);
      } else {
        out.colors.emplace_back(1.0f, 1.0f, 1.0f);
      }
    }
    if (m->mMaterialIndex >= ctx.materialMap.size())
      throw Error(ctx.path, "a mesh names material " + std::to_string(m->mMaterialIndex) +
                                ", which the file does not have");
    const int material = ctx.materialMap[m->mMaterialIndex];
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines left by SortByPType
      out.triangles.emplace_back(base + face.mIndices[0], base + face.mIndices[1],
                                 base + face.mIndices[2]);
      out.triangleMaterial.push_back(material);
    }
  }
  for (unsigned c = 0; c < node->mNumChildren; ++c) appendNode(ctx, node->mChildren[c], world, out);
}

}  // namespace

Scene loadScene(const std::string& path, const LoadOptions& options) {
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

  Scene out;
  out.path = path;
  out.name = fs::path(path).stem().string();
  out.up = options.up;
  // The checks every loader ends with: no triangles, bad indices, non-finite vertices.
  auto checked = [&](Scene& scene) {
    if (scene.mesh.numTriangles() == 0) throw Error(path, "scene has no triangles");
    scene.mesh.validate(path);
    if (scene.up == UpAxis::Auto) scene.up = guessUpAxis(scene.mesh, path);
    return std::move(scene);
  };

  const std::string ext = lower(fs::path(path).extension().string());
  if (ext == ".ply") {
    const PlyHeader header = checkPlyHeader(path, bytes, options);
    if (options.plyFastPath && plyFastPathApplies(header)) {
      readBinaryPly(path, header, options, out.mesh);
      return checked(out);
    }
  }
  GltfCheck gltf;
  if (ext == ".glb") gltf = checkGlbHeader(path, bytes);
  if (ext == ".gltf") gltf = checkGltfJson(path, readFile(path));  // within maxFileBytes
  if (!gltf.basisExtension.empty())
    out.warnings.push_back(path + ": textures use " + gltf.basisExtension +
                           " (Basis Universal), which paircast cannot decode: rendering with base "
                           "colours; for textures use the plain .glb with JPEG textures (HM3D "
                           "ships both)");

  Assimp::Importer importer;
  importer.SetIOHandler(new LimitedIOSystem(options.maxFileBytes));  // the importer owns it
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  // Two steps: read and validate, repair the primitive-type flags, then post-process (see
  // setPrimitiveTypesFromFaces).
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, aiProcess_ValidateDataStructure);
    if (scene && scene->mRootNode && !(scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE)) {
      setPrimitiveTypesFromFaces(const_cast<aiScene*>(scene), path);  // the importer owns the scene
      scene = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_SortByPType);
    }
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path, "cannot load scene: " + explainAssimpError(e.what()));
  }
  if (!scene)
    throw Error(path, "cannot load scene: " + explainAssimpError(importer.GetErrorString()));
  if (!scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE))
    throw Error(path, "scene is incomplete or has no geometry");

  size_t triangles = 0, vertices = 0;
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    triangles += scene->mMeshes[i]->mNumFaces;
    vertices += scene->mMeshes[i]->mNumVertices;
  }
  if (triangles > options.maxTriangles)
    throw Error(path, "scene has " + std::to_string(triangles) + " faces, more than the limit of " +
                          std::to_string(options.maxTriangles));
  if (vertices > options.maxVertices)
    throw Error(path, "scene has " + std::to_string(vertices) +
                          " vertices, more than the limit of " +
                          std::to_string(options.maxVertices));

  out.mesh.positions.reserve(vertices);
  out.mesh.triangles.reserve(triangles);

  MaterialBuilder materials(scene, path, options.maxFileBytes, !gltf.basisExtension.empty(),
                            out.mesh, out.warnings);
  std::vector<int> materialMap;
  for (unsigned i = 0; i < scene->mNumMaterials; ++i)
    materialMap.push_back(materials.build(scene->mMaterials[i]));
  if (materialMap.empty()) materialMap.push_back(out.mesh.addMaterial(Material{}));

  const bool linearVertexColors = ext == ".glb" || ext == ".gltf";
  appendNode(AppendContext{scene, path, options, materialMap, linearVertexColors}, scene->mRootNode,
             aiMatrix4x4(), out.mesh);
  return checked(out);
}

}  // namespace paircast
