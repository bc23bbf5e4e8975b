#include "util/camera.h"

#include <cmath>
#include <nlohmann/json.hpp>

#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {

Camera Camera::fromHfov(int width, int height, double hfovDegrees) {
  if (width <= 0 || height <= 0) throw Error("camera size must be positive");
  if (!(hfovDegrees > 0 && hfovDegrees < 180)) throw Error("hfov must be in (0, 180) degrees");
  Camera c;
  c.width = width;
  c.height = height;
  const double f = 0.5 * width / std::tan(0.5 * hfovDegrees * M_PI / 180.0);
  c.K << f, 0, 0.5 * width, 0, f, 0.5 * height, 0, 0, 1;
  return c;
}

Eigen::Isometry3d Camera::worldFromCamera() const {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R_cam2world;
  T.translation() = t_cam2world;
  return T;
}

Eigen::Isometry3d Camera::cameraFromWorld() const {
  return worldFromCamera().inverse();
}

void Camera::setWorldFromCamera(const Eigen::Isometry3d& T) {
  R_cam2world = T.linear();
  t_cam2world = T.translation();
}

Eigen::Matrix3d lookAtRotation(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                               const Eigen::Vector3d& up) {
  Eigen::Vector3d z = target - eye;
  if (z.norm() < 1e-12) throw Error("lookAt: eye and target coincide");
  z.normalize();
  Eigen::Vector3d x = z.cross(up);  // right = forward x up, in OpenCV axes
  if (x.norm() < 1e-9) throw Error("lookAt: viewing direction is parallel to up");
  x.normalize();
  Eigen::Vector3d y = z.cross(x);  // down
  Eigen::Matrix3d R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = z;
  return R;
}

void Camera::lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                    const Eigen::Vector3d& up) {
  R_cam2world = lookAtRotation(eye, target, up);
  t_cam2world = eye;
}

Eigen::Vector3d Camera::rayCamera(double x, double y) const {
  return Eigen::Vector3d((x - K(0, 2) - K(0, 1) * (y - K(1, 2)) / K(1, 1)) / K(0, 0),
                         (y - K(1, 2)) / K(1, 1), 1.0);
}

Eigen::Vector2d Camera::project(const Eigen::Vector3d& p) const {
  Eigen::Vector3d q = K * p;
  return q.head<2>() / q.z();
}

double Camera::hfovDegrees() const {
  return 2.0 * std::atan(0.5 * width / K(0, 0)) * 180.0 / M_PI;
}

bool Camera::valid() const {
  if (width <= 0 || height <= 0) return false;
  if (!K.allFinite() || !R_cam2world.allFinite() || !t_cam2world.allFinite()) return false;
  if (!(K(0, 0) > 0 && K(1, 1) > 0) || K(2, 0) != 0 || K(2, 1) != 0 || K(2, 2) != 1) return false;
  return (R_cam2world.transpose() * R_cam2world - Eigen::Matrix3d::Identity()).norm() < 1e-4 &&
         R_cam2world.determinant() > 0;
}

namespace {

nlohmann::json matrixJson(const Eigen::Matrix3d& M) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({M(r, 0), M(r, 1), M(r, 2)});
  return rows;
}

Eigen::Matrix3d matrixFrom(const nlohmann::json& j, const char* key, const std::string& source) {
  if (!j.contains(key)) throw Error(source, std::string("missing key '") + key + "'");
  const auto& v = j.at(key);
  if (!v.is_array() || v.size() != 3) throw Error(source, std::string("'") + key + "' is not 3x3");
  Eigen::Matrix3d M;
  for (int r = 0; r < 3; ++r) {
    if (!v[r].is_array() || v[r].size() != 3)
      throw Error(source, std::string("'") + key + "' is not 3x3");
    for (int c = 0; c < 3; ++c) {
      if (!v[r][c].is_number()) throw Error(source, std::string("'") + key + "' has a non-number");
      M(r, c) = v[r][c].get<double>();
    }
  }
  return M;
}

}  // namespace

nlohmann::json cameraToJson(const Camera& c) {
  nlohmann::json j;
  j["camera_intrinsics"] = matrixJson(c.K);
  j["R_cam2world"] = matrixJson(c.R_cam2world);
  j["t_cam2world"] = {c.t_cam2world.x(), c.t_cam2world.y(), c.t_cam2world.z()};
  j["width"] = c.width;
  j["height"] = c.height;
  return j;
}

Camera cameraFromJson(const nlohmann::json& j, const std::string& source) {
  if (!j.is_object()) throw Error(source, "camera JSON is not an object");
  Camera c;
  c.K = matrixFrom(j, "camera_intrinsics", source);
  c.R_cam2world = matrixFrom(j, "R_cam2world", source);
  if (!j.contains("t_cam2world")) throw Error(source, "missing key 't_cam2world'");
  const auto& t = j.at("t_cam2world");
  if (!t.is_array() || t.size() != 3) throw Error(source, "'t_cam2world' is not a 3-vector");
  for (int i = 0; i < 3; ++i) {
    if (!t[i].is_number()) throw Error(source, "'t_cam2world' has a non-number");
    c.t_cam2world[i] = t[i].get<double>();
  }
  // CroCo's own camera_params.json has no size: fall back to the principal point. Sizes are
  // range-checked before they are narrowed to int (1e12 must not wrap to a small size).
  constexpr int kMaxSize = 16384;
  auto dim = [&](const char* key, double fallback) {
    if (!j.contains(key)) {
      if (!(fallback >= 0.5 && fallback < kMaxSize + 0.5))
        throw Error(source, std::string("no '") + key +
                                "' and the principal point implies no size in 1..16384");
      return static_cast<int>(std::lround(fallback));
    }
    const auto& v = j.at(key);
    if (!v.is_number_integer()) throw Error(source, std::string("'") + key + "' is not an integer");
    const bool inRange = v.is_number_unsigned()
                             ? v.get<uint64_t>() <= kMaxSize
                             : v.get<int64_t>() >= 1 && v.get<int64_t>() <= kMaxSize;
    if (!inRange) throw Error(source, "camera size must be in 1..16384");
    return static_cast<int>(v.get<int64_t>());
  };
  c.width = dim("width", 2 * c.K(0, 2));
  c.height = dim("height", 2 * c.K(1, 2));
  if (c.width <= 0 || c.height <= 0) throw Error(source, "camera size must be in 1..16384");
  if (!c.valid())
    throw Error(source,
                "invalid camera (K must be upper-triangular with positive focal lengths, "
                "R_cam2world a rotation, all values finite)");
  return c;
}

Camera readCameraJson(const std::string& path) {
  const std::string text = readFile(path);
  nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded()) throw Error(path, "not valid JSON");
  return cameraFromJson(j, path);
}

void writeCameraJson(const std::string& path, const Camera& camera) {
  writeFileAtomic(path, cameraToJson(camera).dump(2) + "\n");
}

}  // namespace paircast
