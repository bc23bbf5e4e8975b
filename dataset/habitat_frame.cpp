#include "dataset/habitat_frame.h"

#include <cmath>

#include "util/error.h"

namespace paircast {
namespace {

// OpenCV camera axes (x right, y down, z forward) to habitat's (x right, y up, z back).
const Eigen::Matrix3d kHabitatFromOpenCv = Eigen::Vector3d(1, -1, -1).asDiagonal();

}  // namespace

HabitatQuaternion habitatQuaternion(const Eigen::Matrix3d& R_cam2world) {
  const Eigen::Quaterniond q(Eigen::Matrix3d(R_cam2world * kHabitatFromOpenCv));
  return {q.w(), q.x(), q.y(), q.z()};
}

Eigen::Matrix3d cameraRotationFromHabitat(const HabitatQuaternion& q) {
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(n > 1e-12) || !std::isfinite(n))
    throw Error("camera orientation is not a rotation quaternion (norm " + std::to_string(n) + ")");
  const Eigen::Quaterniond quat(q[0] / n, q[1] / n, q[2] / n, q[3] / n);
  return quat.toRotationMatrix() * kHabitatFromOpenCv;
}

Eigen::Matrix3d sceneFromHabitat(UpAxis up) {
  if (up == UpAxis::Y) return Eigen::Matrix3d::Identity();
  Eigen::Matrix3d habitatFromScene;  // (x, y, z) -> (x, z, -y)
  habitatFromScene << 1, 0, 0, 0, 0, 1, 0, -1, 0;
  return habitatFromScene.transpose();
}

}  // namespace paircast
