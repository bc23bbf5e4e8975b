#include "render/ray_caster.h"

#include <gtest/gtest.h>
#include <omp.h>

#include "render/render_albedo.h"
#include "util/random.h"

namespace paircast {
namespace {

// An axis-aligned quad (two triangles) spanning [x0, x1] x [y0, y1] at depth z, facing -z.
void addQuadZ(Mesh& m, float x0, float x1, float y0, float y1, float z, int material) {
  m.addTriangle({x0, y0, z}, {x1, y0, z}, {x1, y1, z}, material, {0, 0}, {1, 0}, {1, 1});
  m.addTriangle({x0, y0, z}, {x1, y1, z}, {x0, y1, z}, material, {0, 0}, {1, 1}, {0, 1});
}

Mesh planeMesh(float z, float halfSize = 1000.0f) {
  Mesh m;
  int mat = m.addMaterial(Material{});
  addQuadZ(m, -halfSize, halfSize, -halfSize, halfSize, z, mat);
  return m;
}

// A cube [-1, 1]^3 seen from inside.
Mesh insideCube() {
  Mesh m;
  int mat = m.addMaterial(Material{});
  const Eigen::Vector3f c[8] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
  const int faces[6][4] = {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4},
                           {2, 3, 7, 6}, {0, 3, 7, 4}, {1, 2, 6, 5}};
  for (const auto& f : faces) {
    m.addTriangle(c[f[0]], c[f[1]], c[f[2]], mat);
    m.addTriangle(c[f[0]], c[f[2]], c[f[3]], mat);
  }
  return m;
}

TEST(RayCaster, PlaneDepthIsExactAtEveryPixel) {
  Rng rng(3);
  for (int trial = 0; trial < 5; ++trial) {
    const float z = static_cast<float>(rng.uniform(0.5, 20.0));
    const Mesh mesh = planeMesh(z);
    RayCaster caster(mesh);
    Camera cam = Camera::fromHfov(97, 61, rng.uniform(30, 100));  // odd sizes: partial packets
    ImageF depth;
    caster.renderDepth(cam, depth);
    ASSERT_EQ(depth.width, 97);
    ASSERT_EQ(depth.height, 61);
    for (float d : depth.data) ASSERT_NEAR(d, z, 1e-4f);
    Frame frame;
    caster.render(cam, RenderOptions{}, frame);
    for (float d : frame.depth.data) ASSERT_NEAR(d, z, 1e-4f);
  }
}

TEST(RayCaster, TiltedPlaneDepthMatchesAnalyticZDepth) {
  // Plane n.p = c seen from a rotated camera: z-depth of pixel ray r (camera frame, z = 1) is
  // (c - n.o) / (n.(R r)).
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, 1.0, -0.3).normalized();
  const double c = -1.3;
  Mesh mesh;
  int mat = mesh.addMaterial(Material{});
  const Eigen::Vector3d a = n.unitOrthogonal(), b = n.cross(a), p0 = c * n;
  auto corner = [&](double s, double t) {
    return (p0 + 500 * s * a + 500 * t * b).cast<float>().eval();
  };
  mesh.addTriangle(corner(-1, -1), corner(1, -1), corner(1, 1), mat);
  mesh.addTriangle(corner(-1, -1), corner(1, 1), corner(-1, 1), mat);
  RayCaster caster(mesh);
  Camera cam = Camera::fromHfov(64, 48, 70);
  cam.lookAt({0.1, 0.2, 0.3}, {2, -1.5, 1}, {0, 1, 0});
  ImageF depth;
  caster.renderDepth(cam, depth);
  int checked = 0;
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d r = cam.R_cam2world * cam.rayCamera(u + 0.5, v + 0.5);
      const double t = (c - n.dot(cam.t_cam2world)) / n.dot(r);
      const float d = depth.data[v * cam.width + u];
      if (t > 0 && t < 200) {  // well inside the finite quad
        ASSERT_NEAR(d, t, 1e-4 * std::max(1.0, t)) << u << "," << v;
        ++checked;
      } else if (t <= 0) {
        ASSERT_EQ(d, 0.0f);
      }
    }
  }
  EXPECT_GT(checked, 100);
}

