#include "covis/unproject.h"

#include <string>

#include "util/error.h"

namespace paircast {
namespace {

// (u, v, 1) of a pixel index -> camera-frame point at z-depth 1: K^-1 moved by the half pixel.
Eigen::Matrix3d cameraFromPixel(const Camera& c) {
  Eigen::Matrix3d centre = Eigen::Matrix3d::Identity();
  centre(0, 2) = 0.5;
  centre(1, 2) = 0.5;
  return c.K.inverse() * centre;
}

}  // namespace

void checkDepthMatches(const Camera& camera, const ImageF& depth) {
  if (depth.width == camera.width && depth.height == camera.height && depth.channels == 1 &&
      depth.data.size() == static_cast<size_t>(depth.width) * depth.height)
    return;
  throw Error("a depth map of " + std::to_string(depth.width) + "x" + std::to_string(depth.height) +
              "x" + std::to_string(depth.channels) + " does not match its camera of " +
              std::to_string(camera.width) + "x" + std::to_string(camera.height) +
              " (expected [H, W, 1])");
}

PixelDepthMap worldFromPixelDepth(const Camera& camera) {
  PixelDepthMap m;
  m.A = (camera.R_cam2world * cameraFromPixel(camera)).cast<float>();
  m.b = camera.t_cam2world.cast<float>();
  return m;
}

PixelDepthMap pixelFromPixelDepth(const Camera& from, const Camera& to) {
  const Eigen::Isometry3d toFromFrom = to.cameraFromWorld() * from.worldFromCamera();
  PixelDepthMap m;
  m.A = (to.K * toFromFrom.linear() * cameraFromPixel(from)).cast<float>();
  m.b = (to.K * toFromFrom.translation()).cast<float>();
  return m;
}

void unprojectDepth(const Camera& camera, const ImageF& depth, std::vector<Eigen::Vector3f>& points,
                    int stride) {
  checkDepthMatches(camera, depth);
  PAIRCAST_CHECK(stride >= 1);
  const PixelDepthMap m = worldFromPixelDepth(camera);
  points.clear();
  for (int v = 0; v < depth.height; v += stride) {
    const float* row = depth.data.data() + static_cast<size_t>(v) * depth.width;
    for (int u = 0; u < depth.width; u += stride)
      if (validDepth(row[u])) points.push_back(m.apply(u, v, row[u]));
  }
}

std::vector<Eigen::Vector3f> unprojectDepth(const Camera& camera, const ImageF& depth) {
  std::vector<Eigen::Vector3f> points;
  unprojectDepth(camera, depth, points);
  return points;
}

std::optional<Eigen::Vector3d> meanValidPoint(const Camera& camera, const ImageF& depth) {
  checkDepthMatches(camera, depth);
  // The point is affine in z (u, v, 1), so the mean point is the map of the mean of z (u, v, 1).
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  size_t n = 0;
  for (int v = 0; v < depth.height; ++v) {
    const float* row = depth.data.data() + static_cast<size_t>(v) * depth.width;
    for (int u = 0; u < depth.width; ++u) {
      const float z = row[u];
      if (!validDepth(z)) continue;
      sum += static_cast<double>(z) * Eigen::Vector3d(u, v, 1.0);
      ++n;
    }
  }
  if (n == 0) return std::nullopt;
  return camera.R_cam2world * (cameraFromPixel(camera) * (sum / static_cast<double>(n))) +
         camera.t_cam2world;
}

size_t countValidDepth(const ImageF& depth) {
  size_t n = 0;
  for (float z : depth.data) n += validDepth(z);
  return n;
}

}  // namespace paircast
