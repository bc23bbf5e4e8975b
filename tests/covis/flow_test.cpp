#include "covis/flow.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>

#include "test_errors.h"
#include "util/error.h"
#include "util/flo_io.h"
#include "util/random.h"

namespace paircast {
namespace {

// A camera at `eye` with rotation `R` (cam2world), hfov 60 on 64 x 48 pixels.
Camera cameraAt(const Eigen::Vector3d& eye,
                const Eigen::Matrix3d& R = Eigen::Matrix3d::Identity()) {
  Camera c = Camera::fromHfov(64, 48, 60.0);
  c.R_cam2world = R;
  c.t_cam2world = eye;
  return c;
}

ImageF constantDepth(const Camera& c, float z) {
  return ImageF(c.width, c.height, 1, z);
}

TEST(OpticalFlow, SidewaysTranslationInFrontOfAPlaneIsFocalTimesBaselineOverDepth) {
  // Camera 2 moved b to the right (x) of camera 1: a point at depth z moves f b / z pixels left.
  for (const double z : {1.5, 4.0, 17.0}) {
    for (const double b : {0.1, 0.35}) {
      const Camera c1 = cameraAt({0, 0, 0}), c2 = cameraAt({b, 0, 0});
      const ImageF flow = opticalFlow(c1, constantDepth(c1, static_cast<float>(z)), c2);
      ASSERT_EQ(flow.channels, 2);
      const double expected = -c1.K(0, 0) * b / z;
      for (int v = 0; v < flow.height; ++v)
        for (int u = 0; u < flow.width; ++u) {
          EXPECT_NEAR(flow.pixel(u, v)[0], expected, 1e-3) << u << "," << v;
          EXPECT_NEAR(flow.pixel(u, v)[1], 0.0, 1e-3) << u << "," << v;
        }
    }
  }
}

TEST(OpticalFlow, PureRotationIsItsHomographysFlowWhateverTheDepth) {
  Rng rng(5);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(rng.uniform(-0.2, 0.2), Eigen::Vector3d::UnitY()).toRotationMatrix() *
        Eigen::AngleAxisd(rng.uniform(-0.2, 0.2), Eigen::Vector3d::UnitX()).toRotationMatrix();
    const Eigen::Vector3d eye(rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3));
    const Camera c1 = cameraAt(eye), c2 = cameraAt(eye, R);
    ImageF depth(c1.width, c1.height, 1);
    for (float& z : depth.data) z = static_cast<float>(rng.uniform(0.5, 50));
    const ImageF flow = opticalFlow(c1, depth, c2);
    // x2 ~ K R2^T R1 K^-1 x1: the homography of a rotation about the shared centre.
    const Eigen::Matrix3d H = c2.K * R.transpose() * c1.K.inverse();
    for (int v = 0; v < flow.height; ++v)
      for (int u = 0; u < flow.width; ++u) {
        const Eigen::Vector3d q = H * Eigen::Vector3d(u + 0.5, v + 0.5, 1.0);
        EXPECT_NEAR(flow.pixel(u, v)[0], q.x() / q.z() - (u + 0.5), 1e-3);
        EXPECT_NEAR(flow.pixel(u, v)[1], q.y() / q.z() - (v + 0.5), 1e-3);
      }
  }
}

TEST(OpticalFlow, NoDepthOrBehindTheOtherCameraIsInfinity) {
  const Camera c1 = cameraAt({0, 0, 0});
  // Camera 2 stands 5 m ahead looking the same way: points nearer than 5 m are behind it.
  const Camera c2 = cameraAt({0, 0, 5});
  ImageF depth = constantDepth(c1, 8.0f);
  depth.data[3] = 0.0f;                                     // a miss
  depth.data[4] = std::numeric_limits<float>::quiet_NaN();  // not a depth
  depth.data[5] = 2.0f;                                     // behind camera 2
  depth.data[6] = 5.0f;                                     // on its image plane
  const ImageF flow = opticalFlow(c1, depth, c2);
  for (int i : {3, 4, 5, 6}) {
    EXPECT_TRUE(std::isinf(flow.data[2 * i]) && flow.data[2 * i] > 0) << i;
    EXPECT_TRUE(std::isinf(flow.data[2 * i + 1]) && flow.data[2 * i + 1] > 0) << i;
    EXPECT_FALSE(knownFlow(&flow.data[2 * i]));
  }
  EXPECT_TRUE(std::isfinite(flow.data[0]) && knownFlow(&flow.data[0]));
}

