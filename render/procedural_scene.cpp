#include "render/procedural_scene.h"

#include <algorithm>
#include <cmath>

#include "util/error.h"

namespace paircast {
namespace {

// ---- integer hashing: the only source of randomness, identical everywhere ----
uint64_t hash64(uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdull;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ull;
  return x ^ (x >> 33);
}
float hashUnit(uint64_t a, uint64_t b = 0, uint64_t c = 0) {
  return static_cast<float>(hash64(a * 0x9E3779B97F4A7C15ull ^ hash64(b + 0x632BE59BD9B4E019ull) ^
                                   hash64(c + 0x85EBCA77C2B2AE63ull)) >>
                            40) /
         static_cast<float>(1 << 24);
}

// Tileable value noise on a period-`period` lattice, smooth, in [0, 1].
float valueNoise(float x, float y, int period, uint64_t seed) {
  const int xi = static_cast<int>(std::floor(x)), yi = static_cast<int>(std::floor(y));
  const float fx = x - xi, fy = y - yi;
  auto at = [&](int i, int j) {
    return hashUnit(seed, static_cast<uint64_t>(((i % period) + period) % period),
                    static_cast<uint64_t>(((j % period) + period) % period));
  };
  const float sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const float a = at(xi, yi) + sx * (at(xi + 1, yi) - at(xi, yi));
  const float b = at(xi, yi + 1) + sx * (at(xi + 1, yi + 1) - at(xi, yi + 1));
  return a + sy * (b - a);
}

// Fractal noise over [0, 1)^2, tileable.
float fbm(float u, float v, int base, uint64_t seed, int octaves = 4) {
  float sum = 0, amp = 0.5f, norm = 0;
  int period = base;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * valueNoise(u * period, v * period, period, seed + o);
    norm += amp;
    amp *= 0.5f;
    period *= 2;
  }
  return sum / norm;
}

Eigen::Vector3f mix(const Eigen::Vector3f& a, const Eigen::Vector3f& b, float t) {
  return a + (b - a) * std::clamp(t, 0.0f, 1.0f);
}

// ---- palette ----
Eigen::Vector3f srgb(int r, int g, int b) {
  return Eigen::Vector3f(r, g, b) / 255.0f;
}

}  // namespace

Texture makeTexture(const std::string& kind, uint64_t seed, int size) {
  Texture t;
  t.name = kind + "_" + std::to_string(seed);
  t.width = t.height = size;
  t.channels = 3;
  t.texels.resize(static_cast<size_t>(size) * size * 3);
  const float hue = hashUnit(seed, 7);
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const float u = (x + 0.5f) / size, v = (y + 0.5f) / size;
      Eigen::Vector3f c;
      if (kind == "wood") {  // planks along u, 4 per tile, grain and knots
        const int plank = static_cast<int>(v * 4);
        const float offset = hashUnit(seed, plank);
        const float grain = fbm(std::fmod(u + offset, 1.0f), v * 0.25f, 2, seed + plank * 13, 3);
        const float rings = 0.5f + 0.5f * std::sin(40.0f * grain + 6.0f * u);
        const Eigen::Vector3f base =
            mix(srgb(120, 78, 45), srgb(181, 134, 88), hashUnit(seed, plank, 3));
        c = base * (0.75f + 0.3f * rings);
        if (std::fmod(v * 4, 1.0f) < 0.03f || std::fmod(u + offset, 0.5f) < 0.006f) c *= 0.45f;
      } else if (kind == "tiles") {  // 4x4 square tiles with grout and mottling
        const float gu = std::fmod(u * 4, 1.0f), gv = std::fmod(v * 4, 1.0f);
        const int tile = static_cast<int>(u * 4) + 4 * static_cast<int>(v * 4);
        const Eigen::Vector3f base = mix(srgb(200, 196, 186), srgb(120, 140, 150), hue);
        c = base * (0.85f + 0.2f * fbm(u, v, 8, seed + tile)) *
            (0.95f + 0.1f * hashUnit(seed, tile));
        if (gu < 0.04f || gv < 0.04f) c = srgb(90, 90, 88);
      } else if (kind == "carpet") {
        const Eigen::Vector3f base = mix(srgb(140, 40, 40), srgb(40, 70, 130), hue);
        const float n = fbm(u, v, 32, seed, 3);
        const float pattern = std::sin(12.566f * u) * std::sin(12.566f * v) > 0.3f ? 1.2f : 1.0f;
        c = base * (0.7f + 0.5f * n) * pattern;
      } else if (kind == "plaster") {
        const Eigen::Vector3f base = mix(srgb(225, 220, 205), srgb(200, 215, 225), hue);
        c = base * (0.88f + 0.16f * fbm(u, v, 4, seed, 5));
      } else if (kind == "wallpaper") {  // stripes with a small motif
        const Eigen::Vector3f a = mix(srgb(210, 200, 170), srgb(170, 200, 190), hue);
        const Eigen::Vector3f b = a * 0.8f;
        const float s = std::fmod(u * 8, 1.0f);
        c = s < 0.5f ? a : b;
        const float du = std::fmod(u * 8, 1.0f) - 0.75f, dv = std::fmod(v * 8, 1.0f) - 0.5f;
        if (du * du + dv * dv < 0.012f) c = srgb(150, 60, 60);
        c *= 0.92f + 0.1f * fbm(u, v, 8, seed, 2);
      } else if (kind == "brick") {
        const int row = static_cast<int>(v * 8);
        const float shift = (row % 2) * 0.125f;
        const float bu = std::fmod(u + shift, 1.0f) * 4;
        const int brick = static_cast<int>(bu) + 4 * row;
        c = mix(srgb(150, 60, 45), srgb(185, 95, 65), hashUnit(seed, brick)) *
            (0.8f + 0.3f * fbm(u, v, 16, seed));
        if (std::fmod(v * 8, 1.0f) < 0.1f || std::fmod(bu, 1.0f) < 0.05f) c = srgb(170, 165, 150);
      } else if (kind == "fabric") {  // woven
        const Eigen::Vector3f base = mix(srgb(70, 90, 120), srgb(150, 110, 70), hue);
        const float weave = 0.5f + 0.5f * std::sin(6.283f * 48 * u) * std::sin(6.283f * 48 * v);
        c = base * (0.75f + 0.25f * weave + 0.2f * fbm(u, v, 8, seed, 2));
      } else if (kind == "paper") {  // a painting: smooth colour fields
        const Eigen::Vector3f a = srgb(40 + 200 * hashUnit(seed, 1), 40 + 200 * hashUnit(seed, 2),
                                       40 + 200 * hashUnit(seed, 3));
        const Eigen::Vector3f b = srgb(40 + 200 * hashUnit(seed, 4), 40 + 200 * hashUnit(seed, 5),
                                       40 + 200 * hashUnit(seed, 6));
        c = mix(a, b, fbm(u, v, 2, seed, 4) * 1.6f - 0.3f);
      } else if (kind == "marble") {
        const float n = fbm(u, v, 4, seed, 5);
        const float vein = std::abs(std::sin(10.0f * (u + v) + 8.0f * n));
        c = mix(srgb(90, 90, 95), srgb(235, 232, 228), std::pow(vein, 0.3f));
      } else {
        throw Error("unknown texture kind '" + kind + "'");
      }
      uint8_t* p = t.texels.data() + (static_cast<size_t>(y) * size + x) * 3;
      for (int k = 0; k < 3; ++k)
        p[k] = static_cast<uint8_t>(std::clamp(c[k], 0.0f, 1.0f) * 255.0f + 0.5f);
    }
  }
  return t;
}

