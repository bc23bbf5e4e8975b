// bench_render: rays/s of depth-only and RGB+depth rendering, against the Embree bound (a
// minimal rtcIntersect8 loop over the same rays, measured in the same run), and scene build time.
#include <omp.h>

#include <unistd.h>
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#include "util/image_io.h"

#include "render/embree.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "util/error.h"

using namespace paircast;
using Clock = std::chrono::steady_clock;

namespace {

double seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

// Best of `reps` timings of `fn`, each repeated until it ran for at least `minSeconds`.
template <typename F>
double bestSecondsPerCall(F&& fn, int reps = 5, double minSeconds = 0.25) {
  double best = 1e30;
  for (int r = 0; r < reps; ++r) {
    int calls = 0;
    auto start = Clock::now();
    do {
      fn();
      ++calls;
    } while (seconds(start) < minSeconds);
    best = std::min(best, seconds(start) / calls);
  }
  return best;
}

// The bound: the same primary rays, traced with rtcIntersect8 over OpenMP tiles, doing nothing
// with the result but a running sum to keep the compiler honest. Its own BVH over the same mesh.
struct EmbreeBound {
  RTCDevice device;
  RTCScene scene;
  explicit EmbreeBound(const Mesh& mesh) {
    device = rtcNewDevice(nullptr);
    scene = rtcNewScene(device);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, mesh.numVertices()));
    auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, mesh.numTriangles()));
    std::memcpy(v, mesh.positions.data(), 12 * mesh.numVertices());
    std::memcpy(idx, mesh.triangles.data(), 12 * mesh.numTriangles());
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(scene);
  }
  ~EmbreeBound() {
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
  }
  double trace(const Camera& c) const {
    const Eigen::Matrix3f M = (c.R_cam2world * c.K.inverse()).cast<float>();
    const Eigen::Vector3f o = c.t_cam2world.cast<float>();
    const int W = c.width, H = c.height, tilesX = (W + 7) / 8, tilesY = (H + 7) / 8;
    double sum = 0;
#pragma omp parallel for schedule(dynamic, tilesX) reduction(+ : sum)  // as RayCaster
    for (int tile = 0; tile < tilesX * tilesY; ++tile) {
      embree::Query query(embree::Rays::kCoherent);
      RTCRayHit8 rh;
      alignas(32) int valid[8];
      const int x0 = (tile % tilesX) * 8, y0 = (tile / tilesX) * 8;
      for (int y = y0; y < std::min(y0 + 8, H); ++y) {
        for (int i = 0; i < 8; ++i) {
          valid[i] = x0 + i < W ? -1 : 0;
          const Eigen::Vector3f d = M * Eigen::Vector3f(x0 + i + 0.5f, y + 0.5f, 1.0f);
          rh.ray.org_x[i] = o.x(), rh.ray.org_y[i] = o.y(), rh.ray.org_z[i] = o.z();
          rh.ray.dir_x[i] = d.x(), rh.ray.dir_y[i] = d.y(), rh.ray.dir_z[i] = d.z();
          rh.ray.tnear[i] = 0, rh.ray.tfar[i] = 1e30f, rh.ray.time[i] = 0;
          rh.ray.mask[i] = 0xFFFFFFFFu, rh.ray.id[i] = i, rh.ray.flags[i] = 0;
          rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        }
        query.intersect8(valid, scene, rh);
        for (int i = 0; i < 8; ++i) sum += rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
      }
    }
    return sum;
  }
};

// A camera inside the scene: at the bounds' centre, 1.5 m above the lowest point, looking along
// the first horizontal axis.
Camera defaultCamera(const Scene& scene, int resolution) {
  const MeshStats s = computeStats(scene.mesh);
  const Eigen::Vector3d up = scene.upVector().cast<double>();
  Eigen::Vector3d eye = (0.5 * (s.boundsMin + s.boundsMax)).cast<double>();
  eye -= eye.dot(up) * up;
  eye += (s.boundsMin.cast<double>().dot(up) + 1.5) * up;
  Camera c = Camera::fromHfov(resolution, resolution, 60.0);
  c.lookAt(eye, eye + up.unitOrthogonal(), up);
  return c;
}

// A 224 x 224-cell height field: 100,352 triangles, to time the BVH build at the target's size.
Mesh syntheticMesh() {
  Mesh m;
  const int mat = m.addMaterial(Material{});
  const int n = 224;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      m.positions.emplace_back(0.05f * i, 0.1f * std::sin(0.3f * i) * std::cos(0.2f * j),
                               0.05f * j);
      m.uvs.emplace_back(0.0f, 0.0f);
      m.colors.emplace_back(1.0f, 1.0f, 1.0f);
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.triangles.emplace_back(a, b, d);
      m.triangles.emplace_back(a, d, c);
      m.triangleMaterial.insert(m.triangleMaterial.end(), 2, mat);
    }
  return m;
}

