#include "covis/unproject.h"

#include <gtest/gtest.h>

#include <limits>

#include "test_errors.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace {

Camera randomCamera(Rng& rng, int w, int h) {
  Camera c = Camera::fromHfov(w, h, rng.uniform(30, 120));
  c.K(0, 2) += rng.uniform(-3, 3);  // off-centre principal point, non-square pixels
  c.K(1, 1) *= rng.uniform(0.9, 1.1);
  const Eigen::Vector3d eye(rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-50, 50));
  c.lookAt(eye, eye + Eigen::Vector3d(rng.normal(), rng.normal(), rng.normal()), {0, 1, 0});
  return c;
}

TEST(Unproject, RoundTripThroughTheCamera) {
  // Unprojecting a pixel and projecting the point back lands on that pixel's centre, at the
  // stored depth, for random cameras and depths.
  Rng rng(2);
  for (int trial = 0; trial < 40; ++trial) {
    const int w = 8 + static_cast<int>(rng.below(40)), h = 8 + static_cast<int>(rng.below(40));
    const Camera c = randomCamera(rng, w, h);
    ImageF d(w, h, 1);
    for (float& z : d.data)
      z = rng.uniform() < 0.3 ? 0.0f : static_cast<float>(rng.uniform(0.5, 30));
    const std::vector<Eigen::Vector3f> points = unprojectDepth(c, d);
    ASSERT_EQ(points.size(), countValidDepth(d));
    size_t k = 0;
    for (int v = 0; v < h; ++v)
      for (int u = 0; u < w; ++u) {
        const float z = d.data[static_cast<size_t>(v) * w + u];
        if (!validDepth(z)) continue;
        const Eigen::Vector3d q = c.cameraFromWorld() * points[k++].cast<double>();
        // World coordinates up to ~80 m in float: ~1e-5 m of rounding.
        EXPECT_NEAR(q.z(), z, 1e-4 + 1e-5 * z);
        const Eigen::Vector2d p = c.project(q);
        EXPECT_NEAR(p.x(), u + 0.5, 1e-2);
        EXPECT_NEAR(p.y(), v + 0.5, 1e-2);
      }
  }
}

TEST(Unproject, PixelToPixelMapAgreesWithTheCameras) {
  Rng rng(8);
  for (int trial = 0; trial < 100; ++trial) {
    const Camera a = randomCamera(rng, 40, 30), b = randomCamera(rng, 50, 20);
    const PixelDepthMap m = pixelFromPixelDepth(a, b);
    const int u = static_cast<int>(rng.below(40)), v = static_cast<int>(rng.below(30));
    const double z = rng.uniform(0.5, 20);
    const Eigen::Vector3d world = a.worldFromCamera() * (z * a.rayCamera(u + 0.5, v + 0.5));
    const Eigen::Vector3d inB = b.cameraFromWorld() * world;
    const Eigen::Vector3f q = m.apply(u, v, static_cast<float>(z));
    EXPECT_NEAR(q.z(), inB.z(), 1e-3 * (1 + std::abs(inB.z())));
    if (inB.z() > 0.1) {
      const Eigen::Vector2d p = b.project(inB);
      EXPECT_NEAR(q.x() / q.z(), p.x(), 1e-3 * (1 + p.norm()));
      EXPECT_NEAR(q.y() / q.z(), p.y(), 1e-3 * (1 + p.norm()));
    }
    // A camera to itself: pixel centres, at the same depth.
    const Eigen::Vector3f self = pixelFromPixelDepth(a, a).apply(u, v, static_cast<float>(z));
    EXPECT_NEAR(self.x() / self.z(), u + 0.5, 1e-4);
    EXPECT_NEAR(self.y() / self.z(), v + 0.5, 1e-4);
    EXPECT_NEAR(self.z(), z, 1e-5 * z);
  }
}

TEST(Unproject, StrideVisitsEveryStrideThPixel) {
  Camera c = Camera::fromHfov(10, 7, 60);
  ImageF d(10, 7, 1, 2.0f);
  d.data[0] = 0;  // (0, 0) is sampled by every stride and is a miss
  std::vector<Eigen::Vector3f> points;
  for (const int s : {1, 2, 3, 4}) {
    unprojectDepth(c, d, points, s);
    EXPECT_EQ(points.size(), static_cast<size_t>(((10 + s - 1) / s) * ((7 + s - 1) / s) - 1));
  }
}

TEST(Unproject, MeanValidPoint) {
  // A fronto-parallel plane at depth 3 with the principal point at the image centre: the
  // pixel rays are symmetric about the optical axis, so the mean point is 3 m along it.
  Camera c = Camera::fromHfov(32, 24, 70);
  c.lookAt({1, 2, 3}, {1, 2, 10}, {0, -1, 0});
  ImageF d(32, 24, 1, 3.0f);
  const auto mean = meanValidPoint(c, d);
  ASSERT_TRUE(mean.has_value());
  EXPECT_LT((*mean - Eigen::Vector3d(1, 2, 6)).norm(), 1e-9);
  // Random depths: the mean of the unprojected points.
  Rng rng(6);
  for (int trial = 0; trial < 20; ++trial) {
    const Camera r = randomCamera(rng, 20, 16);
    ImageF e(20, 16, 1);
    for (float& z : e.data) z = rng.uniform() < 0.5 ? 0.0f : static_cast<float>(rng.uniform(1, 9));
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    const auto points = unprojectDepth(r, e);
    for (const auto& p : points) sum += p.cast<double>();
    const auto m = meanValidPoint(r, e);
    ASSERT_TRUE(m.has_value());
    EXPECT_LT((*m - sum / points.size()).norm(), 1e-4);
  }
  EXPECT_FALSE(meanValidPoint(c, ImageF(32, 24, 1, 0.0f)).has_value());
}

TEST(Unproject, ValidDepthAndChecks) {
  EXPECT_TRUE(validDepth(1e-6f));
  EXPECT_TRUE(validDepth(1e30f));
  EXPECT_FALSE(validDepth(0.0f));
  EXPECT_FALSE(validDepth(-1.0f));
  EXPECT_FALSE(validDepth(std::numeric_limits<float>::infinity()));
  EXPECT_FALSE(validDepth(std::numeric_limits<float>::quiet_NaN()));
  const Camera c = Camera::fromHfov(8, 6, 60);
  EXPECT_NO_THROW(checkDepthMatches(c, ImageF(8, 6, 1)));
  EXPECT_ERROR_CONTAINS(checkDepthMatches(c, ImageF(6, 8, 1)),
                        "a depth map of 6x8x1 does not match its camera of 8x6");
  EXPECT_ERROR_CONTAINS(checkDepthMatches(c, ImageF(8, 6, 2)),
                        "a depth map of 8x6x2 does not match its camera of 8x6");
  EXPECT_ERROR_CONTAINS(unprojectDepth(c, ImageF(8, 5, 1)),
                        "a depth map of 8x5x1 does not match its camera of 8x6");
}

}  // namespace
}  // namespace paircast
