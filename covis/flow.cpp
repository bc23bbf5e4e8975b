#include "covis/flow.h"

#include <limits>

#include "covis/unproject.h"

namespace paircast {

ImageF opticalFlow(const Camera& from, const ImageF& depth, const Camera& to) {
  checkDepthMatches(from, depth);
  const Eigen::Isometry3d toFromFrom = to.cameraFromWorld() * from.worldFromCamera();
  // Pixel centre (u + 0.5, v + 0.5, 1) at depth 1 -> `to`'s homogeneous pixel coordinates.
  const Eigen::Matrix3d A = to.K * toFromFrom.linear() * from.K.inverse();
  const Eigen::Vector3d b = to.K * toFromFrom.translation();
  constexpr float kUnknown = std::numeric_limits<float>::infinity();
  ImageF flow(depth.width, depth.height, 2);
  for (int v = 0; v < depth.height; ++v) {
    for (int u = 0; u < depth.width; ++u) {
      float* f = flow.pixel(u, v);
      const float z = depth.data[static_cast<size_t>(v) * depth.width + u];
      const Eigen::Vector2d p(u + 0.5, v + 0.5);
      const Eigen::Vector3d q = z * (A * p.homogeneous()) + b;
      if (!validDepth(z) || !(q.z() > 0.0)) {
        f[0] = f[1] = kUnknown;
        continue;
      }
      f[0] = static_cast<float>(q.x() / q.z() - p.x());
      f[1] = static_cast<float>(q.y() / q.z() - p.y());
    }
  }
  return flow;
}

Eigen::Isometry3d relativePose(const Camera& a, const Camera& b) {
  return a.cameraFromWorld() * b.worldFromCamera();
}

}  // namespace paircast
