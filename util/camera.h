// A pinhole camera in the OpenCV convention: x right, y down, z forward. Pixel (u, v) covers
// [u, u+1) x [v, v+1), so its centre is at (u + 0.5, v + 0.5) in the coordinates K maps to.
// The pose is worldFromCamera (CroCo's R_cam2world, t_cam2world): p_world = R p_cam + t.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json_fwd.hpp>
#include <string>

namespace paircast {

struct Camera {
  int width = 0;
  int height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  // intrinsics, pixels
  Eigen::Matrix3d R_cam2world = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_cam2world = Eigen::Vector3d::Zero();

  // K from a horizontal field of view: fx = fy = (W/2) / tan(hfov/2), principal point at the
  // image centre (W/2, H/2), as habitat-sim and CroCo's generator compute it.
  static Camera fromHfov(int width, int height, double hfovDegrees);

  Eigen::Isometry3d worldFromCamera() const;
  Eigen::Isometry3d cameraFromWorld() const;
  void setWorldFromCamera(const Eigen::Isometry3d& worldFromCamera);

  // Places the camera at `eye` looking at `target`, with the image's up along `up`
  // (world). Throws paircast::Error when eye == target or the view is along `up`.
  void lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up);

  // Camera-frame direction through pixel coordinates (x, y), with z = 1, so that a hit at ray
  // parameter t has z-depth t.
  Eigen::Vector3d rayCamera(double x, double y) const;
  // Pixel coordinates of a camera-frame point (z must be > 0).
  Eigen::Vector2d project(const Eigen::Vector3d& pCamera) const;

  double hfovDegrees() const;
  bool valid() const;  // positive size, finite, invertible K, orthonormal R
};

// The rotation worldFromCamera of a camera at `eye` looking at `target` (OpenCV axes).
Eigen::Matrix3d lookAtRotation(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                               const Eigen::Vector3d& up);

// CroCo's camera_params.json keys: camera_intrinsics (3x3), R_cam2world (3x3), t_cam2world
// (3), plus width and height.
nlohmann::json cameraToJson(const Camera& camera);
// `source` names the file in error messages.
Camera cameraFromJson(const nlohmann::json& j, const std::string& source);
Camera readCameraJson(const std::string& path);
void writeCameraJson(const std::string& path, const Camera& camera);

}  // namespace paircast
