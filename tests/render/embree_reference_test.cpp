// Embree 3 and Embree 4 builds are held to one answer: the shipped apartment seen from fixed
// cameras must give the stored depth and triangle ids (tests/data/embree_reference.bin). The
// tolerance catches a changed ray convention (a half-pixel shift, a lost tnear, another z-depth)
// while allowing the two versions' BVHs to split ties on shared edges differently.
//
// PAIRCAST_WRITE_EMBREE_REFERENCE=1 rewrites the file from this build instead of checking it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "test_paths.h"
#include "util/error.h"

namespace paircast {
namespace {

constexpr int kWidth = 128, kHeight = 96;
constexpr double kHfov = 75.0;
constexpr char kMagic[8] = {'P', 'C', 'E', 'M', 'B', 'R', 'F', '1'};

std::string referencePath() {
  return testing::sourceDir() + "/tests/data/embree_reference.bin";
}

// Cameras placed from the mesh's bounds: at eye height in the middle of the flat, turned to four
// headings, plus one looking down across it from a corner, so that walls at grazing angles,
// furniture edges and far surfaces are all in view.
std::vector<Camera> referenceCameras(const Scene& scene) {
  const MeshStats s = computeStats(scene.mesh);
  const Eigen::Vector3d lo = s.boundsMin.cast<double>(), hi = s.boundsMax.cast<double>();
  const Eigen::Vector3d up = scene.upVector().cast<double>();
  const Eigen::Vector3d mid = 0.5 * (lo + hi);
  const Eigen::Vector3d eye = mid - up * (mid.dot(up) - lo.dot(up) - 1.5);
  std::vector<Camera> cameras;
  for (int k = 0; k < 4; ++k) {
    const double a = 0.3 + k * M_PI / 2;
    const Eigen::Vector3d flat = up.unitOrthogonal();
    const Eigen::Vector3d dir = std::cos(a) * flat + std::sin(a) * up.cross(flat);
    Camera c = Camera::fromHfov(kWidth, kHeight, kHfov);
    c.lookAt(eye, eye + dir - 0.15 * up, up);
    cameras.push_back(c);
  }
  Camera corner = Camera::fromHfov(kWidth, kHeight, kHfov);
  const Eigen::Vector3d from = lo + 0.1 * (hi - lo) + up * (2.2 - 0.1 * (hi - lo).dot(up));
  corner.lookAt(from, mid - up * (mid.dot(up) - lo.dot(up)), up);
  cameras.push_back(corner);
  return cameras;
}

struct Reference {
  std::vector<ImageF> depth;
  std::vector<ImageI> triangle;
};

// Depth and triangle ids of `cameras`.
Reference renderReference(const Scene& scene, const std::vector<Camera>& cameras) {
  const RayCaster caster(scene.mesh);
  RenderOptions options;
  options.rgb = false;
  options.normals = false;
  Reference out;
  for (const Camera& c : cameras) {
    Frame f;
    caster.render(c, options, f);
    out.depth.push_back(f.depth);
    out.triangle.push_back(f.triangleId);
  }
  return out;
}

void writeReference(const Reference& r, const std::string& path) {
  std::ofstream out(path, std::ios::binary);
  out.write(kMagic, sizeof kMagic);
  const int32_t header[3] = {static_cast<int32_t>(r.depth.size()), kWidth, kHeight};
  out.write(reinterpret_cast<const char*>(header), sizeof header);
  for (size_t i = 0; i < r.depth.size(); ++i) {
    out.write(reinterpret_cast<const char*>(r.depth[i].data.data()), kWidth * kHeight * 4);
    out.write(reinterpret_cast<const char*>(r.triangle[i].data.data()), kWidth * kHeight * 4);
  }
  if (!out) throw Error(path + ": cannot write the Embree reference");
}

Reference readReference(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char magic[sizeof kMagic];
  int32_t header[3];
  in.read(magic, sizeof magic);
  in.read(reinterpret_cast<char*>(header), sizeof header);
  if (!in || std::string(magic, sizeof magic) != std::string(kMagic, sizeof kMagic) ||
      header[1] != kWidth || header[2] != kHeight || header[0] < 1 || header[0] > 64)
    throw Error(path + ": not an Embree reference of " + std::to_string(kWidth) + "x" +
                std::to_string(kHeight));
  Reference r;
  for (int i = 0; i < header[0]; ++i) {
    r.depth.emplace_back();
    r.triangle.emplace_back();
    r.depth.back().resize(kWidth, kHeight, 1);
    r.triangle.back().resize(kWidth, kHeight, 1);
    in.read(reinterpret_cast<char*>(r.depth.back().data.data()), kWidth * kHeight * 4);
    in.read(reinterpret_cast<char*>(r.triangle.back().data.data()), kWidth * kHeight * 4);
  }
  if (!in) throw Error(path + ": truncated Embree reference");
  return r;
}

struct Agreement {
  size_t pixels = 0, sameHit = 0, depthOff = 0;
  double maxDepthError = 0;
};

// Same hit: the same triangle, or a miss in both. Depth is compared where the hit is the same.
Agreement compare(const Reference& ref, const Reference& now) {
  Agreement a;
  for (size_t i = 0; i < ref.depth.size(); ++i)
    for (size_t p = 0; p < ref.depth[i].data.size(); ++p) {
      ++a.pixels;
      if (ref.triangle[i].data[p] != now.triangle[i].data[p]) continue;
      ++a.sameHit;
      const double e = std::abs(double(ref.depth[i].data[p]) - now.depth[i].data[p]);
      a.maxDepthError = std::max(a.maxDepthError, e);
      a.depthOff += e > 1e-4;
    }
  return a;
}

Scene apartment() {
  return loadScene(testing::sourceDir() + "/scenes/apartment/apartment.obj");
}

TEST(EmbreeReference, ApartmentDepthAndTrianglesMatchTheStoredReference) {
  const Scene scene = apartment();
  const Reference now = renderReference(scene, referenceCameras(scene));
  if (const char* w = std::getenv("PAIRCAST_WRITE_EMBREE_REFERENCE"); w && std::string(w) == "1") {
    writeReference(now, referencePath());
    GTEST_SKIP() << "wrote " << referencePath();
  }
  const Reference ref = readReference(referencePath());
  ASSERT_EQ(ref.depth.size(), now.depth.size()) << "cameras in " << referencePath();
  // The views must see the scene: a reference of misses would hold nothing to.
  size_t hits = 0;
  for (const ImageI& t : ref.triangle)
    for (int32_t id : t.data) hits += id >= 0;
  ASSERT_GT(hits, ref.depth.size() * kWidth * kHeight * 9 / 10);
  const Agreement a = compare(ref, now);
  EXPECT_GE(static_cast<double>(a.sameHit) / a.pixels, 0.999)
      << a.pixels - a.sameHit << " of " << a.pixels << " pixels hit another triangle";
  EXPECT_EQ(a.depthOff, 0u) << "pixels whose depth moved by more than 1e-4 m; the largest move "
                            << a.maxDepthError << " m";
}

// The comparison itself: a half-pixel shift of every ray (pixel corners instead of centres) is
// caught, so the tolerance above is tight enough to hold the convention.
TEST(EmbreeReference, AHalfPixelShiftFailsTheComparison) {
  const Scene scene = apartment();
  std::vector<Camera> cameras = referenceCameras(scene);
  const Reference ref = renderReference(scene, cameras);
  for (Camera& c : cameras) {
    c.K(0, 2) += 0.5;
    c.K(1, 2) += 0.5;
  }
  const Agreement a = compare(ref, renderReference(scene, cameras));
  EXPECT_TRUE(static_cast<double>(a.sameHit) / a.pixels < 0.999 || a.depthOff > 0);
  EXPECT_GT(a.depthOff, a.pixels / 10);
}

TEST(EmbreeReference, ABadReferenceFileIsAClearError) {
  const std::string dir = testing::scratchDir("bad");
  std::ofstream(dir + "/ref.bin") << "not a reference";
  try {
    readReference(dir + "/ref.bin");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(dir + "/ref.bin"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace paircast