void addBox(Mesh& m, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, int material,
            float uvScale) {
  // Each face: its own four vertices, outward winding, UVs from the two in-plane axes.
  auto face = [&](const Eigen::Vector3f& o, const Eigen::Vector3f& du, const Eigen::Vector3f& dv,
                  const Eigen::Vector2f& uv0) {
    const float lu = du.norm() * uvScale, lv = dv.norm() * uvScale;
    const Eigen::Vector2f t0 = uv0, t1 = uv0 + Eigen::Vector2f(lu, 0),
                          t2 = uv0 + Eigen::Vector2f(lu, lv), t3 = uv0 + Eigen::Vector2f(0, lv);
    m.addTriangle(o, o + du, o + du + dv, material, t0, t1, t2);
    m.addTriangle(o, o + du + dv, o + dv, material, t0, t2, t3);
  };
  const Eigen::Vector3f d = hi - lo;
  const Eigen::Vector3f X(d.x(), 0, 0), Y(0, d.y(), 0), Z(0, 0, d.z());
  const Eigen::Vector2f uvx(lo.x() * uvScale, lo.y() * uvScale),
      uvz(lo.z() * uvScale, lo.y() * uvScale), uvy(lo.x() * uvScale, lo.z() * uvScale);
  face(lo, Y, X, {uvx.y(), uvx.x()});      // -z
  face(lo + Z, X, Y, uvx);                 // +z
  face(lo, Z, Y, uvz);                     // -x
  face(lo + X, Y, Z, {uvz.y(), uvz.x()});  // +x
  face(lo, X, Z, uvy);                     // -y
  face(lo + Y, Z, X, {uvy.y(), uvy.x()});  // +y
}

namespace {

class Builder {
 public:
  explicit Builder(uint64_t seed) : seed_(seed) {}

  // A material with a procedural texture (-1 kind = plain colour).
  int textured(const std::string& kind, uint64_t variant,
               const Eigen::Vector3f& tint = Eigen::Vector3f::Ones()) {
    mesh.textures.push_back(makeTexture(kind, hash64(seed_ * 131 + variant) % 100000));
    Material m;
    m.name = kind;
    m.texture = static_cast<int>(mesh.textures.size()) - 1;
    m.baseColor = tint;
    return mesh.addMaterial(m);
  }
  int plain(const Eigen::Vector3f& linear) {
    Material m;
    m.baseColor = linear;
    return mesh.addMaterial(m);
  }
  float rnd(uint64_t a, uint64_t b = 0) { return hashUnit(seed_, a * 7919 + counter_++, b); }

  Mesh mesh;
  // Floor rectangles (x0, z0, x1, z1) that furniture must leave free: the space before doors.
  std::vector<Eigen::Vector4f> keepOut;