TEST(RayCaster, BoxSeenFromInside) {
  const Mesh mesh = insideCube();
  RayCaster caster(mesh);
  Camera cam = Camera::fromHfov(64, 64, 120.0);  // wide: the side walls are in view
  cam.lookAt({0, 0, 0}, {1, 0, 0}, {0, 0, 1});
  Frame frame;
  caster.render(cam, RenderOptions{}, frame);
  EXPECT_DOUBLE_EQ(frame.validFraction(), 1.0);
  for (int v = 0; v < 64; ++v) {
    for (int u = 0; u < 64; ++u) {
      const Eigen::Vector3d r = cam.rayCamera(u + 0.5, v + 0.5);
      // Along the ray, the wall reached first is at distance 1 on the dominant axis.
      const double expected = 1.0 / std::max({1.0, std::abs(r.x()), std::abs(r.y())});
      ASSERT_NEAR(frame.depth.data[v * 64 + u], expected, 1e-4);
      // Normals face the camera and are unit length.
      const Eigen::Vector3f n(frame.normals.pixel(u, v));
      ASSERT_NEAR(n.norm(), 1.0f, 1e-5f);
      const Eigen::Vector3d dir = cam.R_cam2world * r;
      ASSERT_LT(n.cast<double>().dot(dir), 0.0);
    }
  }
}

TEST(RayCaster, OneThreadRendersWhatSeveralDo) {
  // With OpenMP allowed one thread (generate_pairs' workers), every call runs in the calling
  // thread without a parallel region; the results must be those of several threads.
  const Mesh mesh = insideCube();
  RayCaster caster(mesh);
  std::vector<Camera> cams;
  for (int k = 0; k < 5; ++k) {
    Camera cam = Camera::fromHfov(8 + 12 * k, 8 + 8 * k, 90.0);  // one tile up to several rows
    cam.lookAt({0.1f * k, 0, 0}, {1, 0.3f * k, 0.2f}, {0, 0, 1});
    cams.push_back(cam);
  }
  std::vector<Ray> rays;
  for (int k = 0; k < 37; ++k)
    rays.push_back({{0, 0, 0}, {std::cos(0.3f * k), std::sin(0.3f * k), 0.1f * (k % 5)}, 0, 1e30f});
  const auto everything = [&](int threads) {
    const int before = omp_get_max_threads();
    omp_set_num_threads(threads);
    std::vector<std::vector<float>> out;
    for (const Camera& cam : cams) {
      ImageF depth;
      caster.renderDepth(cam, depth);
      out.push_back(depth.data);
      Frame frame;
      caster.render(cam, RenderOptions{}, frame);
      out.push_back(frame.depth.data);
      out.emplace_back(frame.rgb.data.begin(), frame.rgb.data.end());
    }
    std::vector<ImageF> batch(cams.size());
    caster.renderDepthBatch(cams.data(), batch.data(), cams.size());
    for (const ImageF& d : batch) out.push_back(d.data);
    std::vector<Hit> hits(rays.size());
    caster.intersect(rays.data(), hits.data(), rays.size());
    for (const Hit& h : hits) out.push_back({h.t, static_cast<float>(h.triangle)});
    omp_set_num_threads(before);
    return out;
  };
  EXPECT_EQ(everything(1), everything(2));
  EXPECT_EQ(everything(1), everything(3));
}

TEST(RayCaster, HitsAtLeastAgreesWithTheDepthMap) {
  // A square that fills part of each view: hitsAtLeast(c) must say whether the depth map has c
  // valid pixels or more, for counts around that number, whatever the size (rows of a partial
  // packet included) and wherever the hits lie.
  const Mesh mesh = planeMesh(4.0f, 1.5f);
  RayCaster caster(mesh);
  Rng rng(5);
  int partial = 0;
  for (int k = 0; k < 60; ++k) {
    const int w = 1 + static_cast<int>(rng.below(20)), h = 1 + static_cast<int>(rng.below(12));
    Camera cam = Camera::fromHfov(w, h, 60.0 + 60.0 * rng.uniform());
    const Eigen::Vector3d at(rng.uniform(-3, 3), rng.uniform(-3, 3), 4.0);
    cam.lookAt({0, 0, 0}, at, {0, 1, 0});
    ImageF depth;
    caster.renderDepth(cam, depth);
    long valid = 0;
    for (float d : depth.data) valid += d > 0.0f;
    const long n = static_cast<long>(w) * h;
    partial += valid > 0 && valid < n;
    for (long count : {0L, 1L, valid - 1, valid, valid + 1, n, n + 1})
      EXPECT_EQ(caster.hitsAtLeast(cam, count), valid >= count)
          << w << "x" << h << " valid " << valid << " count " << count;
  }
  EXPECT_GT(partial, 20);  // the cases that can stop early either way
}

