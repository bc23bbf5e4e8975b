#include "render/ray_caster.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <mutex>

#include <omp.h>

#include "render/embree.h"
#include "render/packet_shading.h"
#include "render/texture_pyramid.h"
#include "util/error.h"

namespace paircast {
namespace {

constexpr int kPacket = kLanes;        // rays per rtcIntersect8 call: one row of a tile
constexpr int kTileW = 8;              // tile width in pixels (one packet)
constexpr int kTileH = 8;              // tile height in pixels (packets per tile)
static_assert(kTileH <= kMaxPackets);  // a tile's rows are shaded together
// Meshes this large get a medium-quality BVH, smaller ones a high-quality one (see RayCaster).
constexpr size_t kMediumQualityTriangles = 500'000;

void embreeError(void* /*user*/, RTCError code, const char* message) {
  spdlog::error("embree error {}: {}", static_cast<int>(code), message ? message : "");
}

// One Embree device per process: creating one costs milliseconds and threads.
RTCDevice sharedDevice() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d)
      throw Error("cannot create the Embree device (error " +
                  std::to_string(static_cast<int>(rtcGetDeviceError(nullptr))) + ")");
    rtcSetDeviceErrorFunction(d, embreeError, nullptr);
    return d;
  }();
  return device;
}

// Per-camera constants: world direction of pixel coordinates (x, y) is rowX*x + rowY*y + base.
struct PrimaryRays {
  Eigen::Vector3f org, dx, dy, d0;
  explicit PrimaryRays(const Camera& c) {
    const Eigen::Matrix3d M = c.R_cam2world * c.K.inverse();
    org = c.t_cam2world.cast<float>();
    dx = M.col(0).cast<float>();
    dy = M.col(1).cast<float>();
    d0 = M.col(2).cast<float>();
  }
};

// Fills a packet for pixels [x0, x0 + 8) of row y, at sub-pixel offset (sx, sy) in [0, 1).
inline void setupPacket(const PrimaryRays& P, int x0, int y, int width, float sx, float sy,
                        RTCRayHit8& rh, int* valid) {
  const float py = y + sy;
  for (int i = 0; i < kPacket; ++i) {
    const int x = x0 + i;
    valid[i] = x < width ? -1 : 0;
    const float px = x + sx;
    const Eigen::Vector3f d = P.dx * px + P.dy * py + P.d0;
    rh.ray.org_x[i] = P.org.x();
    rh.ray.org_y[i] = P.org.y();
    rh.ray.org_z[i] = P.org.z();
    rh.ray.dir_x[i] = d.x();
    rh.ray.dir_y[i] = d.y();
    rh.ray.dir_z[i] = d.z();
    rh.ray.tnear[i] = 0.0f;
    rh.ray.tfar[i] = std::numeric_limits<float>::infinity();
    rh.ray.time[i] = 0.0f;
    rh.ray.mask[i] = 0xFFFFFFFFu;  // Debian's Embree has ray masks on: 0 would hit nothing
    rh.ray.id[i] = static_cast<unsigned>(i);
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
}

// What shading needs besides the hit, fixed for one render.
PacketLight packetLight(const ShadingOptions& o, float sampleSize) {
  const Eigen::Vector3f sun = o.sunDirection.normalized();
  return {o.ambient,  o.headlight,
          o.sun,      {sun.x(), sun.y(), sun.z()},
          sampleSize, {o.background.x(), o.background.y(), o.background.z()}};
}

// Neighbouring rays of a small image are far apart, so the eight rays of a packet share little
// of their path through a deep BVH: over a large mesh Embree traverses them better as incoherent
// rays. At larger images, or over a small mesh whose BVH is shallow, the rays of a packet stay
// together and the coherent traversal wins. Meshes count as large from kMediumQualityTriangles,
// where the BVH quality changes too.
constexpr int kIncoherentPixels = 128 * 128;

inline embree::Query primaryQuery(int width, int height, bool largeMesh) {
  return embree::Query(largeMesh && width * height <= kIncoherentPixels ? embree::Rays::kIncoherent
                                                                        : embree::Rays::kCoherent);
}

}  // namespace

