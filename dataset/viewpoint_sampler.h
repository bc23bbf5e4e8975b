// Camera poses inside a scene, following CroCo's habitat generator: a camera 1.2 to 1.8 m above
// a walkable point, with a random yaw and pan/tilt/roll noise; the second view of a pair comes
// from a short random walk on the floor and looks at the mean 3D point seen by the first.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "dataset/floor_map.h"
#include "dataset/habitat_frame.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "util/camera.h"
#include "util/random.h"

namespace paircast {

struct SamplerOptions {
  double minHeight = 1.2;  // camera height above the floor, metres
  double maxHeight = 1.8;
  double panDegrees = 3.0;  // orientation noise, uniform in [-x, x]
  double tiltDegrees = 10.0;
  double rollDegrees = 5.0;
  int walkSteps = 5;       // random walk of the second view
  double walkScale = 2.0;  // each step: walkScale * N(0, 1) along both floor axes (CroCo's
                           // random_step_variance)
  // > 0: each second view draws its walk scale s log-uniformly in [minWalkScale, walkScale],
  // and moves its height and orientation noise towards the first view's by s / walkScale, so
  // near-identical views (covis up to 1) are proposed too (covis_sweep's pool).
  double minWalkScale = 0;
  // How the second view moves from the first. kWalk: CroCo's random walk on the floor, looking
  // at the first view's mean point (wide pairs, for pre-training). kNear: a bounded motion around
  // the first camera, as consecutive video frames move (flow-style pairs: small, dense motions):
  // a translation uniform in the ball of radius nearTranslation (its vertical part halved) and a
  // turn of the first camera by pan and tilt uniform in [-nearRotation, nearRotation] degrees
  // and roll in half that.
  enum class Motion { kWalk, kNear };
  Motion motion = Motion::kWalk;
  double nearTranslation = 0.25;  // metres
  double nearRotation = 4.0;      // degrees
  FloorOptions floor;
};

// "walk" or "near" (generate_pairs --motion); throws OptionError for anything else.
SamplerOptions::Motion parseMotion(const std::string& name);
// {"kind": "walk"}, or {"kind": "near", "translation": m, "rotation": degrees}: index.json's and
// metadata.json's "motion".
nlohmann::json motionJson(const SamplerOptions& options);

// A sampled camera with the floor point under it.
struct Viewpoint {
  Camera camera;
  Eigen::Vector3f floorPoint;
  // camera.R_cam2world is made from this (cameraRotationFromHabitat), so that metadata.json,
  // which stores it, replays the pose bit for bit.
  HabitatQuaternion orientation{1, 0, 0, 0};
};

class ViewpointSampler {
 public:
  // Builds the floor map. Throws paircast::Error naming the scene when it has no walkable floor.
  ViewpointSampler(const Scene& scene, const RayCaster& caster, const SamplerOptions& options);

  // A reference view: random floor point, height and yaw, plus orientation noise.
  // `intrinsics` gives the size and K; its pose is ignored.
  Viewpoint sampleReference(const Camera& intrinsics, Rng& rng) const;
  // The second view: a random walk from `from.floorPoint`, looking at `target`, plus noise; with
  // Motion::kNear, a bounded motion of `from` instead (target unused).
  Viewpoint sampleOther(const Camera& intrinsics, const Viewpoint& from,
                        const Eigen::Vector3d& target, Rng& rng) const;
  Camera sampleView(const Camera& intrinsics, Rng& rng) const {
    return sampleReference(intrinsics, rng).camera;
  }

  const FloorMap& floor() const { return floor_; }
  const SamplerOptions& options() const { return options_; }
  Eigen::Vector3d up() const { return up_; }

 private:
  // worldFromCamera rotation looking along `forward` (levelled on up), then the noise.
  HabitatQuaternion orient(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, Rng& rng,
                           double noiseScale = 1.0) const;
  Viewpoint sampleNear(const Camera& intrinsics, const Viewpoint& from, Rng& rng) const;
  SamplerOptions options_;
  Eigen::Vector3d up_;
  FloorMap floor_;
};

// worldFromCamera rotation of CroCo's orientation noise (pan about the camera's up, tilt about
// its right, roll about its forward axis, in that order), in OpenCV camera axes.
Eigen::Matrix3d orientationNoise(double panDeg, double tiltDeg, double rollDeg);

}  // namespace paircast