TEST(RayCaster, MissesGiveZeroDepthAndNegativeIds) {
  Mesh mesh;
  int mat = mesh.addMaterial(Material{});
  addQuadZ(mesh, 0.0f, 10.0f, -10.0f, 10.0f, 2.0f, mat);  // the right half only: x >= 0
  RayCaster caster(mesh);
  Camera cam = Camera::fromHfov(8, 8, 60.0);
  Frame frame;
  caster.render(cam, RenderOptions{}, frame);
  for (int v = 0; v < 8; ++v) {
    for (int u = 0; u < 8; ++u) {
      const size_t i = v * 8 + u;
      // Pixel centres at u + 0.5: column 4 is the first right of the optical axis.
      if (u >= 4) {
        EXPECT_NEAR(frame.depth.data[i], 2.0f, 1e-5f);
        EXPECT_GE(frame.triangleId.data[i], 0);
        EXPECT_EQ(frame.materialId.data[i], mat);
      } else {
        EXPECT_EQ(frame.depth.data[i], 0.0f);
        EXPECT_EQ(frame.triangleId.data[i], -1);
        EXPECT_EQ(frame.materialId.data[i], -1);
        EXPECT_EQ(frame.normals.data[3 * i], 0.0f);
      }
    }
  }
}

TEST(RayCaster, PixelCentreEdgeIsExact) {
  // A quad edge half a pixel right of the optical axis: the pixel whose centre is at
  // cx + 0.5 sits exactly on it; one a little further in is hit, one a little out is not.
  Camera cam = Camera::fromHfov(16, 16, 60.0);
  const double f = cam.K(0, 0);
  for (double offset : {0.45, 0.55}) {
    Mesh mesh;
    int mat = mesh.addMaterial(Material{});
    const float edge = static_cast<float>(offset / f);  // at depth 1
    addQuadZ(mesh, edge, 10.0f, -10.0f, 10.0f, 1.0f, mat);
    RayCaster caster(mesh);
    ImageF depth;
    caster.renderDepth(cam, depth);
    const bool hit = depth.data[8 * 16 + 8] > 0;  // pixel (8, 8): centre at cx + 0.5
    EXPECT_EQ(hit, offset < 0.5) << offset;
    EXPECT_GT(depth.data[8 * 16 + 9], 0.0f);
    EXPECT_EQ(depth.data[8 * 16 + 7], 0.0f);
  }
}

TEST(RayCaster, TexturedQuadShowsTextureColours) {
  // A 4x4 texture made of 2x2 blocks of four colours fills the view; with ambient light only,
  // each quadrant's centre shows its texel colour exactly (sRGB in, sRGB out).
  Mesh mesh;
  Texture tex;
  tex.width = tex.height = 4;
  tex.channels = 3;
  const uint8_t colours[4][3] = {{200, 30, 40}, {20, 180, 60}, {50, 60, 220}, {240, 230, 10}};
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x)
      for (int c = 0; c < 3; ++c) tex.texels.push_back(colours[(y / 2) * 2 + x / 2][c]);
  mesh.textures.push_back(tex);
  Material mat;
  mat.texture = 0;
  const int m = mesh.addMaterial(mat);
  addQuadZ(mesh, -1, 1, -1, 1, 1.0f, m);  // uv (0,0) at (-1,-1)
  Camera cam = Camera::fromHfov(64, 64, 80.0);
  cam.lookAt({0, 0, -0.1}, {0, 0, 1}, {0, -1, 0});  // image right = +x, image down = +y
  const Frame frame = renderAlbedo(mesh, cam);
  // Project each quadrant's centre and compare.
  const Eigen::Vector3d centres[4] = {
      {-0.5, 0.5, 1}, {0.5, 0.5, 1}, {-0.5, -0.5, 1}, {0.5, -0.5, 1}};
  for (int q = 0; q < 4; ++q) {
    const Eigen::Vector2d px = cam.project(cam.cameraFromWorld() * centres[q]);
    const uint8_t* rgb = frame.rgb.pixel(static_cast<int>(px.x()), static_cast<int>(px.y()));
    // Texture row 0 is v = 1 (top), so quadrant y > 0 shows the first texture rows.
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rgb[c], colours[q][c], 1) << "quadrant " << q;
  }
}