struct RayCaster::Impl {
  RTCScene scene = nullptr;
  std::vector<ShadeTriangle> triangles;  // [T], precomputed at build time; empty for scans
  std::vector<TexturePyramid> textures;  // one per Mesh::textures
  // Scans (no texture, colours per vertex): each triangle's corner colours, material factor
  // included, as 8-bit sRGB (R in the low byte): 12 bytes a triangle against a 64-byte
  // ShadeTriangle, since on a scan nearly every pixel hits a triangle of its own. The normal then
  // comes from Embree's hit.
  std::vector<std::array<uint32_t, 3>> corners;
  const Mesh* mesh = nullptr;
  bool largeMesh = false;  // at least kMediumQualityTriangles: medium BVH, incoherent small images
  // Fills the tables above from the mesh.
  void prepareShading(const Mesh& mesh);
  void renderTile(const PrimaryRays& P, const RenderOptions& options, const PacketLight& light,
                  int x0, int y0, Frame& frame) const;
  void writeGeometry(const RTCRayHit8& rh, const RenderOptions& options, int x0, int y, int cols,
                     Frame& frame) const;
  void shadeRows(const RTCRayHit8* rh, int rows, const PacketLight& light, LaneColours* rgb,
                 uint8_t* const* pixels, int cols) const;
  void shadeInPasses(const RTCRayHit8& rh, const PacketLight& light,
                     float (&rgb)[3][kPacket]) const;
  void surfaces(const RTCRayHit8& rh, PacketShading& s) const;
  void sampleTextures(PacketShading& s) const;
  Eigen::Vector3f unitNormal(const RTCRayHit8& rh, int i) const;
  static ShadeTriangle shadeTriangle(const Mesh& m, size_t t);
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
  }
};

void RayCaster::Impl::prepareShading(const Mesh& m) {
  mesh = &m;
  textures.reserve(m.textures.size());
  for (const Texture& t : m.textures) textures.emplace_back(t);
  bool textured = false, varying = false;
  for (const Material& mat : m.materials) textured = textured || mat.texture >= 0;
  for (const Eigen::Vector3f& c : m.colors) varying = varying || c != m.colors.front();
  if (!textured && varying) {
    corners.resize(m.numTriangles());
    for (size_t t = 0; t < m.numTriangles(); ++t) {
      const Eigen::Vector3f& factor = m.materials[m.triangleMaterial[t]].baseColor;
      for (int k = 0; k < 3; ++k)
        corners[t][k] = packSrgb8(factor.cwiseProduct(m.colors[m.triangles[t][k]]));
    }
    return;
  }
  triangles.resize(m.numTriangles());
  for (size_t t = 0; t < m.numTriangles(); ++t) triangles[t] = shadeTriangle(m, t);
}

ShadeTriangle RayCaster::Impl::shadeTriangle(const Mesh& m, size_t t) {
  const Eigen::Vector3i& tri = m.triangles[t];
  const Eigen::Vector3f& p0 = m.positions[tri[0]];
  // Embree's Ng is (p2 - p0) x (p1 - p0) ... up to sign; its sign is fixed at shading time.
  const Eigen::Vector3f n = (m.positions[tri[1]] - p0).cross(m.positions[tri[2]] - p0);
  const Material& mat = m.materials[m.triangleMaterial[t]];
  const bool sameColour =
      m.colors[tri[0]] == m.colors[tri[1]] && m.colors[tri[0]] == m.colors[tri[2]];
  ShadeTriangle s;
  s.normal = n.norm() > 0 ? n.normalized() : Eigen::Vector3f::UnitZ();
  s.texture = mat.texture;
  if (!sameColour && mat.texture < 0) {
    s.colour = ShadeTriangle::kPerVertex;
    for (int k = 0; k < 3; ++k)
      Eigen::Map<Eigen::Vector3f>(s.corners.rgb[k]) = mat.baseColor.cwiseProduct(m.colors[tri[k]]);
    return s;
  }
  s.colour = sameColour ? ShadeTriangle::kFlat : ShadeTriangle::kFromMesh;
  ShadeTriangle::Surface& f = s.surface;
  Eigen::Map<Eigen::Vector3f>(f.albedo) =
      sameColour ? mat.baseColor.cwiseProduct(m.colors[tri[0]]).eval() : mat.baseColor;
  const Eigen::Vector2f uv0 = m.uvs[tri[0]], duv1 = m.uvs[tri[1]] - uv0, duv2 = m.uvs[tri[2]] - uv0;
  Eigen::Map<Eigen::Vector2f>(f.uv0) = uv0;
  Eigen::Map<Eigen::Vector2f>(f.duv1) = duv1;
  Eigen::Map<Eigen::Vector2f>(f.duv2) = duv2;
  f.texelsPerMetre = 0.0f;
  if (mat.texture >= 0 && n.norm() > 0) {  // sqrt(texel area / world area)
    const Texture& tex = m.textures[mat.texture];
    const float uvArea = std::abs(duv1.x() * duv2.y() - duv1.y() * duv2.x());
    f.texelsPerMetre = std::sqrt(uvArea * tex.width * tex.height / n.norm());
  }
  return s;
}