 private:
  uint64_t seed_;
  uint64_t counter_ = 0;
};

using V3 = Eigen::Vector3f;

// The wall two rooms of a plan share: on the line x = at (atX) or z = at, spanning [from, to]
// along it; to - from <= 0 when they share no wall.
struct SharedWall {
  bool atX = false;
  float at = 0, from = 0, to = 0;
};
SharedWall sharedWall(const RoomSpec& a, const RoomSpec& b) {
  SharedWall w;
  if (std::abs(a.z1 - b.z0) < 1e-3f || std::abs(a.z0 - b.z1) < 1e-3f) {
    w.at = std::abs(a.z1 - b.z0) < 1e-3f ? a.z1 : a.z0;
    w.from = std::max(a.x0, b.x0), w.to = std::min(a.x1, b.x1);
  }
  if (std::abs(a.x1 - b.x0) < 1e-3f || std::abs(a.x0 - b.x1) < 1e-3f) {
    const float from = std::max(a.z0, b.z0), to = std::min(a.z1, b.z1);
    if (to - from > w.to - w.from)
      w = {true, std::abs(a.x1 - b.x0) < 1e-3f ? a.x1 : a.x0, from, to};
  }
  return w;
}

// One piece of furniture: whatever it added to the mesh is taken out again when its footprint
// reaches into a keep-out rectangle, so that no random plan has a door blocked by a sofa.
class Piece {
 public:
  explicit Piece(Builder& b)
      : b_(b), vertices_(b.mesh.positions.size()), triangles_(b.mesh.triangles.size()) {}
  ~Piece() {
    Mesh& m = b_.mesh;
    if (m.positions.size() == vertices_) return;
    Eigen::Vector3f lo = m.positions[vertices_], hi = lo;
    for (size_t i = vertices_; i < m.positions.size(); ++i)
      lo = lo.cwiseMin(m.positions[i]), hi = hi.cwiseMax(m.positions[i]);
    for (const Eigen::Vector4f& r : b_.keepOut) {
      if (hi.x() > r[0] && lo.x() < r[2] && hi.z() > r[1] && lo.z() < r[3]) {
        m.positions.resize(vertices_), m.uvs.resize(vertices_), m.colors.resize(vertices_);
        m.triangles.resize(triangles_), m.triangleMaterial.resize(triangles_);
        return;
      }
    }
  }
  Piece(const Piece&) = delete;
  Piece& operator=(const Piece&) = delete;

