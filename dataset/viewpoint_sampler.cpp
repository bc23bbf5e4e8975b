#include "dataset/viewpoint_sampler.h"

#include <cmath>

#include "dataset/habitat_frame.h"
#include "util/error.h"

namespace paircast {

Eigen::Matrix3d orientationNoise(double panDeg, double tiltDeg, double rollDeg) {
  constexpr double kDeg = M_PI / 180.0;
  // Habitat's UP, RIGHT and FRONT are -y, +x and +z in OpenCV camera axes.
  return (Eigen::AngleAxisd(panDeg * kDeg, -Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(tiltDeg * kDeg, Eigen::Vector3d::UnitX()) *
          Eigen::AngleAxisd(rollDeg * kDeg, Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

SamplerOptions::Motion parseMotion(const std::string& name) {
  if (name == "walk") return SamplerOptions::Motion::kWalk;
  if (name == "near") return SamplerOptions::Motion::kNear;
  throw OptionError("motion", "the motion is walk or near, not '" + name + "'");
}

nlohmann::json motionJson(const SamplerOptions& o) {
  if (o.motion == SamplerOptions::Motion::kWalk) return {{"kind", "walk"}};
  return {{"kind", "near"}, {"translation", o.nearTranslation}, {"rotation", o.nearRotation}};
}

ViewpointSampler::ViewpointSampler(const Scene& scene, const RayCaster& caster,
                                   const SamplerOptions& options)
    : options_(options),
      up_(scene.upVector().cast<double>()),
      floor_(scene, caster, options.floor) {
  if (!(options.minHeight > 0 && options.maxHeight >= options.minHeight))
    throw Error("camera heights must satisfy 0 < min <= max");
  if (floor_.empty())
    throw Error(scene.path,
                "no walkable floor found (is --up right? the scene needs "
                "horizontal surfaces with " +
                    std::to_string(options.floor.headroom) + " m of headroom)");
}

HabitatQuaternion ViewpointSampler::orient(const Eigen::Vector3d& eye,
                                           const Eigen::Vector3d& target, Rng& rng,
                                           double noiseScale) const {
  Eigen::Vector3d forward = target - eye;
  // Looking straight up or down: fall back to a horizontal direction.
  if ((forward - forward.dot(up_) * up_).norm() < 1e-6) forward = up_.unitOrthogonal();
  const Eigen::Matrix3d R = lookAtRotation(eye, eye + forward, up_);
  const double pan = rng.uniform(-options_.panDegrees, options_.panDegrees);
  const double tilt = rng.uniform(-options_.tiltDegrees, options_.tiltDegrees);
  const double roll = rng.uniform(-options_.rollDegrees, options_.rollDegrees);
  return habitatQuaternion(
      R * orientationNoise(noiseScale * pan, noiseScale * tilt, noiseScale * roll));
}

Viewpoint ViewpointSampler::sampleReference(const Camera& intrinsics, Rng& rng) const {
  Viewpoint v;
  v.floorPoint = floor_.sample(rng);
  const double height = rng.uniform(options_.minHeight, options_.maxHeight);
  const Eigen::Vector3d eye = v.floorPoint.cast<double>() + height * up_;
  const double yaw = rng.uniform(0.0, 2.0 * M_PI);
  const Eigen::Vector3d a = up_.unitOrthogonal(), b = up_.cross(a);
  const Eigen::Vector3d forward = std::cos(yaw) * a + std::sin(yaw) * b;
  v.camera = intrinsics;
  v.orientation = orient(eye, eye + forward, rng);
  v.camera.R_cam2world = cameraRotationFromHabitat(v.orientation);
  v.camera.t_cam2world = eye;
  return v;
}

Viewpoint ViewpointSampler::sampleNear(const Camera& intrinsics, const Viewpoint& from,
                                       Rng& rng) const {
  Eigen::Vector3d d(rng.normal(), rng.normal(), rng.normal());
  d = d.normalized() * options_.nearTranslation * std::cbrt(rng.uniform(0.0, 1.0));
  d -= 0.5 * d.dot(up_) * up_;
  const double a = options_.nearRotation;
  const double pan = rng.uniform(-a, a), tilt = rng.uniform(-a, a);
  const double roll = rng.uniform(-a / 2, a / 2);
  Viewpoint v;
  const Eigen::Vector3d horizontal = d - d.dot(up_) * up_;
  const auto snapped = floor_.snap(from.floorPoint + horizontal.cast<float>());
  v.floorPoint = snapped ? *snapped : from.floorPoint;
  v.camera = intrinsics;
  v.orientation = habitatQuaternion(from.camera.R_cam2world * orientationNoise(pan, tilt, roll));
  v.camera.R_cam2world = cameraRotationFromHabitat(v.orientation);
  v.camera.t_cam2world = from.camera.t_cam2world + d;
  return v;
}

Viewpoint ViewpointSampler::sampleOther(const Camera& intrinsics, const Viewpoint& from,
                                        const Eigen::Vector3d& target, Rng& rng) const {
  if (options_.motion == SamplerOptions::Motion::kNear) return sampleNear(intrinsics, from, rng);
  Viewpoint v;
  v.floorPoint = from.floorPoint;
  const Eigen::Vector3f a = up_.unitOrthogonal().cast<float>();
  const Eigen::Vector3f b = up_.cast<float>().cross(a);
  double scale = options_.walkScale, closeness = 1.0;
  if (options_.minWalkScale > 0 && options_.minWalkScale < scale) {
    scale = std::exp(rng.uniform(std::log(options_.minWalkScale), std::log(scale)));
    closeness = scale / options_.walkScale;
  }
  for (int s = 0; s < options_.walkSteps; ++s) {
    const float da = static_cast<float>(scale * rng.normal());
    const float db = static_cast<float>(scale * rng.normal());
    rng.normal();  // CroCo draws a third (vertical, zero-weighted) component
    if (auto snapped = floor_.snap(v.floorPoint + da * a + db * b)) v.floorPoint = *snapped;
  }
  double height = rng.uniform(options_.minHeight, options_.maxHeight);
  if (closeness < 1.0) {
    const double firstHeight = (from.camera.t_cam2world - from.floorPoint.cast<double>()).dot(up_);
    height = firstHeight + closeness * (height - firstHeight);
  }
  const Eigen::Vector3d eye = v.floorPoint.cast<double>() + height * up_;
  v.camera = intrinsics;
  v.orientation = orient(eye, target, rng, closeness);
  v.camera.R_cam2world = cameraRotationFromHabitat(v.orientation);
  v.camera.t_cam2world = eye;
  return v;
}

}  // namespace paircast