TEST(OpticalFlow, DepthOfTheWrongSizeIsRefused) {
  const Camera c = cameraAt({0, 0, 0});
  EXPECT_ERROR_CONTAINS(opticalFlow(c, ImageF(10, 10, 1, 1.0f), c), "does not match");
}

TEST(RelativePose, MapsTheSecondCamerasCoordinatesIntoTheFirsts) {
  Rng rng(9);
  const Eigen::Matrix3d R1 = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
  const Eigen::Matrix3d R2 =
      Eigen::AngleAxisd(-0.4, Eigen::Vector3d(3, 1, 0).normalized()).matrix();
  const Camera a = cameraAt({1, 2, 3}, R1), b = cameraAt({-2, 0.5, 4}, R2);
  const Eigen::Isometry3d T = relativePose(a, b);
  for (int i = 0; i < 5; ++i) {
    const Eigen::Vector3d pb(rng.normal(), rng.normal(), rng.normal());
    const Eigen::Vector3d world = R2 * pb + b.t_cam2world;
    EXPECT_LT((T * pb - R1.transpose() * (world - a.t_cam2world)).norm(), 1e-12);
  }
}

// An independent .flo reader: the header as the format defines it, then (u, v) float32 pairs.
ImageF readFloByHand(const std::vector<char>& bytes) {
  float magic;
  int32_t w, h;
  std::memcpy(&magic, bytes.data(), 4);
  std::memcpy(&w, bytes.data() + 4, 4);
  std::memcpy(&h, bytes.data() + 8, 4);
  EXPECT_EQ(magic, 202021.25f);
  EXPECT_EQ(bytes.size(), 12u + 8u * w * h);
  ImageF f(w, h, 2);
  std::memcpy(f.data.data(), bytes.data() + 12, 8u * w * h);
  return f;
}

TEST(FloFile, WritesWhatAHandReaderReadsAndReadsItBack) {
  ImageF flow(5, 3, 2);
  for (size_t i = 0; i < flow.size(); ++i) flow.data[i] = 0.25f * static_cast<float>(i) - 1.0f;
  flow.data[7] = std::numeric_limits<float>::infinity();
  const std::vector<unsigned char> bytes = encodeFlo(flow);
  const ImageF byHand = readFloByHand(std::vector<char>(bytes.begin(), bytes.end()));
  EXPECT_EQ(byHand.width, 5);
  EXPECT_EQ(byHand.height, 3);
  EXPECT_EQ(byHand.data, flow.data);
  const ImageF back = decodeFlo(bytes.data(), bytes.size(), "x.flo");
  EXPECT_EQ(back.data, flow.data);
}

TEST(FloFile, BadFilesAreRefusedNamingThem) {
  ImageF flow(4, 4, 2, 1.0f);
  std::vector<unsigned char> bytes = encodeFlo(flow);
  EXPECT_ERROR_CONTAINS(decodeFlo(bytes.data(), bytes.size() - 1, "cut.flo"), "cut.flo");
  EXPECT_ERROR_CONTAINS(decodeFlo(bytes.data(), 5, "short.flo"), "short.flo");
  bytes[0] ^= 1;
  EXPECT_ERROR_CONTAINS(decodeFlo(bytes.data(), bytes.size(), "magic.flo"), "wrong magic");
  bytes[0] ^= 1;
  const int32_t huge = 1 << 30;
  std::memcpy(bytes.data() + 4, &huge, 4);
  EXPECT_ERROR_CONTAINS(decodeFlo(bytes.data(), bytes.size(), "size.flo"), "bad .flo size");
  EXPECT_ERROR_CONTAINS(readFlo("/nonexistent/x.flo"), "/nonexistent/x.flo");
}

// A 12-byte file that claims the largest sides the format allows: 65,536 x 65,536 x 2 floats is
// 32 GiB. It is refused from its byte count, before anything is allocated (a vector of that size
// would throw std::bad_alloc, or be zeroed into the OOM killer on a 24 GiB machine).
TEST(FloFile, AHeaderThatLiesAboutItsSizeIsRefusedBeforeAllocating) {
  std::vector<unsigned char> bytes = encodeFlo(ImageF(1, 1, 2, 0.0f));
  bytes.resize(12);
  const int32_t side = 1 << 16;
  std::memcpy(bytes.data() + 4, &side, 4);
  std::memcpy(bytes.data() + 8, &side, 4);
  EXPECT_ERROR_CONTAINS(decodeFlo(bytes.data(), bytes.size(), "shard.tar: 000001.flow1.flo"),
                        "shard.tar: 000001.flow1.flo: truncated or padded .flo: 12 bytes, "
                        "expected 34359738380 for 65536x65536");
}

}  // namespace
}  // namespace paircast