TEST(RayCaster, VertexColoursAreInterpolatedWithAndWithoutTexture) {
  // One triangle at z = 1 with red, green and blue corners, lit by ambient light only: every
  // pixel shows material factor x texture (1x1 white, or none) x the barycentric mix. Three
  // meshes, for the renderer's three ways to store colours: a scan's (no texture anywhere), a
  // textured triangle, and an untextured one in a mesh with a texture elsewhere.
  const Eigen::Vector3f corner[3] = {{0.8f, 0.1f, 0.1f}, {0.1f, 0.7f, 0.1f}, {0.1f, 0.2f, 0.9f}};
  for (const int variant : {0, 1, 2}) {
    const bool textured = variant == 1;
    Mesh mesh;
    Material mat;
    mat.baseColor = {0.5f, 1.0f, 0.9f};
    if (variant > 0) mesh.textures.push_back(Texture{"white", 1, 1, 3, {255, 255, 255}});
    if (textured) mat.texture = 0;
    mesh.addTriangle({-2, -2, 1}, {2, -2, 1}, {-2, 2, 1}, mesh.addMaterial(mat));
    for (int k = 0; k < 3; ++k) mesh.colors[k] = corner[k];
    if (variant == 2) {  // behind the camera
      Material other;
      other.texture = 0;
      mesh.addTriangle({-1, -1, -5}, {1, -1, -5}, {0, 1, -5}, mesh.addMaterial(other));
    }
    Camera cam = Camera::fromHfov(40, 40, 90.0);
    cam.lookAt({0, 0, 0}, {0, 0, 1}, {0, -1, 0});  // image right = +x, image down = +y
    const Frame frame = renderAlbedo(mesh, cam);
    int checked = 0;
    for (int y = 0; y < 40; ++y) {
      for (int x = 0; x < 40; ++x) {
        const float z = frame.depth.data[y * 40 + x];
        if (z <= 0) continue;
        const Eigen::Vector3d p = cam.worldFromCamera() * (z * cam.rayCamera(x + 0.5, y + 0.5));
        const float u = static_cast<float>((p.x() + 2) / 4),
                    v = static_cast<float>((p.y() + 2) / 4);
        const Eigen::Vector3f linear =
            mat.baseColor.cwiseProduct((1 - u - v) * corner[0] + u * corner[1] + v * corner[2]);
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(frame.rgb.pixel(x, y)[c], linearToSrgb8(linear[c]), 1)
              << "variant " << variant << " pixel " << x << "," << y;
        ++checked;
      }
    }
    EXPECT_GT(checked, 700);
  }
}

TEST(RayCaster, SupersamplingKeepsFlatColourAndCentreGeometry) {
  const Mesh mesh = planeMesh(3.0f);
  RayCaster caster(mesh);
  Camera cam = Camera::fromHfov(33, 17, 60.0);
  RenderOptions one, four;
  four.supersample = 2;
  one.shading.headlight = four.shading.headlight = 0.0f;  // flat shading: no view dependence
  one.shading.sun = four.shading.sun = 0.0f;
  Frame a, b;
  caster.render(cam, one, a);
  caster.render(cam, four, b);
  EXPECT_EQ(a.rgb.data, b.rgb.data);
  EXPECT_EQ(a.depth.data, b.depth.data);
}

TEST(RayCaster, BuffersAreReusedAcrossFrames) {
  const Mesh mesh = planeMesh(2.0f);
  RayCaster caster(mesh);
  Frame frame;
  caster.render(Camera::fromHfov(32, 32, 60), RenderOptions{}, frame);
  const float* before = frame.depth.data.data();
  caster.render(Camera::fromHfov(32, 32, 50), RenderOptions{}, frame);
  EXPECT_EQ(before, frame.depth.data.data());
}

TEST(RayCaster, IntersectBatchMatchesAnalyticHits) {
  const Mesh mesh = insideCube();
  RayCaster caster(mesh);
  Rng rng(5);
  std::vector<Ray> rays;
  for (int i = 0; i < 500; ++i) {
    Eigen::Vector3f d(rng.normal(), rng.normal(), rng.normal());
    rays.push_back(Ray{Eigen::Vector3f::Zero(), d.normalized(), 0.0f, 1e30f});
  }
  rays.push_back(Ray{Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(), 0.0f, 0.5f});  // too short
  std::vector<Hit> hits(rays.size());
  caster.intersect(rays.data(), hits.data(), rays.size());
  for (size_t i = 0; i + 1 < rays.size(); ++i) {
    ASSERT_GE(hits[i].triangle, 0);
    EXPECT_NEAR(hits[i].t, 1.0f / rays[i].direction.cwiseAbs().maxCoeff(), 1e-4f);
    EXPECT_NEAR(hits[i].normal.norm(), 1.0f, 1e-5f);
  }
  EXPECT_EQ(hits.back().triangle, -1);
}

}  // namespace
}  // namespace paircast