RayCaster::RayCaster(const Mesh& mesh) : mesh_(mesh), impl_(std::make_unique<Impl>()) {
  const auto start = std::chrono::steady_clock::now();
  RTCDevice device = sharedDevice();
  impl_->scene = rtcNewScene(device);
  // High quality (spatial splits) pays on small scenes, which are built in no time and rendered
  // for long. On a scan of a million triangles and more it takes about twice medium's build time,
  // for no faster rendering.
  impl_->largeMesh = mesh.numTriangles() >= kMediumQualityTriangles;
  const RTCBuildQuality quality =
      impl_->largeMesh ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH;
  rtcSetSceneBuildQuality(impl_->scene, quality);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_NONE);

  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geom, quality);
  // rtcSetNewGeometryBuffer pads the buffer as Embree's SIMD loads require.
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.numVertices()));
  auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), mesh.numTriangles()));
  if (!vertices || !indices) {
    rtcReleaseGeometry(geom);
    throw Error("Embree could not allocate buffers for " + std::to_string(mesh.numTriangles()) +
                " triangles");
  }
  for (size_t i = 0; i < mesh.numVertices(); ++i) {
    vertices[3 * i] = mesh.positions[i].x();
    vertices[3 * i + 1] = mesh.positions[i].y();
    vertices[3 * i + 2] = mesh.positions[i].z();
  }
  for (size_t t = 0; t < mesh.numTriangles(); ++t) {
    for (int k = 0; k < 3; ++k) indices[3 * t + k] = static_cast<uint32_t>(mesh.triangles[t][k]);
  }
  impl_->prepareShading(mesh);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(impl_->scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(impl_->scene);
  const RTCError err = rtcGetDeviceError(device);
  if (err != RTC_ERROR_NONE)
    throw Error("Embree failed to build the scene (error " + std::to_string(int(err)) + ")");
  buildSeconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

RayCaster::~RayCaster() = default;

namespace {

// One 8x8 tile of z-depth: rows of packets, misses 0.
inline void depthTile(RTCScene scene, const PrimaryRays& P, int x0, int ty, int W, int H,
                      embree::Query& query, float* depth) {
  RTCRayHit8 rh;
  alignas(32) int valid[kPacket];
  for (int y = ty; y < std::min(ty + kTileH, H); ++y) {
    setupPacket(P, x0, y, W, 0.5f, 0.5f, rh, valid);
    query.intersect8(valid, scene, rh);
    float* row = depth + static_cast<size_t>(y) * W;
    for (int i = 0; i < kPacket && x0 + i < W; ++i)
      row[x0 + i] = rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID ? rh.ray.tfar[i] : 0.0f;
  }
}

int tilesAcross(int width) {
  return (width + kTileW - 1) / kTileW;
}

int tilesDown(int height) {
  return (height + kTileH - 1) / kTileH;
}

// Whether `items` of work go in this thread alone: one item, or OpenMP allowed one thread (as in
// generate_pairs' workers). A parallel region costs about 0.4 us even with one thread, a quarter
// of an 8x8 render's time, and screening makes dozens of those a pair.
bool inThisThread(long items) {
  return items <= 1 || omp_get_max_threads() == 1;
}

}  // namespace

void RayCaster::renderDepth(const Camera& camera, ImageF& depth) const {
  PAIRCAST_CHECK(camera.width > 0 && camera.height > 0);
  depth.resize(camera.width, camera.height, 1);
  const PrimaryRays P(camera);
  const int W = camera.width, H = camera.height;
  const int tilesX = tilesAcross(W), tilesY = tilesDown(H);
  RTCScene scene = impl_->scene;
  const bool largeMesh = impl_->largeMesh;
  // A row of tiles at a time: threads on neighbouring tiles of one row would write the same cache
  // lines of the output (false sharing).
  const auto render = [&](int tile) {
    embree::Query query = primaryQuery(W, H, largeMesh);
    depthTile(scene, P, (tile % tilesX) * kTileW, (tile / tilesX) * kTileH, W, H, query,
              depth.data.data());
  };
  const int tiles = tilesX * tilesY;
  if (inThisThread(tiles)) {
    for (int tile = 0; tile < tiles; ++tile) render(tile);
    return;
  }
#pragma omp parallel for schedule(dynamic, tilesX)
  for (int tile = 0; tile < tiles; ++tile) render(tile);
}

void RayCaster::renderDepthBatch(const Camera* cameras, ImageF* depths, size_t count) const {
  // Views are split across threads whole (a small view is a few tiles): no two threads write the
  // same image.
  std::vector<PrimaryRays> rays;
  rays.reserve(count);
  for (size_t k = 0; k < count; ++k) {
    PAIRCAST_CHECK(cameras[k].width > 0 && cameras[k].height > 0);
    depths[k].resize(cameras[k].width, cameras[k].height, 1);
    rays.emplace_back(cameras[k]);
  }
  RTCScene scene = impl_->scene;
  const bool largeMesh = impl_->largeMesh;
  const auto render = [&](size_t k) {
    const int W = cameras[k].width, H = cameras[k].height, tilesX = tilesAcross(W);
    embree::Query query = primaryQuery(W, H, largeMesh);
    for (int tile = 0; tile < tilesX * tilesDown(H); ++tile)
      depthTile(scene, rays[k], (tile % tilesX) * kTileW, (tile / tilesX) * kTileH, W, H, query,
                depths[k].data.data());
  };
  if (inThisThread(static_cast<long>(count))) {
    for (size_t k = 0; k < count; ++k) render(k);
    return;
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t k = 0; k < count; ++k) render(k);
}

bool RayCaster::hitsAtLeast(const Camera& camera, long count) const {
  PAIRCAST_CHECK(camera.width > 0 && camera.height > 0);
  const PrimaryRays P(camera);
  const int W = camera.width, H = camera.height;
  embree::Query query = primaryQuery(W, H, impl_->largeMesh);
  RTCRayHit8 rh;
  alignas(32) int valid[kPacket];
  long hits = 0, left = static_cast<long>(W) * H;
  for (int y = 0; y < H; ++y) {
    for (int x0 = 0; x0 < W; x0 += kPacket) {
      if (hits >= count) return true;
      if (hits + left < count) return false;
      setupPacket(P, x0, y, W, 0.5f, 0.5f, rh, valid);
      query.intersect8(valid, impl_->scene, rh);
      for (int i = 0; i < kPacket && x0 + i < W; ++i, --left)
        hits += rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID && rh.ray.tfar[i] > 0.0f;
    }
  }
  return hits >= count;
}

void RayCaster::render(const Camera& camera, const RenderOptions& options, Frame& frame) const {
  PAIRCAST_CHECK(camera.width > 0 && camera.height > 0);
  const int W = camera.width, H = camera.height;
  frame.depth.resize(W, H, 1);
  if (options.rgb) frame.rgb.resize(W, H, 3);
  if (options.normals) frame.normals.resize(W, H, 3);
  if (options.ids) {
    frame.triangleId.resize(W, H, 1);
    frame.materialId.resize(W, H, 1);
  }
  const PrimaryRays P(camera);
  const int ss = std::clamp(options.supersample, 1, 4);
  const PacketLight light =
      packetLight(options.shading, static_cast<float>(1.0 / (camera.K(0, 0) * ss)));
  const int tilesX = (W + kTileW - 1) / kTileW, tilesY = (H + kTileH - 1) / kTileH;
  const auto render = [&](int tile) {
    impl_->renderTile(P, options, light, (tile % tilesX) * kTileW, (tile / tilesX) * kTileH, frame);
  };
  const int tiles = tilesX * tilesY;
  if (inThisThread(tiles)) {
    for (int tile = 0; tile < tiles; ++tile) render(tile);
    return;
  }
#pragma omp parallel for schedule(dynamic, tilesX)  // rows of tiles, as renderDepth
  for (int tile = 0; tile < tiles; ++tile) render(tile);
}

// One 8x8 tile: the centre rays give the geometry maps (and the colour without supersampling);
// each further sub-sample adds a packet per row.
void RayCaster::Impl::renderTile(const PrimaryRays& P, const RenderOptions& options,
                                 const PacketLight& light, int x0, int y0, Frame& frame) const {
  const int W = frame.depth.width, H = frame.depth.height;
  const int rows = std::min(kTileH, H - y0), cols = std::min(kTileW, W - x0);
  const int ss = std::clamp(options.supersample, 1, 4);
  embree::Query query = primaryQuery(W, H, largeMesh);
  RTCRayHit8 rh[kTileH];
  alignas(32) int valid[kPacket];
  alignas(32) float colour[kTileH][3][kPacket];  // linear colour sums over the sub-samples
  // All rows are cast before any is shaded: shading is a chain of dependent loads, and eight of
  // them back to back overlap in the CPU where a cast between them would not.
  for (int r = 0; r < rows; ++r) {
    setupPacket(P, x0, y0 + r, W, 0.5f, 0.5f, rh[r], valid);
    query.intersect8(valid, scene, rh[r]);
    writeGeometry(rh[r], options, x0, y0 + r, cols, frame);
  }
  if (!options.rgb) return;
  if (ss == 1) {
    uint8_t* pixels[kTileH];
    for (int r = 0; r < rows; ++r) pixels[r] = frame.rgb.pixel(x0, y0 + r);
    shadeRows(rh, rows, light, colour, pixels, cols);
    return;
  }
  for (int sub = 0; sub < ss * ss; ++sub) {
    for (int r = 0; r < rows; ++r) {
      setupPacket(P, x0, y0 + r, W, (sub % ss + 0.5f) / ss, (sub / ss + 0.5f) / ss, rh[r], valid);
      query.intersect8(valid, scene, rh[r]);
    }
    alignas(32) LaneColours c[kTileH];
    shadeRows(rh, rows, light, c, nullptr, cols);
    for (int r = 0; r < rows; ++r)
      for (int k = 0; k < 3; ++k)
        for (int i = 0; i < kPacket; ++i)
          colour[r][k][i] = sub == 0 ? c[r][k][i] : colour[r][k][i] + c[r][k][i];
  }
  const float inv = 1.0f / static_cast<float>(ss * ss);
  for (int r = 0; r < rows; ++r) srgbLanes(colour[r], inv, cols, frame.rgb.pixel(x0, y0 + r));
}

// Depth, and the normals and ids when asked, of the first `cols` rays of a packet on row y.
void RayCaster::Impl::writeGeometry(const RTCRayHit8& rh, const RenderOptions& options, int x0,
                                    int y, int cols, Frame& frame) const {
  const size_t row = static_cast<size_t>(y) * frame.depth.width + x0;
  for (int i = 0; i < cols; ++i) {
    const bool hit = rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
    frame.depth.data[row + i] = hit ? rh.ray.tfar[i] : 0.0f;
  }
  if (!options.normals && !options.ids) return;
  for (int i = 0; i < cols; ++i) {
    const size_t pix = row + i;
    const bool hit = rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
    const int prim = hit ? static_cast<int>(rh.hit.primID[i]) : -1;
    if (options.normals) {
      Eigen::Vector3f n = Eigen::Vector3f::Zero();
      if (hit) {
        n = unitNormal(rh, i);
        const Eigen::Vector3f d(rh.ray.dir_x[i], rh.ray.dir_y[i], rh.ray.dir_z[i]);
        if (n.dot(d) > 0) n = -n;
      }
      for (int c = 0; c < 3; ++c) frame.normals.data[3 * pix + c] = n[c];
    }
    if (options.ids) {
      frame.triangleId.data[pix] = prim;
      frame.materialId.data[pix] = hit ? mesh->triangleMaterial[prim] : -1;
    }
  }
}

// Linear colours of a tile's rows: albedo (material, vertex colours, texture) times ambient,
// headlight and sun terms; the background on a miss. With `pixels` (no supersampling), each row's
// first `cols` colours go to pixels[r] as 8-bit sRGB instead. Rows that hit only kFlat triangles
// (over a scene of large triangles, nearly all) in SIMD lanes, together; the others (vertex
// colours, scans) in passes over the eight lanes that gather the records, light, sample the
// textures, combine.
void RayCaster::Impl::shadeRows(const RTCRayHit8* rh, int rows, const PacketLight& light,
                                LaneColours* rgb, uint8_t* const* pixels, int cols) const {
  uint32_t done = 0;
  if (!triangles.empty()) {
    RayLanes lanes[kTileH];
    PacketOut out[kTileH];
    static_assert(RTC_INVALID_GEOMETRY_ID == ~0u);
    for (int r = 0; r < rows; ++r) {
      lanes[r] = {rh[r].hit.geomID, rh[r].hit.primID, rh[r].ray.dir_x, rh[r].ray.dir_y,
                  rh[r].ray.dir_z,  rh[r].ray.tfar,   rh[r].hit.u,     rh[r].hit.v};
      out[r] = {&rgb[r], pixels ? pixels[r] : nullptr, cols};
    }
    done = shadeFlatPackets({triangles.data(), textures.data()}, lanes, rows, light, out);
  }
  for (int r = 0; r < rows; ++r) {
    if ((done >> r) & 1) continue;
    shadeInPasses(rh[r], light, rgb[r]);
    if (pixels) srgbLanes(rgb[r], 1.0f, cols, pixels[r]);
  }
}

// shadeRows as passes over the eight lanes (the scalar code the SIMD path matches).
void RayCaster::Impl::shadeInPasses(const RTCRayHit8& rh, const PacketLight& light,
                                    float (&rgb)[3][kPacket]) const {
  PacketShading s;
  surfaces(rh, s);
  lightLanes(rh.ray.dir_x, rh.ray.dir_y, rh.ray.dir_z, rh.ray.tfar, light, s);
  sampleTextures(s);
  combineLanes(s, light, rgb);
}

// Per lane, what the hit triangle gives: its normal, albedo, and texture and coordinates.
void RayCaster::Impl::surfaces(const RTCRayHit8& rh, PacketShading& s) const {
  for (int i = 0; i < kPacket; ++i) {
    s.texture[i] = -1;
    s.u[i] = s.v[i] = s.texelsPerMetre[i] = 0.0f;
    s.n[0][i] = s.n[1][i] = s.albedo[0][i] = s.albedo[1][i] = s.albedo[2][i] = 0.0f;
    s.n[2][i] = 1.0f;
    if (rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) continue;
    s.hits |= 1u << i;
    const int prim = static_cast<int>(rh.hit.primID[i]);
    const float u = rh.hit.u[i], v = rh.hit.v[i], w = 1.0f - u - v;
    Eigen::Vector3f a;
    if (triangles.empty()) {  // a scan: corner colours, Embree's normal
      const std::array<uint32_t, 3>& c = corners[prim];
      a = w * unpackSrgb8(c[0]) + u * unpackSrgb8(c[1]) + v * unpackSrgb8(c[2]);
      const Eigen::Vector3f n = unitNormal(rh, i);
      for (int k = 0; k < 3; ++k) s.n[k][i] = n[k];
    } else {
      const ShadeTriangle& t = triangles[prim];
      for (int k = 0; k < 3; ++k) s.n[k][i] = t.normal[k];
      if (t.colour == ShadeTriangle::kPerVertex) {
        using V = Eigen::Map<const Eigen::Vector3f>;
        a = w * V(t.corners.rgb[0]) + u * V(t.corners.rgb[1]) + v * V(t.corners.rgb[2]);
      } else {
        const ShadeTriangle::Surface& f = t.surface;
        a = Eigen::Map<const Eigen::Vector3f>(f.albedo);
        if (t.colour == ShadeTriangle::kFromMesh) {
          const Eigen::Vector3i& tri = mesh->triangles[prim];
          a = a.cwiseProduct(w * mesh->colors[tri[0]] + u * mesh->colors[tri[1]] +
                             v * mesh->colors[tri[2]]);
        }
        if (t.texture >= 0) {
          s.texture[i] = t.texture;
          s.u[i] = f.uv0[0] + u * f.duv1[0] + v * f.duv2[0];
          s.v[i] = f.uv0[1] + u * f.duv1[1] + v * f.duv2[1];
          s.texelsPerMetre[i] = f.texelsPerMetre;
        }
      }
    }
    for (int k = 0; k < 3; ++k) s.albedo[k][i] = a[k];
  }
}

// Each textured lane's texture colour, sampled for all lanes of one texture at once.
void RayCaster::Impl::sampleTextures(PacketShading& s) const {
  const int first = s.texture[0];
  bool same = true;
  for (int i = 1; i < kPacket; ++i) same &= s.texture[i] == first;
  if (same) {  // the common case: one texture (or none) for all lanes
    if (first >= 0) textures[first].sample8(s.u, s.v, s.level, (1u << kPacket) - 1, s.texel);
    return;
  }
  uint32_t todo = 0;
  for (int i = 0; i < kPacket; ++i) todo |= static_cast<uint32_t>(s.texture[i] >= 0) << i;
  while (todo) {
    const int t = s.texture[__builtin_ctz(todo)];
    uint32_t lanes = 0;
    for (int i = 0; i < kPacket; ++i) lanes |= static_cast<uint32_t>(s.texture[i] == t) << i;
    textures[t].sample8(s.u, s.v, s.level, lanes, s.texel);
    todo &= ~lanes;
  }
}

// Unit geometric normal of ray i's triangle, either sign.
Eigen::Vector3f RayCaster::Impl::unitNormal(const RTCRayHit8& rh, int i) const {
  if (!triangles.empty()) return triangles[rh.hit.primID[i]].normal;
  const Eigen::Vector3f ng(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]);
  const float norm = ng.norm();
  return norm > 0 ? Eigen::Vector3f(ng / norm) : Eigen::Vector3f::UnitZ();
}

