#include "render/scan_scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>

#include "render/obj_writer.h"
#include "render/procedural_scene.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace fs = std::filesystem;

ScanKind parseScanKind(const std::string& text) {
  if (text == "scannet") return ScanKind::ScanNet;
  if (text == "replica") return ScanKind::Replica;
  if (text == "mp3d") return ScanKind::Matterport;
  throw Error("invalid scan kind '" + text + "' (use scannet, replica or mp3d)");
}

std::string scanKindName(ScanKind kind) {
  switch (kind) {
    case ScanKind::ScanNet:
      return "scannet";
    case ScanKind::Replica:
      return "replica";
    case ScanKind::Matterport:
      return "mp3d";
  }
  return "";
}

namespace {

enum class Surface { Floor, Wall, Ceiling, Furniture };

struct Disc {
  Eigen::Vector3f centre;
  float radius;
};

// A rectangle origin + s*u + t*v (s, t in [0, 1]) facing `normal`, tessellated into a grid.
struct Patch {
  Eigen::Vector3f origin, u, v, normal;
  Surface surface;
  Eigen::Vector3f color;  // sRGB base colour in [0, 1]
  std::string textureKind;
};

struct Room {
  float width, depth, height;  // x, y, z extents, metres
  float partitionX, partitionY;
  std::vector<Patch> patches;
  std::vector<Disc> holes;                       // cells with their centre inside are left out
  std::vector<Eigen::AlignedBox3f> ceilingGaps;  // ... and so are ceiling cells inside these
};

Patch makePatch(const Eigen::Vector3f& origin, Eigen::Vector3f u, Eigen::Vector3f v,
                const Eigen::Vector3f& normal, Surface surface, const Eigen::Vector3f& color,
                const std::string& textureKind) {
  if (u.cross(v).dot(normal) < 0) std::swap(u, v);
  return Patch{origin, u, v, normal.normalized(), surface, color, textureKind};
}

// The five visible faces of a box standing on the floor (scans have no bottoms).
void addBoxPatches(std::vector<Patch>& out, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi,
                   const Eigen::Vector3f& color, const std::string& textureKind) {
  const Eigen::Vector3f d = hi - lo;
  const Eigen::Vector3f X(d.x(), 0, 0), Y(0, d.y(), 0), Z(0, 0, d.z());
  auto add = [&](const Eigen::Vector3f& o, const Eigen::Vector3f& u, const Eigen::Vector3f& v,
                 const Eigen::Vector3f& n) {
    out.push_back(makePatch(o, u, v, n, Surface::Furniture, color, textureKind));
  };
  add(lo + Z, X, Y, Eigen::Vector3f::UnitZ());
  add(lo, Y, Z, -Eigen::Vector3f::UnitX());
  add(lo + X, Y, Z, Eigen::Vector3f::UnitX());
  add(lo, X, Z, -Eigen::Vector3f::UnitY());
  add(lo + Y, X, Z, Eigen::Vector3f::UnitY());
}

Room layoutRoom(uint64_t seed) {
  Rng rng(mixSeed(seed, "scan_layout", 0));
  Room r;
  r.width = static_cast<float>(rng.uniform(6.5, 8.0));
  r.depth = static_cast<float>(rng.uniform(5.0, 6.0));
  r.height = static_cast<float>(rng.uniform(2.5, 2.8));
  r.partitionX = r.width * static_cast<float>(rng.uniform(0.5, 0.6));
  r.partitionY = r.depth * 0.55f;
  const float W = r.width, D = r.depth, H = r.height;
  const Eigen::Vector3f X = Eigen::Vector3f::UnitX(), Y = Eigen::Vector3f::UnitY(),
                        Z = Eigen::Vector3f::UnitZ();
  const Eigen::Vector3f paint(0.86f, 0.83f, 0.76f), floorColor(0.55f, 0.38f, 0.24f);
  auto& P = r.patches;
  P.push_back(makePatch({0, 0, 0}, W * X, D * Y, Z, Surface::Floor, floorColor, "wood"));
  P.push_back(
      makePatch({0, 0, H}, W * X, D * Y, -Z, Surface::Ceiling, {0.93f, 0.93f, 0.92f}, "plaster"));
  P.push_back(makePatch({0, 0, 0}, W * X, H * Z, Y, Surface::Wall, paint, "plaster"));
  P.push_back(makePatch({0, D, 0}, W * X, H * Z, -Y, Surface::Wall, paint, "wallpaper"));
  P.push_back(makePatch({0, 0, 0}, D * Y, H * Z, X, Surface::Wall, paint, "plaster"));
  P.push_back(makePatch({W, 0, 0}, D * Y, H * Z, -X, Surface::Wall, paint, "brick"));
  // A partition wall, 12 cm thick, from the y = 0 wall to the middle: two rooms joined by an
  // opening.
  const float px = r.partitionX, py = r.partitionY, t = 0.12f;
  P.push_back(makePatch({px, 0, 0}, py * Y, H * Z, -X, Surface::Wall, paint, "plaster"));
  P.push_back(makePatch({px + t, 0, 0}, py * Y, H * Z, X, Surface::Wall, paint, "wallpaper"));
  P.push_back(makePatch({px, py, 0}, t * X, H * Z, Y, Surface::Wall, paint, "plaster"));

  auto jitter = [&](float a) { return static_cast<float>(rng.uniform(-a, a)); };
  // Left room: a table with four legs in the middle, a cabinet against the back wall.
  const Eigen::Vector3f tableLo(px * 0.5f - 0.7f + jitter(0.2f), py * 0.5f - 0.4f + jitter(0.2f),
                                0.0f);
  const Eigen::Vector3f table(0.55f, 0.4f, 0.28f);
  addBoxPatches(P, tableLo + Eigen::Vector3f(0, 0, 0.72f),
                tableLo + Eigen::Vector3f(1.4f, 0.8f, 0.76f), table, "wood");
  for (int leg = 0; leg < 4; ++leg) {
    const Eigen::Vector3f at =
        tableLo + Eigen::Vector3f(leg % 2 ? 1.3f : 0.05f, leg / 2 ? 0.7f : 0.05f, 0.0f);
    addBoxPatches(P, at, at + Eigen::Vector3f(0.05f, 0.05f, 0.72f), table, "wood");
  }
  const float cabinetX = 0.3f + jitter(0.2f);
  addBoxPatches(P, {cabinetX, D - 0.5f, 0}, {cabinetX + 0.9f, D, 1.9f}, {0.7f, 0.7f, 0.72f},
                "marble");
  // Right room: a sofa against the right wall, a bed against the front wall, clutter.
  const float sofaY = D * 0.55f + jitter(0.2f);
  addBoxPatches(P, {W - 0.9f, sofaY, 0}, {W, sofaY + 2.0f, 0.45f}, {0.25f, 0.35f, 0.55f}, "fabric");
  addBoxPatches(P, {W - 0.2f, sofaY, 0.45f}, {W, sofaY + 2.0f, 0.85f}, {0.25f, 0.35f, 0.55f},
                "fabric");
  const float bedX = px + t + 0.6f + jitter(0.2f);
  addBoxPatches(P, {bedX, 0, 0}, {bedX + 1.6f, 2.0f, 0.5f}, {0.8f, 0.75f, 0.7f}, "fabric");
  for (int k = 0; k < 3; ++k) {
    const float s = static_cast<float>(rng.uniform(0.25, 0.5));
    const Eigen::Vector3f lo(static_cast<float>(rng.uniform(0.5, W - 1.5)),
                             static_cast<float>(rng.uniform(py + 0.3, D - 1.2)), 0.0f);
    addBoxPatches(P, lo, lo + Eigen::Vector3f(s, s * 0.8f, s), {0.6f, 0.5f, 0.35f}, "paper");
  }

  // Holes where the scanner saw nothing: in the floor (under furniture, dark spots) and walls.
  for (int k = 0; k < 4; ++k)
    r.holes.push_back({{static_cast<float>(rng.uniform(0.5, W - 0.5)),
                        static_cast<float>(rng.uniform(0.5, D - 0.5)), 0.0f},
                       static_cast<float>(rng.uniform(0.08, 0.2))});
  for (int k = 0; k < 4; ++k)
    r.holes.push_back({{static_cast<float>(rng.uniform(0.5, W - 0.5)), k % 2 ? D : 0.0f,
                        static_cast<float>(rng.uniform(0.5, H - 0.5))},
                       static_cast<float>(rng.uniform(0.1, 0.3))});
  // The ceiling is the least scanned surface: a large gap and a strip along a wall.
  r.ceilingGaps.emplace_back(Eigen::Vector3f(W * 0.6f, D * 0.2f, H - 0.5f),
                             Eigen::Vector3f(W * 0.9f, D * 0.6f, H + 0.5f));
  r.ceilingGaps.emplace_back(Eigen::Vector3f(0.0f, 0.0f, H - 0.5f),
                             Eigen::Vector3f(W * 0.4f, 0.5f, H + 0.5f));
  return r;
}

bool isHole(const Room& room, const Patch& patch, const Eigen::Vector3f& p) {
  if (patch.surface == Surface::Furniture) return false;
  if (patch.surface == Surface::Ceiling)
    for (const auto& gap : room.ceilingGaps)
      if (gap.contains(p)) return true;
  for (const Disc& d : room.holes)
    if ((p - d.centre).squaredNorm() < d.radius * d.radius) return true;
  return false;
}

uint32_t hash3(uint64_t seed, int a, int b) {
  return static_cast<uint32_t>(
      mixSeed(seed, "scan_color", (uint64_t(uint32_t(a)) << 32) ^ uint32_t(b)));
}

// sRGB colour of a scan vertex at world point p: the patch's colour with a pattern (floor
// planks, wood grain, paint shading), baked-in lighting from the ceiling centre, and speckle.
Eigen::Vector3f scanColor(const Room& room, const Patch& patch, const Eigen::Vector3f& p,
                          uint64_t seed, uint32_t vertexHash) {
  Eigen::Vector3f c = patch.color;
  if (patch.surface == Surface::Floor) {
    const int plank = static_cast<int>(std::floor(p.y() / 0.18f));
    const float shade = 0.8f + 0.4f * (hash3(seed, plank, 0) % 1000) / 1000.0f;
    const float grain = 0.9f + 0.1f * std::sin(p.x() * 37.0f + plank * 1.7f);
    c *= shade * grain;
    if (std::fmod(p.y() + 1000.0f, 0.18f) < 0.006f) c *= 0.5f;
  } else if (patch.surface == Surface::Wall) {
    c *= 0.92f + 0.08f * std::sin(p.x() * 3.1f + p.y() * 2.3f) * std::cos(p.z() * 4.7f);
  } else if (patch.surface == Surface::Furniture) {
    c *= 0.85f + 0.15f * std::sin((p.x() + p.y()) * 23.0f + p.z() * 11.0f);
  }
  const Eigen::Vector3f light(room.width * 0.5f, room.depth * 0.5f, room.height);
  const float d2 = (p - light).squaredNorm();
  c *= 0.6f + 0.5f * std::exp(-d2 / 12.0f);
  c *= 0.96f + 0.08f * (vertexHash % 1000) / 1000.0f;
  return c.cwiseMax(0.0f).cwiseMin(1.0f);
}

double patchArea(const Patch& p) {
  return p.u.norm() * p.v.norm();
}

// Everything the writers need: the mesh plus what the formats store per vertex.
struct ScanMesh {
  Mesh mesh;
  std::vector<std::array<uint8_t, 3>> rgb;  // [V] sRGB vertex colours
  std::vector<Eigen::Vector3f> normals;     // [V] unit normals of the (unperturbed) surfaces
};

ScanMesh buildScanMesh(const ScanSpec& spec) {
  if (spec.triangles < 1000 || spec.triangles > 100'000'000)
    throw OptionError("triangles", "a scan must have between 1000 and 100000000 triangles");
  if (!(spec.noise >= 0.0f) || spec.noise > 0.05f)
    throw Error("scan noise must be between 0 and 5 cm");
  const Room room = layoutRoom(spec.seed);
  double area = 0;
  for (const Patch& p : room.patches) area += patchArea(p);
  // Two triangles per cell of side `step`; the holes take away a little, so aim a bit over.
  const double step = std::sqrt(2.0 * area / (spec.triangles * 1.04));
  const bool textured = spec.kind == ScanKind::Matterport;

  ScanMesh out;
  Mesh& mesh = out.mesh;
  if (!textured) mesh.addMaterial(Material{});
  for (size_t k = 0; k < room.patches.size(); ++k) {
    const Patch& patch = room.patches[k];
    int material = 0;
    if (textured) {
      // One texture per patch, as a Matterport mesh has dozens of texture images.
      mesh.textures.push_back(makeTexture(patch.textureKind, spec.seed * 1000 + k, 256));
      mesh.textures.back().name = "scan_" + std::to_string(k);
      Material m;
      m.name = "material_" + std::to_string(k);
      m.texture = static_cast<int>(mesh.textures.size()) - 1;
      material = mesh.addMaterial(m);
    }
    const float lu = patch.u.norm(), lv = patch.v.norm();
    const int nu = std::max(1, static_cast<int>(std::lround(lu / step)));
    const int nv = std::max(1, static_cast<int>(std::lround(lv / step)));
    Rng rng(mixSeed(spec.seed, "scan_noise", k));
    const int base = static_cast<int>(mesh.positions.size());
    for (int j = 0; j <= nv; ++j) {
      for (int i = 0; i <= nu; ++i) {
        const float s = static_cast<float>(i) / nu, t = static_cast<float>(j) / nv;
        const Eigen::Vector3f onSurface = patch.origin + s * patch.u + t * patch.v;
        const float n = static_cast<float>(std::clamp(rng.normal(), -3.0, 3.0)) * spec.noise;
        mesh.positions.push_back(onSurface + n * patch.normal);
        mesh.uvs.emplace_back(s * lu, t * lv);  // one texture tile per metre
        const Eigen::Vector3f c =
            scanColor(room, patch, onSurface, spec.seed, static_cast<uint32_t>(rng.next()));
        out.rgb.push_back({static_cast<uint8_t>(std::lround(c.x() * 255)),
                           static_cast<uint8_t>(std::lround(c.y() * 255)),
                           static_cast<uint8_t>(std::lround(c.z() * 255))});
        mesh.colors.emplace_back(srgbToLinear(c.x()), srgbToLinear(c.y()), srgbToLinear(c.z()));
        out.normals.push_back(patch.normal);
      }
    }
    auto at = [&](int i, int j) { return base + j * (nu + 1) + i; };
    for (int j = 0; j < nv; ++j) {
      for (int i = 0; i < nu; ++i) {
        const Eigen::Vector3f centre =
            patch.origin + (i + 0.5f) / nu * patch.u + (j + 0.5f) / nv * patch.v;
        if (isHole(room, patch, centre)) continue;
        const int a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
        mesh.triangles.emplace_back(a, b, c);
        mesh.triangles.emplace_back(a, c, d);
        mesh.triangleMaterial.insert(mesh.triangleMaterial.end(), 2, material);
      }
    }
  }
  return out;
}

template <typename T>
void put(std::string& out, const T& value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof value);
}