 private:
  Builder& b_;
  size_t vertices_, triangles_;
};

// ---- furniture: each piece is a few boxes standing on the floor at (x, z), rotated by
// multiples of 90 degrees (swap of extents) ----
struct Placement {
  float x, z;    // centre
  bool rotated;  // swap the x and z extents
};

V3 ext(const Placement& p, float ex, float ez) {
  return p.rotated ? V3(ez, 0, ex) : V3(ex, 0, ez);
}

void box(Builder& b, const Placement& p, float cx, float cz, float y0, float ex, float ey, float ez,
         int mat, float uvScale = 1.0f) {
  // (cx, cz) is an offset in the piece's own frame.
  const float ox = p.rotated ? cz : cx, oz = p.rotated ? cx : cz;
  const V3 e = ext(p, ex, ez);
  const V3 c(p.x + ox, y0, p.z + oz);
  addBox(b.mesh, V3(c.x() - e.x() / 2, y0, c.z() - e.z() / 2),
         V3(c.x() + e.x() / 2, y0 + ey, c.z() + e.z() / 2), mat, uvScale);
}

void table(Builder& b, const Placement& p, int wood, float w, float d) {
  Piece piece(b);
  box(b, p, 0, 0, 0.72f, w, 0.04f, d, wood, 2.0f);
  for (int sx : {-1, 1})
    for (int sz : {-1, 1})
      box(b, p, sx * (w / 2 - 0.06f), sz * (d / 2 - 0.06f), 0, 0.05f, 0.72f, 0.05f, wood);
}

void chair(Builder& b, const Placement& p, int wood, int fabric, bool backAtPlusZ) {
  Piece piece(b);
  box(b, p, 0, 0, 0.42f, 0.42f, 0.05f, 0.42f, fabric, 3.0f);
  for (int sx : {-1, 1})
    for (int sz : {-1, 1}) box(b, p, sx * 0.18f, sz * 0.18f, 0, 0.04f, 0.42f, 0.04f, wood);
  box(b, p, 0, backAtPlusZ ? 0.19f : -0.19f, 0.47f, 0.42f, 0.45f, 0.04f, wood, 2.0f);
}

void sofa(Builder& b, const Placement& p, int fabric) {
  Piece piece(b);
  box(b, p, 0, 0, 0.0f, 2.0f, 0.42f, 0.9f, fabric, 2.0f);
  box(b, p, 0, 0.35f, 0.42f, 2.0f, 0.45f, 0.2f, fabric, 2.0f);
  for (int s : {-1, 1}) box(b, p, s * 0.9f, 0, 0.42f, 0.2f, 0.22f, 0.9f, fabric, 2.0f);
}

void bed(Builder& b, const Placement& p, int wood, int fabric, int sheet) {
  Piece piece(b);
  box(b, p, 0, 0, 0.0f, 1.6f, 0.3f, 2.0f, wood, 2.0f);
  box(b, p, 0, 0, 0.3f, 1.5f, 0.22f, 1.9f, sheet, 2.0f);
  box(b, p, 0, 0.55f, 0.52f, 1.4f, 0.1f, 0.7f, fabric, 3.0f);  // blanket fold
  box(b, p, 0, -0.98f, 0.0f, 1.6f, 1.0f, 0.06f, wood, 2.0f);   // headboard
}

void shelf(Builder& b, const Placement& p, int wood, uint64_t salt) {
  Piece piece(b);
  const float w = 1.0f, d = 0.32f, h = 1.9f;
  for (int s : {-1, 1}) box(b, p, s * (w / 2 - 0.02f), 0, 0, 0.03f, h, d, wood, 2.0f);
  for (int level = 0; level < 5; ++level) {
    const float y = 0.05f + level * 0.45f;
    box(b, p, 0, 0, y, w, 0.025f, d, wood, 2.0f);
    if (level == 4) continue;
    float x = -w / 2 + 0.05f;  // books of random sizes and colours
    while (x < w / 2 - 0.1f) {
      const float bw = 0.025f + 0.035f * b.rnd(salt, level);
      const float bh = 0.2f + 0.15f * b.rnd(salt + 1, level);
      const int book =
          b.plain(V3(0.05f + 0.6f * b.rnd(salt + 2, level), 0.05f + 0.5f * b.rnd(salt + 3, level),
                     0.05f + 0.5f * b.rnd(salt + 4, level)));
      box(b, p, x + bw / 2, 0, y + 0.025f, bw, bh, d * 0.8f, book);
      x += bw + 0.004f;
    }
  }
}

void cabinet(Builder& b, const Placement& p, int wood, int top, float w, float h) {
  Piece piece(b);
  box(b, p, 0, 0, 0, w, h, 0.55f, wood, 2.0f);
  box(b, p, 0, 0, h, w + 0.02f, 0.03f, 0.58f, top, 1.0f);
}

void lamp(Builder& b, const Placement& p, int metal, int shade) {
  Piece piece(b);
  box(b, p, 0, 0, 0, 0.3f, 0.03f, 0.3f, metal);
  box(b, p, 0, 0, 0.03f, 0.03f, 1.45f, 0.03f, metal);
  box(b, p, 0, 0, 1.4f, 0.4f, 0.3f, 0.4f, shade, 2.0f);
}

// ---- the stages of buildLayout ----

// The materials the rooms share, made first and in this order (their textures' indices and
// seeds are part of the mesh).
struct Materials {
  int walls[3];  // by room index, modulo 3
  int ceiling, wood, darkWood, fabric, fabric2, sheet, marble, metal, shade;
};

Materials sharedMaterials(Builder& b) {
  Materials m;
  m.walls[0] = b.textured("plaster", 1);
  m.walls[1] = b.textured("wallpaper", 2);
  m.walls[2] = b.textured("brick", 3);
  m.ceiling = b.textured("plaster", 4, V3(1.0f, 1.0f, 1.0f));
  m.wood = b.textured("wood", 5);
  m.darkWood = b.textured("wood", 6, V3(0.55f, 0.45f, 0.4f));
  m.fabric = b.textured("fabric", 7);
  m.fabric2 = b.textured("fabric", 8);
  m.sheet = b.textured("fabric", 9, V3(0.95f, 0.95f, 0.9f));
  m.marble = b.textured("marble", 10);
  m.metal = b.plain(V3(0.3f, 0.3f, 0.32f));
  m.shade = b.textured("paper", 11, V3(1.0f, 0.95f, 0.8f));
  return m;
}

// A furnished shell's: the ceiling alone (its walls and floors draw their own, and nothing
// else uses the others).
Materials shellMaterials(Builder& b) {
  Materials m{};
  m.ceiling = b.textured("plaster", 4, V3(1.0f, 1.0f, 1.0f));
  return m;
}

// A light tint, drawn per room: furnished shells vary their textures' colours.
V3 roomTint(Builder& b, size_t room, uint64_t salt) {
  return V3(0.75f + 0.25f * b.rnd(room, salt), 0.75f + 0.25f * b.rnd(room, salt + 1),
            0.75f + 0.25f * b.rnd(room, salt + 2));
}

// A floor per room, of its kind's texture, and one ceiling slab over the whole plan.
void addFloorsAndCeiling(Builder& b, const LayoutSpec& L, int ceiling) {
  const float H = L.height, T = kWallThickness;
  const std::string floorKinds[5] = {"wood", "carpet", "tiles", "wood", "tiles"};
  // Bounds of the whole plan.
  float minX = 1e9f, minZ = 1e9f, maxX = -1e9f, maxZ = -1e9f;
  for (const auto& r : L.rooms) {
    minX = std::min(minX, r.x0), minZ = std::min(minZ, r.z0);
    maxX = std::max(maxX, r.x1), maxZ = std::max(maxZ, r.z1);
  }
  const std::string furnishedKinds[5] = {"wood", "tiles", "carpet", "marble", "wood"};
  for (size_t i = 0; i < L.rooms.size(); ++i) {
    const RoomSpec& r = L.rooms[i];
    const int kind = static_cast<int>(r.kind);
    const int floorMat = L.furnished
                             ? b.textured(furnishedKinds[static_cast<int>(b.rnd(i, 31) * 5) % 5],
                                          200 + i, roomTint(b, i, 32))
                             : b.textured(floorKinds[kind], 20 + i);
    addBox(b.mesh, V3(r.x0, -0.1f, r.z0), V3(r.x1, 0.0f, r.z1), floorMat, 0.5f);
  }
  addBox(b.mesh, V3(minX - T, H, minZ - T), V3(maxX + T, H + 0.1f, maxZ + T), ceiling, 0.5f);
}

// An interval [a, b] along a wall.
struct Gap {
  float a, b;
};

void sortGaps(std::vector<Gap>& gaps) {
  std::sort(gaps.begin(), gaps.end(), [](const Gap& a, const Gap& c) { return a.a < c.a; });
}

// Edge `index` of a room (0: z = z0, 1: z = z1, 2: x = x0, 3: x = x1): on the line `fixed`,
// from lo to hi along x (alongX) or z.
struct RoomEdge {
  int index;
  bool alongX;
  float fixed, lo, hi;
};

RoomEdge roomEdge(const RoomSpec& r, int edge) {
  const bool alongX = edge < 2;
  const float fixed = edge == 0 ? r.z0 : edge == 1 ? r.z1 : edge == 2 ? r.x0 : r.x1;
  return {edge, alongX, fixed, alongX ? r.x0 : r.z0, alongX ? r.x1 : r.z1};
}

// The parts of room `room`'s edge that no lower-indexed room built (a shared edge is built once,
// by the room with the lower index).
std::vector<Gap> unbuiltParts(const LayoutSpec& L, size_t room, const RoomEdge& e) {
  std::vector<Gap> covered;
  for (size_t j = 0; j < room; ++j) {
    const RoomSpec& o = L.rooms[j];
    const float a = e.alongX ? o.x0 : o.z0, c = e.alongX ? o.x1 : o.z1;
    const bool sameLine =
        e.alongX ? (std::abs(o.z0 - e.fixed) < 1e-3f || std::abs(o.z1 - e.fixed) < 1e-3f)
                 : (std::abs(o.x0 - e.fixed) < 1e-3f || std::abs(o.x1 - e.fixed) < 1e-3f);
    if (sameLine && c > e.lo && a < e.hi) covered.push_back({std::max(a, e.lo), std::min(c, e.hi)});
  }
  sortGaps(covered);
  std::vector<Gap> open;
  float start = e.lo;
  for (const Gap& g : covered) {
    if (g.a > start + 1e-3f) open.push_back({start, g.a});
    start = std::max(start, g.b);
  }
  if (e.hi > start + 1e-3f) open.push_back({start, e.hi});
  return open;
}

// The door openings in a room's edge, in order along it.
std::vector<Gap> doorGaps(const LayoutSpec& L, int room, int edge) {
  std::vector<Gap> gaps;
  for (const auto& d : L.doors) {
    if (d.roomA != room && d.roomB != room) continue;
    const RoomSpec& r = L.rooms[room];
    const RoomSpec& o = L.rooms[d.roomA == room ? d.roomB : d.roomA];
    const bool shares = (edge == 0 && std::abs(r.z0 - o.z1) < 1e-3f) ||
                        (edge == 1 && std::abs(r.z1 - o.z0) < 1e-3f) ||
                        (edge == 2 && std::abs(r.x0 - o.x1) < 1e-3f) ||
                        (edge == 3 && std::abs(r.x1 - o.x0) < 1e-3f);
    if (shares) gaps.push_back({d.at - d.width / 2, d.at + d.width / 2});
  }
  sortGaps(gaps);
  return gaps;
}

// The wall over `open` (extended by half a wall at the edge's ends), floor to ceiling but for
// the doors' `gaps`, which get a lintel.
void addWallParts(Builder& b, const RoomEdge& e, const std::vector<Gap>& open,
                  const std::vector<Gap>& gaps, int wall, float H) {
  const float T = kWallThickness;
  auto segment = [&](float a, float c, float y0, float y1) {
    if (c - a < 1e-3f) return;
    if (e.alongX)
      addBox(b.mesh, V3(a, y0, e.fixed - T / 2), V3(c, y1, e.fixed + T / 2), wall, 1.0f);
    else
      addBox(b.mesh, V3(e.fixed - T / 2, y0, a), V3(e.fixed + T / 2, y1, c), wall, 1.0f);
  };
  for (const Gap& part : open) {
    const float from = part.a - (std::abs(part.a - e.lo) < 1e-3f ? T / 2 : 0.0f);
    const float to = part.b + (std::abs(part.b - e.hi) < 1e-3f ? T / 2 : 0.0f);
    float cursor = from;
    for (const Gap& g : gaps) {
      if (g.b <= from || g.a >= to) continue;
      segment(cursor, g.a, 0.0f, H);
      segment(g.a, g.b, kDoorHeight, H);  // lintel
      cursor = g.b;
    }
    segment(cursor, to, 0.0f, H);
  }
}

// A painting in the middle of room `room`'s edge, on its inner face.
void addPainting(Builder& b, size_t room, const RoomEdge& e) {
  const float T = kWallThickness;
  const int edge = e.index;
  const int art = b.textured("paper", 100 + room * 4 + edge);
  const float mid = 0.5f * (e.lo + e.hi), inward = (edge == 0 || edge == 2) ? 1.0f : -1.0f;
  const float w = 0.6f + 0.5f * b.rnd(room, edge + 9), off = e.fixed + inward * (T / 2 + 0.015f);
  if (e.alongX)
    addBox(b.mesh, V3(mid - w / 2, 1.3f, off - 0.015f),
           V3(mid + w / 2, 1.3f + 0.7f * w, off + 0.015f), art, 1.0f / w);
  else
    addBox(b.mesh, V3(off - 0.015f, 1.3f, mid - w / 2),
           V3(off + 0.015f, 1.3f + 0.7f * w, mid + w / 2), art, 1.0f / w);
}

// Walls: every room edge, split where a door or an already-built shared edge is; door gaps get
// a lintel, and walls without doors sometimes a painting.
void addWalls(Builder& b, const LayoutSpec& L, const int (&wallMats)[3]) {
  const std::string kinds[3] = {"plaster", "wallpaper", "brick"};
  for (size_t i = 0; i < L.rooms.size(); ++i) {
    const int wall = L.furnished ? b.textured(kinds[static_cast<int>(b.rnd(i, 41) * 3) % 3],
                                              300 + i, roomTint(b, i, 42))
                                 : wallMats[i % 3];
    for (int edge = 0; edge < 4; ++edge) {
      const RoomEdge e = roomEdge(L.rooms[i], edge);
      const std::vector<Gap> open = unbuiltParts(L, i, e);
      if (open.empty()) continue;
      const std::vector<Gap> gaps = doorGaps(L, static_cast<int>(i), edge);
      addWallParts(b, e, open, gaps, wall, L.height);
      if (!L.furnished && gaps.empty() && b.rnd(i, edge) < 0.6f) addPainting(b, i, e);
    }
  }
}

// With clearDoorways, the floor before each door (0.8 m deep on both sides, 0.1 m wider than
// the door) becomes a keep-out rectangle for furniture.
void keepDoorwaysClear(Builder& b, const LayoutSpec& L) {
  if (L.clearDoorways) b.keepOut = doorwayKeepOuts(L);
}

// A room to furnish: its floor, centre and size, and the salt of its random draws.
struct RoomFrame {
  const RoomSpec& r;
  float cx, cz;  // centre
  float w, d;    // extent along x and z
  uint64_t salt;
};

void furnishLiving(Builder& b, const RoomFrame& f, const Materials& m) {
  const RoomSpec& r = f.r;
  const float cx = f.cx, cz = f.cz, w = f.w, d = f.d;
  addBox(b.mesh, V3(cx - 1.2f, 0.0f, cz - 0.8f), V3(cx + 1.2f, 0.012f, cz + 0.8f),
         b.textured("carpet", f.salt), 0.7f);
  sofa(b, {cx, r.z1 - 0.55f, false}, m.fabric);
  table(b, {cx, cz - 0.1f, false}, m.darkWood, 1.1f, 0.6f);
  shelf(b, {r.x0 + 0.25f, cz + 0.3f * d * (b.rnd(f.salt) - 0.5f), true}, m.wood, f.salt);
  lamp(b, {r.x1 - 0.4f, r.z1 - 0.4f, false}, m.metal, m.shade);
  cabinet(b, {cx, r.z0 + 0.35f, false}, m.darkWood, m.marble, std::min(1.6f, w - 2.0f), 0.55f);
}

void furnishBedroom(Builder& b, const RoomFrame& f, const Materials& m) {
  const RoomSpec& r = f.r;
  const float cx = f.cx, cz = f.cz;
  bed(b, {cx, r.z0 + 1.1f, false}, m.wood, m.fabric2, m.sheet);
  cabinet(b, {r.x1 - 0.35f, cz + 0.8f, true}, m.darkWood, m.wood, 1.0f, 1.8f);
  cabinet(b, {cx - 1.1f, r.z0 + 0.3f, false}, m.wood, m.marble, 0.45f, 0.5f);
  lamp(b, {r.x0 + 0.35f, r.z1 - 0.35f, false}, m.metal, m.shade);
}

void furnishKitchen(Builder& b, const RoomFrame& f, const Materials& m) {
  const RoomSpec& r = f.r;
  const float cx = f.cx, cz = f.cz;
  // Counters along two walls, a table with chairs.
  {
    Piece counters(b);
    addBox(b.mesh, V3(r.x0 + 0.05f, 0.0f, r.z0 + 0.05f), V3(r.x1 - 0.05f, 0.88f, r.z0 + 0.65f),
           m.darkWood, 2.0f);
    addBox(b.mesh, V3(r.x0 + 0.03f, 0.88f, r.z0 + 0.03f), V3(r.x1 - 0.03f, 0.92f, r.z0 + 0.68f),
           m.marble, 1.0f);
    addBox(b.mesh, V3(r.x0 + 0.05f, 1.5f, r.z0 + 0.05f), V3(r.x1 - 0.05f, 2.2f, r.z0 + 0.4f),
           m.wood, 2.0f);
  }
  table(b, {cx, cz + 0.4f, false}, m.wood, 1.2f, 0.8f);
  chair(b, {cx - 0.35f, cz + 1.05f, false}, m.wood, m.fabric, true);
  chair(b, {cx + 0.35f, cz - 0.25f, false}, m.wood, m.fabric, false);
}

void furnishOffice(Builder& b, const RoomFrame& f, const Materials& m) {
  const RoomSpec& r = f.r;
  const float cx = f.cx, cz = f.cz;
  table(b, {cx, r.z0 + 0.5f, false}, m.wood, 1.4f, 0.7f);
  chair(b, {cx, r.z0 + 1.05f, false}, m.metal, m.fabric2, true);
  shelf(b, {r.x1 - 0.25f, cz, true}, m.darkWood, f.salt);
  shelf(b, {r.x0 + 0.25f, cz + 0.4f, true}, m.wood, f.salt + 7);
}

void furnishHall(Builder& b, const RoomFrame& f, const Materials& m) {
  const RoomSpec& r = f.r;
  const float cx = f.cx, cz = f.cz, w = f.w;
  cabinet(b, {cx, r.z1 - 0.35f, false}, m.darkWood, m.marble, std::min(1.2f, w - 0.8f), 0.9f);
  addBox(b.mesh, V3(cx - 0.6f, 0.0f, cz - 0.9f), V3(cx + 0.6f, 0.012f, cz + 0.9f),
         b.textured("carpet", f.salt), 0.7f);
}

// Furniture by the room's kind, mostly in the room's far half.
void furnishRoom(Builder& b, const RoomSpec& r, size_t index, const Materials& m) {
  const RoomFrame f{r,           0.5f * (r.x0 + r.x1), 0.5f * (r.z0 + r.z1),
                    r.x1 - r.x0, r.z1 - r.z0,          1000 + index * 50};
  switch (r.kind) {
    case RoomKind::Living:
      furnishLiving(b, f, m);
      break;
    case RoomKind::Bedroom:
      furnishBedroom(b, f, m);
      break;
    case RoomKind::Kitchen:
      furnishKitchen(b, f, m);
      break;
    case RoomKind::Office:
      furnishOffice(b, f, m);
      break;
    case RoomKind::Hall:
      furnishHall(b, f, m);
      break;
  }
}

}  // namespace