// Runs ../shared/tools/ref_raycast.py (Open3D) on the same mesh, camera and rays: its speed, and
// its agreement with our depth. Returns the SUMMARY fields, or an empty object when unavailable.
nlohmann::json open3dReference(const std::string& mesh, const Camera& cam, const ImageF& depth) {
  const std::string tool =
      (std::filesystem::path(PAIRCAST_SOURCE_DIR).parent_path() / "shared/tools/ref_raycast.py")
          .string();
  if (!std::filesystem::exists(tool) ||
      std::system("/usr/bin/python3 -c 'import open3d' 2>/dev/null") != 0)
    return {};
  const auto dir =
      std::filesystem::temp_directory_path() / ("bench_render_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  writeCameraJson((dir / "cam.json").string(), cam);
  writeExr((dir / "ours.exr").string(), depth);
  const std::string cmd = "/usr/bin/python3 " + tool + " --mesh '" + mesh + "' --camera " +
                          (dir / "cam.json").string() + " --compare " +
                          (dir / "ours.exr").string() + " --bench --repeat 10 --threads " +
                          std::to_string(omp_get_max_threads()) +
                          " 2>&1 | grep '^SUMMARY' | tail -1";
  nlohmann::json out;
  if (FILE* p = popen(cmd.c_str(), "r")) {
    char buf[4096];
    std::string line;
    while (fgets(buf, sizeof buf, p)) line += buf;
    pclose(p);
    std::istringstream is(line);
    std::string tok;
    while (is >> tok) {
      const auto eq = tok.find('=');
      if (eq == std::string::npos) continue;
      try {
        out[tok.substr(0, eq)] = std::stod(tok.substr(eq + 1));
      } catch (...) {
        out[tok.substr(0, eq)] = tok.substr(eq + 1);
      }
    }
  }
  std::filesystem::remove_all(dir);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scenePath, up = "y", cameraPath;
  std::vector<int> resolutions;
  CLI::App app{"Rendering speed against the Embree bound"};
  app.add_option("--scene", scenePath, "Scene (default: the shipped apartment)");
  app.add_option("--up", up, "Up axis: y or z")->check(CLI::IsMember({"y", "z"}));
  app.add_option("--camera", cameraPath, "Camera JSON (default: a view from the scene's centre)");
  app.add_option("--resolution", resolutions, "Image sizes (default 256 512)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (scenePath.empty())
      scenePath = std::string(PAIRCAST_SOURCE_DIR) + "/scenes/apartment/apartment.obj";
    if (resolutions.empty()) resolutions = {256, 512};
    LoadOptions lo;
    lo.up = parseUpAxis(up);
    Scene scene = loadScene(scenePath, lo);
    std::printf("scene %s: %s\n", scenePath.c_str(), computeStats(scene.mesh).summary().c_str());
    std::printf("threads: %d\n", omp_get_max_threads());
    auto t0 = Clock::now();
    RayCaster caster(scene.mesh);
    const double build = seconds(t0);
    std::printf("BVH build: %.3f s for %zu triangles\n", build, scene.mesh.numTriangles());
    const Mesh synthetic = syntheticMesh();
    t0 = Clock::now();
    { RayCaster big(synthetic); }
    const double build100k = seconds(t0);
    std::printf("BVH build: %.3f s for a synthetic %zu-triangle mesh (target: under 1 s)\n",
                build100k, synthetic.numTriangles());
    EmbreeBound bound(scene.mesh);

    nlohmann::json last;
    for (int res : resolutions) {
      Camera cam = cameraPath.empty() ? defaultCamera(scene, res) : readCameraJson(cameraPath);
      if (!cameraPath.empty() && res != cam.width) {
        const double s = static_cast<double>(res) / cam.width;
        cam.K.topRows<2>() *= s;
        cam.width = res;
        cam.height = static_cast<int>(std::lround(cam.height * s));
      }
      const double rays = static_cast<double>(cam.width) * cam.height;
      ImageF depth;
      Frame frame;
      RenderOptions rgbd;
      rgbd.normals = false;
      rgbd.ids = false;
      // Interleave the three so that machine noise hits them alike.
      double tBound = 1e30, tDepth = 1e30, tRgbd = 1e30;
      for (int round = 0; round < 3; ++round) {
        tBound = std::min(tBound, bestSecondsPerCall([&] { bound.trace(cam); }, 2));
        tDepth = std::min(tDepth, bestSecondsPerCall([&] { caster.renderDepth(cam, depth); }, 2));
        tRgbd = std::min(tRgbd, bestSecondsPerCall([&] { caster.render(cam, rgbd, frame); }, 2));
      }
      size_t hits = 0;
      for (float d : depth.data) hits += d > 0;
      const double mBound = rays / tBound / 1e6, mDepth = rays / tDepth / 1e6,
                   mRgbd = rays / tRgbd / 1e6;
      std::printf(
          "%dx%d (%.1f%% hit): embree bound %.2f Mrays/s | depth %.2f Mrays/s (%.1f%% of "
          "bound) | rgb+depth %.2f Mrays/s (%.2fx depth time)\n",
          cam.width, cam.height, 100.0 * hits / rays, mBound, mDepth, 100.0 * mDepth / mBound,
          mRgbd, tRgbd / tDepth);
      const nlohmann::json o3d = open3dReference(scenePath, cam, depth);
      if (o3d.contains("best_Mrays/s")) {
        const double m = o3d["best_Mrays/s"].get<double>();
        std::printf(
            "  open3d cast_rays %.2f Mrays/s: ours depth-only %.2fx faster; depth agreement "
            "within 1 mm: %.4f%% of pixels\n",
            m, mDepth / m, 100.0 * o3d.value("agree_1mm", 0.0));
      } else {
        std::printf("  open3d comparison skipped (needs ../shared/tools and python3-open3d)\n");
      }
      last = {{"scene", scenePath},
              {"resolution", res},
              {"mrays_depth", mDepth},
              {"mrays_rgbd", mRgbd},
              {"mrays_embree_bound", mBound},
              {"build_seconds", build},
              {"build_seconds_100k", build100k},
              {"triangles", scene.mesh.numTriangles()}};
      if (o3d.contains("best_Mrays/s")) {
        last["mrays_open3d"] = o3d["best_Mrays/s"];
        last["agree_1mm_open3d"] = o3d.value("agree_1mm", 0.0);
      }
    }
    std::printf("%s\n", last.dump().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_render: error: %s\n", e.what());
    return 1;
  }
}