namespace {

// rays[k0, k0 + 8) as a packet; lanes past `count` are invalid (and repeat the last ray).
void loadPacket(const Ray* rays, size_t k0, size_t count, RTCRay8& packet, int* valid) {
  for (size_t i = 0; i < kPacket; ++i) {
    const size_t k = k0 + i;
    valid[i] = k < count ? -1 : 0;
    const Ray& r = rays[std::min(k, count - 1)];
    packet.org_x[i] = r.origin.x();
    packet.org_y[i] = r.origin.y();
    packet.org_z[i] = r.origin.z();
    packet.dir_x[i] = r.direction.x();
    packet.dir_y[i] = r.direction.y();
    packet.dir_z[i] = r.direction.z();
    packet.tnear[i] = r.tnear;
    packet.tfar[i] = r.tfar;
    packet.time[i] = 0.0f;
    packet.mask[i] = 0xFFFFFFFFu;
    packet.id[i] = static_cast<unsigned>(i);
    packet.flags[i] = 0;
  }
}

}  // namespace

// Packets of eight (shadow rays from one eye are coherent enough to traverse together).
void RayCaster::occluded(const Ray* rays, uint8_t* blocked, size_t count) const {
  RTCScene scene = impl_->scene;
  embree::Query query;
  for (size_t k0 = 0; k0 < count; k0 += kPacket) {
    alignas(32) RTCRay8 packet;
    alignas(32) int valid[kPacket];
    loadPacket(rays, k0, count, packet, valid);
    query.occluded8(valid, scene, packet);
    for (size_t i = 0; i < kPacket && k0 + i < count; ++i)
      blocked[k0 + i] = packet.tfar[i] < 0.0f ? 1 : 0;
  }
}