std::vector<DoorOpening> doorOpenings(const LayoutSpec& L) {
  std::vector<DoorOpening> out;
  for (const auto& d : L.doors) {
    const SharedWall w = sharedWall(L.rooms[d.roomA], L.rooms[d.roomB]);
    out.push_back(w.atX ? DoorOpening{w.at, d.at, true, d.width}
                        : DoorOpening{d.at, w.at, false, d.width});
  }
  return out;
}

std::vector<Eigen::Vector4f> doorwayKeepOuts(const LayoutSpec& L, float depth) {
  std::vector<Eigen::Vector4f> out;
  for (const DoorOpening& o : doorOpenings(L)) {
    const float half = o.width / 2 + 0.1f;
    const float hx = o.alongZ ? depth : half, hz = o.alongZ ? half : depth;
    out.emplace_back(o.x - hx, o.z - hz, o.x + hx, o.z + hz);
  }
  return out;
}

Mesh buildLayout(const LayoutSpec& L) {
  Builder b(L.seed);
  const Materials materials = L.furnished ? shellMaterials(b) : sharedMaterials(b);
  addFloorsAndCeiling(b, L, materials.ceiling);
  addWalls(b, L, materials.walls);
  if (!L.furnished) {
    // Furniture per room kind, never in front of a door.
    keepDoorwaysClear(b, L);
    for (size_t i = 0; i < L.rooms.size(); ++i) furnishRoom(b, L.rooms[i], i, materials);
  }
  b.mesh.validate(L.name);
  return std::move(b.mesh);
}

