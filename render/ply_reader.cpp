#include "render/ply_reader.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

// ---- the property types ----

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

// The one table of PLY property types: each name the format allows, its type, and its size in
// binary files.
struct PlyTypeName {
  const char* name;
  PlyType type;
  uint8_t bytes;
};
constexpr PlyTypeName kPlyTypes[] = {
    {"char", PlyType::Int8, 1},      {"int8", PlyType::Int8, 1},
    {"uchar", PlyType::UInt8, 1},    {"uint8", PlyType::UInt8, 1},
    {"short", PlyType::Int16, 2},    {"int16", PlyType::Int16, 2},
    {"ushort", PlyType::UInt16, 2},  {"uint16", PlyType::UInt16, 2},
    {"int", PlyType::Int32, 4},      {"int32", PlyType::Int32, 4},
    {"uint", PlyType::UInt32, 4},    {"uint32", PlyType::UInt32, 4},
    {"float", PlyType::Float32, 4},  {"float32", PlyType::Float32, 4},
    {"double", PlyType::Float64, 8}, {"float64", PlyType::Float64, 8}};

// The sizes by type, from the table.
constexpr std::array<uint8_t, 8> kPlySizes = [] {
  std::array<uint8_t, 8> sizes{};
  for (const PlyTypeName& t : kPlyTypes) sizes[static_cast<int>(t.type)] = t.bytes;
  return sizes;
}();

// The table's entry for `type`, or null for an unknown type.
const PlyTypeName* findPlyType(const std::string& type) {
  for (const PlyTypeName& t : kPlyTypes)
    if (type == t.name) return &t;
  return nullptr;
}

// Bytes one value of a PLY property type takes at least: its size in binary files, a digit and
// a separator in ASCII ones. 0 for an unknown type.
uint64_t plyValueBytes(const std::string& type, bool ascii) {
  const PlyTypeName* t = findPlyType(type);
  if (!t) return 0;
  return ascii ? 2 : t->bytes;
}

PlyType plyType(const std::string& type) {
  const PlyTypeName* t = findPlyType(type);
  PAIRCAST_CHECK_MSG(t, "unknown PLY type '" << type << "'");  // readPlyHeader accepted only these
  return t->type;
}

size_t plySize(PlyType t) {
  return kPlySizes[static_cast<int>(t)];
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

// ---- the header ----

// Reads the header line by line, each checked as it comes.
class PlyHeaderParser {
 public:
  explicit PlyHeaderParser(const std::string& path) : path_(path) {}

  PlyHeader parse() {
    constexpr uint64_t kMaxHeaderBytes = 1 << 16;
    std::ifstream in(path_, std::ios::binary);
    std::string line;
    for (number_ = 1; !ended_ && h_.bytes < kMaxHeaderBytes && std::getline(in, line); ++number_) {
      h_.bytes += line.size() + 1;
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t'))
        line.pop_back();
      parseLine(line);
    }
    if (!ended_)
      throw Error(path_, "cannot load scene: PLY header has no end_header line in its first " +
                             std::to_string(kMaxHeaderBytes) + " bytes");
    return h_;
  }

 private:
  Error bad(const std::string& why) const {
    return Error(path_,
                 "cannot load scene: PLY header line " + std::to_string(number_) + ": " + why);
  }

  void parseLine(const std::string& line) {
    if (std::any_of(line.begin(), line.end(), [](char c) {
          return (static_cast<unsigned char>(c) < 0x20 && c != '\t') || c == 0x7f;
        }))
      throw bad("holds a control character");
    std::istringstream stream(line);
    std::vector<std::string> w;
    for (std::string t; stream >> t;) w.push_back(t);
    const std::string word = w.empty() ? "" : w[0];
    if (number_ == 1) {
      if (line != "ply") throw bad("not a PLY file (the first line is not 'ply')");
    } else if (line == "end_header") {
      ended_ = true;
    } else if (word == "comment" || word == "obj_info") {
      return;
    } else if (word == "format") {
      format(w);
    } else if (word == "element") {
      element(w);
    } else if (word == "property") {
      property(w);
    } else {
      throw bad("unknown keyword '" + word + "'");
    }
  }

  // Names are identifiers: assimp reads a name that starts with digits as the count
  // ("element 5555555555face 3" made it allocate 30 GB; fuzz_scene_ply found it).
  void checkName(const std::string& name) const {
    if (name.empty() || !(std::isalpha(static_cast<unsigned char>(name[0])) || name[0] == '_') ||
        !std::all_of(name.begin(), name.end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
        }))
      throw bad("'" + name + "' is not a name (letters, digits, '_' or '-', not first a digit)");
  }

  void format(const std::vector<std::string>& w) {
    if (w.size() != 3 || w[2] != "1.0") throw bad("expected 'format <type> 1.0'");
    if (w[1] != "ascii" && w[1] != "binary_little_endian" && w[1] != "binary_big_endian")
      throw bad("unknown format '" + w[1] + "'");
    ascii_ = w[1] == "ascii";
    h_.format = w[1];
    hasFormat_ = true;
  }

  void element(const std::vector<std::string>& w) {
    if (!hasFormat_) throw bad("element before the format line");
    if (w.size() != 3 || w[2].find_first_not_of("0123456789") != std::string::npos)
      throw bad("expected 'element <name> <count>'");
    checkName(w[1]);
    PlyElement e;
    e.name = w[1];
    errno = 0;
    e.count = std::strtoull(w[2].c_str(), nullptr, 10);
    if (errno == ERANGE) e.count = UINT64_MAX;
    h_.elements.push_back(e);
  }

  void property(const std::vector<std::string>& w) {
    if (h_.elements.empty()) throw bad("property before any element");
    const bool list = w.size() > 1 && w[1] == "list";
    if (w.size() != (list ? 5u : 3u))
      throw bad(list ? "expected 'property list <count type> <item type> <name>'"
                     : "expected 'property <type> <name>'");
    checkName(w.back());
    const std::string& type = w[list ? 2 : 1];
    if (list && plyValueBytes(w[3], ascii_) == 0) throw bad("unknown type '" + w[3] + "'");
    const uint64_t bytes = plyValueBytes(type, ascii_);  // a list may be empty: only its count
    if (bytes == 0) throw bad("unknown type '" + type + "'");
    h_.elements.back().minBytes += bytes;
    h_.elements.back().properties.push_back({w.back(), w[list ? 3 : 1], list ? type : ""});
  }

  const std::string& path_;
  PlyHeader h_;
  int number_ = 0;  // of the line being read
  bool ended_ = false, ascii_ = false, hasFormat_ = false;
};