// Packets of eight consecutive rays: callers pass neighbours in turn (a footprint's rays, a row
// of columns), which traverse together.
void RayCaster::intersect(const Ray* rays, Hit* hits, size_t count) const {
  RTCScene scene = impl_->scene;
  const long packets = static_cast<long>((count + kPacket - 1) / kPacket);
  const auto cast = [&](long p) {
    embree::Query query;
    alignas(32) RTCRayHit8 rh;
    alignas(32) int valid[kPacket];
    const size_t k0 = static_cast<size_t>(p) * kPacket;
    loadPacket(rays, k0, count, rh.ray, valid);
    for (size_t i = 0; i < kPacket; ++i) {
      rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    query.intersect8(valid, scene, rh);
    for (size_t i = 0; i < kPacket && k0 + i < count; ++i) {
      Hit& h = hits[k0 + i];
      if (rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) {
        h = Hit{};
        continue;
      }
      h.t = rh.ray.tfar[i];
      h.triangle = static_cast<int32_t>(rh.hit.primID[i]);
      h.normal = Eigen::Vector3f(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]).normalized();
    }
  };
  if (inThisThread(packets)) {
    for (long p = 0; p < packets; ++p) cast(p);
    return;
  }
#pragma omp parallel for schedule(static, 32)
  for (long p = 0; p < packets; ++p) cast(p);
}

double validFraction(const ImageF& depth) {
  size_t valid = 0;
  for (float d : depth.data) valid += d > 0.0f;
  return depth.data.empty() ? 0.0 : static_cast<double>(valid) / depth.data.size();
}

double Frame::validFraction() const {
  return paircast::validFraction(depth);
}

}  // namespace paircast