namespace {

constexpr float kMinRoomSide = 3.0f;

float roundToGrid(float v) {
  return std::round(v * 20.0f) / 20.0f;  // 5 cm
}

// Splits the largest room that can be split, across its longer side, until `target` rooms or
// none can be split; cut positions and kinds drawn by `u`.
template <typename Draw>
void splitRooms(LayoutSpec& L, int target, const Draw& u) {
  const RoomKind kinds[] = {RoomKind::Living, RoomKind::Bedroom, RoomKind::Kitchen,
                            RoomKind::Office, RoomKind::Hall};
  const int maxSplits = std::max(16, 4 * target);
  for (int k = 0; static_cast<int>(L.rooms.size()) < target && k < maxSplits; ++k) {
    int best = -1;
    float bestArea = 0;
    for (size_t i = 0; i < L.rooms.size(); ++i) {
      const RoomSpec& r = L.rooms[i];
      const float area = (r.x1 - r.x0) * (r.z1 - r.z0);
      if (std::max(r.x1 - r.x0, r.z1 - r.z0) >= 2 * kMinRoomSide && area > bestArea)
        best = static_cast<int>(i), bestArea = area;
    }
    if (best < 0) break;
    RoomSpec a = L.rooms[best], b = a;
    const bool alongX = a.x1 - a.x0 >= a.z1 - a.z0;
    const float lo = (alongX ? a.x0 : a.z0) + kMinRoomSide;
    const float hi = (alongX ? a.x1 : a.z1) - kMinRoomSide;
    const float cut = roundToGrid(lo + (hi - lo) * u(10 + k));
    (alongX ? a.x1 : a.z1) = cut;
    (alongX ? b.x0 : b.z0) = cut;
    b.kind = kinds[static_cast<int>(u(30 + k) * 5.0f) % 5];
    L.rooms[best] = a;
    L.rooms.push_back(b);
  }
}

}  // namespace