// ---- the binary body ----

// Where each property of an element lies in its records.
struct PlyLayout {
  std::vector<PlyType> types;
  std::vector<size_t> offsets;  // of scalar properties, in a fixed-size record
  size_t stride = 0;            // bytes of a fixed-size record (lists count 0)

  explicit PlyLayout(const PlyElement& e) {
    for (const PlyProperty& prop : e.properties) {
      types.push_back(plyType(prop.type));
      offsets.push_back(stride);
      stride += prop.countType.empty() ? plySize(types.back()) : 0;
    }
  }
};

// The vertex properties the mesh keeps, by index into the element's properties (-1: none).
struct PlyVertexFields {
  int x = -1, y = -1, z = -1, r = -1, g = -1, b = -1;

  explicit PlyVertexFields(const PlyElement& e) {
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
  }
};

// Reads the elements in order, with p_ at the next byte to read.
class BinaryPlyReader {
 public:
  BinaryPlyReader(const std::string& path, const std::string& data, uint64_t headerBytes,
                  const LoadOptions& options, Mesh& mesh)
      : path_(path),
        options_(options),
        mesh_(mesh),
        p_(data.data() + std::min<uint64_t>(headerBytes, data.size())),
        end_(data.data() + data.size()) {}

  void read(const PlyHeader& h) {
    mesh_.addMaterial(Material{});
    for (const PlyElement& e : h.elements) {
      const PlyLayout layout(e);
      if (e.name != "face")
        readRecords(e, layout);
      else
        readFaces(e, layout);
    }
    mesh_.triangleMaterial.assign(mesh_.triangles.size(), 0);
  }

 private:
  Error truncated(const PlyElement& e, uint64_t index) const {
    return Error(path_, "cannot load scene: PLY file is truncated: it ends in '" + e.name +
                            "' element " + std::to_string(index) + " of " +
                            std::to_string(e.count));
  }
  size_t left() const { return static_cast<size_t>(end_ - p_); }

  // An element of fixed-size records: the vertices are read, others skipped.
  void readRecords(const PlyElement& e, const PlyLayout& layout) {
    const uint64_t fit = static_cast<uint64_t>(end_ - p_) / std::max<size_t>(layout.stride, 1);
    if (e.count > fit) throw truncated(e, fit);
    if (e.name == "vertex")
      readVertices(e, layout);
    else
      p_ += e.count * layout.stride;
  }

