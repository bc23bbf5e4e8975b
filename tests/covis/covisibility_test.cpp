#include "covis/covisibility.h"

#include <gtest/gtest.h>

#include "render/procedural_scene.h"
#include "render/ray_caster.h"
#include "util/random.h"

namespace paircast {
namespace {

ImageF constantDepth(int w, int h, float z) {
  return ImageF(w, h, 1, z);
}

Camera cameraAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int size = 64,
                double hfov = 90.0) {
  Camera c = Camera::fromHfov(size, size, hfov);
  c.lookAt(eye, target, Eigen::Vector3d(0, -1, 0));  // image down = +y
  return c;
}

TEST(Covisibility, IdenticalViewsGiveOne) {
  const Camera c = cameraAt({0, 0, 0}, {0, 0, 1});
  const ImageF d = constantDepth(64, 64, 3.0f);
  const CovisResult r = computeCovisibility(c, d, c, d);
  EXPECT_DOUBLE_EQ(r.v_ij, 1.0);
  EXPECT_DOUBLE_EQ(r.v_ji, 1.0);
  EXPECT_DOUBLE_EQ(r.covis, 1.0);
  EXPECT_DOUBLE_EQ(r.valid_i, 1.0);
}

TEST(Covisibility, DisjointViewsGiveZero) {
  // Back to back: each view's points are behind the other camera.
  const Camera a = cameraAt({0, 0, 0}, {0, 0, 1}), b = cameraAt({0, 0, 0}, {0, 0, -1});
  const ImageF d = constantDepth(64, 64, 3.0f);
  const CovisResult r = computeCovisibility(a, d, b, d);
  EXPECT_EQ(r.v_ij, 0.0);
  EXPECT_EQ(r.v_ji, 0.0);
  EXPECT_EQ(r.covis, 0.0);
}

TEST(Covisibility, TranslatedCameraFacingAPlaneMatchesHandComputation) {
  // hfov 90 on 64 px: f = 32. A plane at depth 2; moving the camera 1 m sideways shifts the
  // image by f * 1 / 2 = 16 px, so 48 of 64 columns stay in view: v = 0.75 both ways.
  const Camera a = cameraAt({0, 0, 0}, {0, 0, 1});
  const Camera b = cameraAt({1, 0, 0}, {1, 0, 1});
  const ImageF d = constantDepth(64, 64, 2.0f);
  const CovisResult r = computeCovisibility(a, d, b, d);
  EXPECT_DOUBLE_EQ(r.v_ij, 0.75);
  EXPECT_DOUBLE_EQ(r.v_ji, 0.75);
  // Half the pixels invalid (sky): the valid-normalised value is unchanged for the valid rows,
  // and the all-pixels variant halves.
  ImageF half = d;
  for (int v = 0; v < 32; ++v)
    for (int u = 0; u < 64; ++u) half.data[v * 64 + u] = 0.0f;
  CovisOptions all;
  all.normalize = CovisOptions::Normalize::All;
  const CovisResult rv = computeCovisibility(a, half, b, half);
  const CovisResult ra = computeCovisibility(a, half, b, half, all);
  EXPECT_DOUBLE_EQ(rv.valid_i, 0.5);
  EXPECT_DOUBLE_EQ(rv.v_ij, 0.75);
  EXPECT_DOUBLE_EQ(ra.v_ij, 0.375);
}

TEST(Covisibility, DepthDisagreementIsOcclusion) {
  const Camera a = cameraAt({0, 0, 0}, {0, 0, 1});
  const ImageF d = constantDepth(64, 64, 4.0f);
  ImageF occluded = d;
  for (int v = 0; v < 64; ++v)
    for (int u = 0; u < 16; ++u) occluded.data[v * 64 + u] = 1.0f;  // a quarter is nearer
  const CovisResult r = computeCovisibility(a, d, a, occluded);
  EXPECT_DOUBLE_EQ(r.v_ij, 0.75);
  // Within the tolerance (3 cm + 3 %) still counts as the same surface.
  ImageF noisy = d;
  for (float& z : noisy.data) z += 0.1f;  // 0.1 < 0.03 + 0.03 * 4.1
  EXPECT_DOUBLE_EQ(computeCovisibility(a, d, a, noisy).v_ij, 1.0);
}

TEST(Covisibility, OccluderBetweenCamerasMatchesExactVisibility) {
  // A wall at z = 4 and a box floating between the cameras. The exact v_ij: the fraction of
  // view i's surface points that view j sees unobstructed and inside its frame, found with
  // shadow rays. Depth reprojection must agree within the edge pixels.
  Mesh m;
  const int mat = m.addMaterial(Material{});
  addBox(m, {-20, -20, 4}, {20, 20, 4.2f}, mat);
  addBox(m, {-0.4f, -0.4f, 1.8f}, {0.3f, 0.4f, 2.2f}, mat);
  RayCaster caster(m);
  const Camera ci = cameraAt({0, 0, 0}, {0, 0, 4}, 96, 70);
  const Camera cj = cameraAt({1.2, 0.1, 0.3}, {0, 0, 4}, 96, 70);
  ImageF di, dj;
  caster.renderDepth(ci, di);
  caster.renderDepth(cj, dj);
  const CovisResult r = computeCovisibility(ci, di, cj, dj);

  size_t valid = 0, visible = 0;
  std::vector<Ray> rays;
  std::vector<Eigen::Vector3d> points;
  for (int v = 0; v < 96; ++v)
    for (int u = 0; u < 96; ++u) {
      const float z = di.data[v * 96 + u];
      if (z <= 0) continue;
      ++valid;
      const Eigen::Vector3d p = ci.worldFromCamera() * (z * ci.rayCamera(u + 0.5, v + 0.5));
      const Eigen::Vector3d q = cj.cameraFromWorld() * p;
      if (q.z() <= 0) continue;
      const Eigen::Vector2d px = cj.project(q);
      if (px.x() < 0 || px.y() < 0 || px.x() >= 96 || px.y() >= 96) continue;
      const Eigen::Vector3d toCam = cj.t_cam2world - p;
      rays.push_back(Ray{p.cast<float>(), toCam.cast<float>(), 1e-4f, 1.0f - 1e-4f});
    }
  std::vector<Hit> hits(rays.size());
  caster.intersect(rays.data(), hits.data(), rays.size());
  for (const Hit& h : hits) visible += h.triangle < 0;
  const double exact = static_cast<double>(visible) / valid;
  EXPECT_LT(exact, 0.95) << "the occluder should hide part of view i";
  EXPECT_NEAR(r.v_ij, exact, 0.02);
}

TEST(Covisibility, SwappingViewsSwapsTheDirections) {
  Mesh m;
  const int mat = m.addMaterial(Material{});
  addBox(m, {-3, -3, -3}, {3, 3, 3}, mat);  // seen from inside
  addBox(m, {-0.5f, -0.5f, -0.5f}, {0.5f, 0.5f, 0.5f}, mat);
  RayCaster caster(m);
  Rng rng(9);
  for (int i = 0; i < 30; ++i) {
    const Eigen::Vector3d e1(rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2));
    const Eigen::Vector3d e2(rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-2, 2));
    if ((e1.cwiseAbs().maxCoeff() < 0.7) || (e2.cwiseAbs().maxCoeff() < 0.7))
      continue;  // inside the box
    const Eigen::Vector3d t(rng.normal(), rng.normal(), rng.normal());
    const Camera a = cameraAt(e1, t, 48, 60), b = cameraAt(e2, t, 48, 60);
    ImageF da, db;
    caster.renderDepth(a, da);
    caster.renderDepth(b, db);
    const CovisResult ab = computeCovisibility(a, da, b, db),
                      ba = computeCovisibility(b, db, a, da);
    EXPECT_DOUBLE_EQ(ab.v_ij, ba.v_ji);
    EXPECT_DOUBLE_EQ(ab.v_ji, ba.v_ij);
    EXPECT_DOUBLE_EQ(ab.covis, ba.covis);
    EXPECT_GE(ab.covis, 0.0);
    EXPECT_LE(ab.covis, 1.0);
    // A view always sees itself entirely.
    EXPECT_DOUBLE_EQ(computeCovisibility(a, da, a, da).covis, 1.0);
  }
}

}  // namespace
}  // namespace paircast