LayoutSpec randomLayout(const std::string& name, uint64_t seed, int rooms) {
  constexpr float kDoorOverlap = 1.6f;
  PAIRCAST_CHECK(rooms >= 0 && rooms <= kMaxLayoutRooms);
  auto u = [&](uint64_t a, uint64_t b = 0) { return hashUnit(seed, 0x5ca1ab1e + a, b); };
  auto lerp = [](float a, float b, float t) { return a + (b - a) * t; };
  LayoutSpec L;
  L.name = name;
  L.seed = seed;
  L.clearDoorways = true;
  L.height = roundToGrid(lerp(2.5f, 3.0f, u(1)));
  const RoomKind kinds[] = {RoomKind::Living, RoomKind::Bedroom, RoomKind::Kitchen,
                            RoomKind::Office, RoomKind::Hall};
  const RoomKind firstKind = kinds[static_cast<int>(u(5) * 5.0f) % 5];
  if (rooms == 0) {
    const float W = roundToGrid(lerp(5.0f, 12.0f, u(2))), D = roundToGrid(lerp(4.0f, 9.0f, u(3)));
    L.rooms.push_back({0, 0, W, D, firstKind});
    splitRooms(L, 1 + static_cast<int>(u(4) * 5.0f), u);
  } else {
    // A rectangle of 12-20 m^2 a room with sides in ratio 1-1.6, grown by a tenth until the
    // splits give `rooms` rooms (a cut may leave a piece too small to split again).
    const float area = rooms * lerp(12.0f, 20.0f, u(2)), aspect = lerp(1.0f, 1.6f, u(3));
    for (float grow = 1.0f; static_cast<int>(L.rooms.size()) < rooms; grow *= 1.1f) {
      const float W = roundToGrid(std::max(kMinRoomSide, std::sqrt(grow * area * aspect)));
      const float D = roundToGrid(std::max(kMinRoomSide, std::sqrt(grow * area / aspect)));
      L.rooms.assign(1, {0, 0, W, D, firstKind});
      splitRooms(L, rooms, u);
    }
  }
  // Doors: a spanning tree over the rooms that share enough wall, plus a chance of more.
  std::vector<int> component(L.rooms.size());
  for (size_t i = 0; i < component.size(); ++i) component[i] = static_cast<int>(i);
  for (size_t i = 0; i < L.rooms.size(); ++i) {
    for (size_t j = i + 1; j < L.rooms.size(); ++j) {
      const SharedWall w = sharedWall(L.rooms[i], L.rooms[j]);
      if (w.to - w.from < kDoorOverlap) continue;
      const int ci = component[i], cj = component[j];
      if (ci == cj && u(50 + i, j) > 0.3f) continue;  // already connected: rarely a second door
      for (int& c : component)
        if (c == cj) c = ci;
      const float at = roundToGrid(lerp(w.from + 0.7f, w.to - 0.7f, u(70 + i, j)));
      L.doors.push_back({static_cast<int>(i), static_cast<int>(j), at});
    }
  }
  return L;
}