  void readVertices(const PlyElement& e, const PlyLayout& layout) {
    const std::vector<PlyType>& types = layout.types;
    const std::vector<size_t>& offsets = layout.offsets;
    const PlyVertexFields v(e);
    const bool rgb = v.r >= 0 && v.g >= 0 && v.b >= 0;
    const bool rgb8 = rgb && types[v.r] == PlyType::UInt8 && types[v.g] == PlyType::UInt8 &&
                      types[v.b] == PlyType::UInt8;
    const float scale = static_cast<float>(options_.scale);
    const std::array<float, 256>& linear = kSrgb8ToLinear;
    auto value = [&](const char* rec, int k) { return plyRead(types[k], rec + offsets[k]); };
    auto channel = [&](const char* rec, int k) {
      return srgbToLinear(
          std::clamp(static_cast<float>(value(rec, k)) / (isIntegerType(types[k]) ? 255.0f : 1.0f),
                     0.0f, 1.0f));
    };
    auto byte = [&](const char* rec, int k) { return static_cast<uint8_t>(rec[offsets[k]]); };
    mesh_.positions.resize(e.count);
    mesh_.uvs.assign(e.count, Eigen::Vector2f::Zero());
    mesh_.colors.resize(e.count);
    for (uint64_t i = 0; i < e.count; ++i, p_ += layout.stride) {
      mesh_.positions[i] = scale * Eigen::Vector3f(value(p_, v.x), value(p_, v.y), value(p_, v.z));
      if (rgb8)
        mesh_.colors[i] = {linear[byte(p_, v.r)], linear[byte(p_, v.g)], linear[byte(p_, v.b)]};
      else if (rgb)
        mesh_.colors[i] = {channel(p_, v.r), channel(p_, v.g), channel(p_, v.b)};
      else
        mesh_.colors[i].setOnes();
    }
    vertexCount_ = e.count;
    verticesRead_ = true;
  }

  void readFaces(const PlyElement& e, const PlyLayout& layout) {
    if (!verticesRead_)
      throw Error(path_, "cannot load scene: PLY faces come before the vertices they index");
    mesh_.triangles.reserve(std::min<uint64_t>(e.count, options_.maxTriangles));
    for (uint64_t f = 0; f < e.count; ++f) {
      for (size_t k = 0; k < layout.types.size(); ++k) {
        const PlyType type = layout.types[k];
        if (!e.properties[k].countType.empty()) {
          readFaceList(e, f, plyType(e.properties[k].countType), type);
          continue;
        }
        if (left() < plySize(type)) throw truncated(e, f);
        p_ += plySize(type);
      }
    }
  }

  // Face f's list of vertex indices: points and lines are dropped, as assimp's SortByPType
  // does; polygons become fans.
  void readFaceList(const PlyElement& e, uint64_t f, PlyType countType, PlyType itemType) {
    if (left() < plySize(countType)) throw truncated(e, f);
    const double n = plyRead(countType, p_);
    p_ += plySize(countType);
    const size_t itemSize = plySize(itemType);
    if (n < 0 || n > static_cast<double>(end_ - p_) / itemSize) throw truncated(e, f);
    const size_t corners = static_cast<size_t>(n);
    auto index = [&](size_t c) {
      const double v = plyRead(itemType, p_ + c * itemSize);
      if (v < 0 || v >= static_cast<double>(vertexCount_))
        throw Error(path_, "cannot load scene: PLY face " + std::to_string(f) +
                               " has vertex index " + std::to_string(static_cast<int64_t>(v)) +
                               ", but the file has " + std::to_string(vertexCount_) + " vertices");
      return static_cast<int>(v);
    };
    for (size_t c = 2; c < corners; ++c) {
      if (mesh_.triangles.size() >= options_.maxTriangles)
        throw Error(path_, "scene has more than " + std::to_string(options_.maxTriangles) +
                               " triangles (the limit)");
      mesh_.triangles.emplace_back(index(0), index(c - 1), index(c));
    }
    p_ += corners * itemSize;
  }

  const std::string& path_;
  const LoadOptions& options_;
  Mesh& mesh_;
  const char* p_;
  const char* const end_;
  uint64_t vertexCount_ = 0;
  bool verticesRead_ = false;
};

// Whether element e fits the fast reader (see plyFastPathApplies); counts its lists and x y z.
bool plyFastPathFits(const PlyElement& e) {
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
  if (e.name == "vertex") return xyz == 3;
  if (e.name == "face") return lists == 1;
  return lists == 0;
}

}  // namespace

PlyHeader readPlyHeader(const std::string& path) {
  return PlyHeaderParser(path).parse();
}

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

bool plyFastPathApplies(const PlyHeader& h) {
  if (h.format != "binary_little_endian") return false;
  int vertexElements = 0, faceElements = 0;
  for (const PlyElement& e : h.elements) {
    if (!plyFastPathFits(e)) return false;
    vertexElements += e.name == "vertex";
    faceElements += e.name == "face";
  }
  return vertexElements == 1 && faceElements == 1;
}

void readBinaryPly(const std::string& path, const PlyHeader& h, const LoadOptions& options,
                   Mesh& mesh) {
  const std::string data = readFile(path);  // within maxFileBytes, checked by the caller
  BinaryPlyReader(path, data, h.bytes, options, mesh).read(h);
}

}  // namespace paircast
