#include "covis/pointcloud_covis.h"

#include <gtest/gtest.h>

#include <vector>

#include "covis/covisibility.h"
#include "test_errors.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace {

Camera randomCamera(Rng& rng, int w, int h, const Eigen::Vector3d& target) {
  Camera c = Camera::fromHfov(w, h, rng.uniform(40, 90));
  const Eigen::Vector3d eye(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3));
  c.lookAt(eye, target, {0, -1, 0});
  return c;
}

// A noisy plane through `target` facing the origin, with holes: both views see parts of the
// same surface, and the noise (3 cm) puts some points beyond the radius of any other.
struct NoisyPlane {
  Eigen::Vector3d normal;
  double offset;  // points X with normal . X = offset
};

NoisyPlane randomPlane(Rng& rng, const Eigen::Vector3d& target) {
  const Eigen::Vector3d n =
      (-target.normalized() + 0.4 * Eigen::Vector3d(rng.normal(), rng.normal(), rng.normal()))
          .normalized();
  return {n, n.dot(target)};
}

ImageF noisyDepth(Rng& rng, const Camera& c, const NoisyPlane& plane) {
  ImageF d(c.width, c.height, 1, 0.0f);
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      // z = 1 in the camera, so the ray parameter is the z-depth.
      const Eigen::Vector3d ray = c.R_cam2world * c.rayCamera(u + 0.5, v + 0.5);
      const double t = (plane.offset - plane.normal.dot(c.t_cam2world)) / plane.normal.dot(ray);
      if (t > 0 && rng.uniform() > 0.1)
        d.data[static_cast<size_t>(v) * c.width + u] = static_cast<float>(t + 0.03 * rng.normal());
    }
  return d;
}

// World points of the valid pixels, in double, from the camera's own ray formula.
std::vector<Eigen::Vector3d> worldPoints(const Camera& c, const ImageF& d) {
  std::vector<Eigen::Vector3d> out;
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      const double z = d.data[static_cast<size_t>(v) * c.width + u];
      if (z > 0) out.push_back(c.worldFromCamera() * (z * c.rayCamera(u + 0.5, v + 0.5)));
    }
  return out;
}

size_t bruteForceWithin(const std::vector<Eigen::Vector3d>& a,
                        const std::vector<Eigen::Vector3d>& b, double radius) {
  size_t n = 0;
  for (const auto& p : a) {
    bool found = false;
    for (const auto& q : b) found = found || (p - q).squaredNorm() < radius * radius;
    n += found;
  }
  return n;
}

TEST(PointCloudCovis, MatchesBruteForce) {
  // CroCo's definition over all pairs of points, in double. Float rounding may move a point
  // across the 5 cm sphere only when it lies within ~1e-6 m of it, so the kd-tree count must
  // lie between the brute-force counts for slightly smaller and larger radii.
  Rng rng(3);
  int partial = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const Eigen::Vector3d target(rng.normal(), rng.normal(), 4 + rng.normal());
    const Camera ci = randomCamera(rng, 24, 20, target), cj = randomCamera(rng, 28, 18, target);
    const NoisyPlane plane = randomPlane(rng, target);
    const ImageF di = noisyDepth(rng, ci, plane), dj = noisyDepth(rng, cj, plane);
    const auto pi = worldPoints(ci, di), pj = worldPoints(cj, dj);
    const CovisResult r = computePointCloudCovisibility(ci, di, cj, dj);
    const double all = 24 * 20;
    EXPECT_DOUBLE_EQ(r.valid_i, pi.size() / all);
    EXPECT_GE(r.v_ij * all, bruteForceWithin(pi, pj, 0.05 * (1 - 1e-4)) - 1e-9);
    EXPECT_LE(r.v_ij * all, bruteForceWithin(pi, pj, 0.05 * (1 + 1e-4)) + 1e-9);
    const double allJ = 28 * 18;
    EXPECT_GE(r.v_ji * allJ, bruteForceWithin(pj, pi, 0.05 * (1 - 1e-4)) - 1e-9);
    EXPECT_LE(r.v_ji * allJ, bruteForceWithin(pj, pi, 0.05 * (1 + 1e-4)) + 1e-9);
    EXPECT_EQ(r.covis, std::min(r.v_ij, r.v_ji));
    partial += r.covis > 0.05 && r.covis < 0.8;
  }
  EXPECT_GT(partial, 5);  // the cases are not all trivial
}

TEST(PointCloudCovis, IdenticalViewsGiveTheValidFraction) {
  // Every point is its own neighbour at distance 0: CroCo's value is the valid fraction.
  Rng rng(4);
  const Camera c = randomCamera(rng, 32, 32, {0, 0, 3});
  const ImageF d = noisyDepth(rng, c, randomPlane(rng, {0, 0, 3}));
  const CovisResult all = computePointCloudCovisibility(c, d, c, d);
  EXPECT_DOUBLE_EQ(all.covis, all.valid_i);
  EXPECT_LT(all.valid_i, 1.0);
  PointCloudCovisOptions o;
  o.normalize = CovisOptions::Normalize::Valid;
  EXPECT_DOUBLE_EQ(computePointCloudCovisibility(c, d, c, d, o).covis, 1.0);
}

TEST(PointCloudCovis, AgreesWithReprojectionWithoutOcclusion) {
  // A fronto-parallel plane, a camera moved sideways by 1 m: 0.75 of each view by reprojection
  // (covisibility_test has the hand computation). Points within 5 cm of the other view's
  // border also find a neighbour, at 2 m depth and f = 32 px less than a column's worth.
  Camera a = Camera::fromHfov(64, 64, 90), b = a;
  a.lookAt({0, 0, 0}, {0, 0, 1}, {0, -1, 0});
  b.lookAt({1, 0, 0}, {1, 0, 1}, {0, -1, 0});
  const ImageF d(64, 64, 1, 2.0f);
  PointCloudCovisOptions o;
  o.normalize = CovisOptions::Normalize::Valid;
  const CovisResult kd = computePointCloudCovisibility(a, d, b, d, o);
  EXPECT_NEAR(kd.v_ij, 0.75, 1.0 / 64);
  EXPECT_NEAR(kd.v_ji, 0.75, 1.0 / 64);
  EXPECT_NEAR(kd.covis, computeCovisibility(a, d, b, d).covis, 1.0 / 64);
}

TEST(PointCloudCovis, EmptyViewsGiveZero) {
  Camera c = Camera::fromHfov(8, 8, 60);
  const ImageF empty(8, 8, 1, 0.0f), full(8, 8, 1, 1.0f);
  const CovisResult r = computePointCloudCovisibility(c, empty, c, full);
  EXPECT_EQ(r.v_ij, 0.0);
  EXPECT_EQ(r.v_ji, 0.0);
  EXPECT_EQ(r.valid_i, 0.0);
  PointCloudCovisOptions bad;
  bad.radius = 0;
  EXPECT_ERROR_CONTAINS(computePointCloudCovisibility(c, full, c, full, bad),
                        "point-cloud covis radius must be > 0");
}

}  // namespace
}  // namespace paircast