std::vector<LayoutSpec> shippedLayouts() {
  std::vector<LayoutSpec> out;
  // One furnished living room.
  out.push_back({"room", {{0, 0, 5.5f, 4.5f, RoomKind::Living}}, {}, 2.7f, 11});
  // Living room, bedroom and kitchen around a hall, with doors.
  out.push_back({"apartment",
                 {{0, 0, 6.0f, 4.5f, RoomKind::Living},
                  {6.0f, 0, 10.0f, 4.5f, RoomKind::Bedroom},
                  {0, 4.5f, 4.0f, 8.0f, RoomKind::Kitchen},
                  {4.0f, 4.5f, 10.0f, 8.0f, RoomKind::Hall}},
                 {{0, 1, 3.0f}, {0, 2, 2.0f}, {0, 3, 5.0f}, {1, 3, 8.0f}, {2, 3, 6.25f, 1.2f}},
                 2.8f,
                 22});
  // An office and a bedroom off a living room.
  out.push_back({"studio",
                 {{0, 0, 5.0f, 5.0f, RoomKind::Living},
                  {5.0f, 0, 8.5f, 3.0f, RoomKind::Office},
                  {5.0f, 3.0f, 8.5f, 7.0f, RoomKind::Bedroom}},
                 {{0, 1, 1.5f}, {0, 2, 4.0f}, {1, 2, 6.75f}},
                 2.6f,
                 33});
  return out;
}

}  // namespace paircast