// ScanNet's *_vh_clean_2.ply and Replica's mesh.ply, binary little-endian.
std::string plyBytes(const ScanMesh& scan, bool replica) {
  const Mesh& mesh = scan.mesh;
  const size_t faces = replica ? mesh.numTriangles() / 2 : mesh.numTriangles();
  std::string out =
      "ply\nformat binary_little_endian 1.0\ncomment written by paircast "
      "make_scenes --scan\nelement vertex " +
      std::to_string(mesh.numVertices()) +
      "\nproperty float x\nproperty float y\nproperty float z\n";
  if (replica) out += "property float nx\nproperty float ny\nproperty float nz\n";
  out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (!replica) out += "property uchar alpha\n";
  out += "element face " + std::to_string(faces) +
         "\nproperty list uchar int vertex_indices\nend_header\n";
  const size_t vertexBytes = replica ? 27 : 16;
  out.reserve(out.size() + mesh.numVertices() * vertexBytes + faces * (replica ? 17 : 13));
  static_assert(sizeof(float) == 4 && sizeof(int32_t) == 4);
  for (size_t i = 0; i < mesh.numVertices(); ++i) {
    for (int a = 0; a < 3; ++a) put(out, mesh.positions[i][a]);
    if (replica)
      for (int a = 0; a < 3; ++a) put(out, scan.normals[i][a]);
    for (int a = 0; a < 3; ++a) put(out, scan.rgb[i][a]);
    if (!replica) put(out, uint8_t{255});
  }
  for (size_t f = 0; f < faces; ++f) {
    if (replica) {
      const Eigen::Vector3i& t0 = mesh.triangles[2 * f];
      const Eigen::Vector3i& t1 = mesh.triangles[2 * f + 1];
      put(out, uint8_t{4});
      for (int32_t v : {t0[0], t0[1], t0[2], t1[2]}) put(out, v);
    } else {
      put(out, uint8_t{3});
      for (int a = 0; a < 3; ++a) put(out, static_cast<int32_t>(mesh.triangles[f][a]));
    }
  }
  return out;
}

}  // namespace

Mesh buildScan(const ScanSpec& spec) {
  return buildScanMesh(spec).mesh;
}

std::string writeScan(const ScanSpec& spec, const std::string& dir, MeshStats* stats) {
  const ScanMesh scan = buildScanMesh(spec);
  if (stats) *stats = computeStats(scan.mesh);
  const std::string name = "scan_" + scanKindName(spec.kind) + "_" + std::to_string(spec.seed);
  fs::path path;
  switch (spec.kind) {
    case ScanKind::ScanNet:
      path = fs::path(dir) / (name + "_vh_clean_2.ply");
      makeDirs(dir);
      writeFileAtomic(path.string(), plyBytes(scan, false));
      break;
    case ScanKind::Replica:
      path = fs::path(dir) / name / "mesh.ply";
      makeDirs(path.parent_path().string());
      writeFileAtomic(path.string(), plyBytes(scan, true));
      break;
    case ScanKind::Matterport:
      path = fs::path(dir) / name / "matterport_mesh" / (name + ".obj");
      writeObj(path.string(), scan.mesh, "jpg");
      break;
  }
  return path.string();
}

}  // namespace paircast
