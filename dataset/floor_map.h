// The walkable floor of a scene, found from the mesh alone (no navmesh is given): a grid of
// columns over the scene's horizontal extent, each holding the floor levels where a person
// could stand. A level is an upward-facing, near-horizontal surface hit by a downward ray, with
// enough headroom, clear of walls, inside the scene (under a ceiling when the scene has one),
// and part of a connected region large enough to walk in (so table tops and beds are not).
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "util/random.h"

namespace paircast {

struct FloorOptions {
  double cellSize = 0.1;          // grid spacing, metres
  double maxSlopeDegrees = 20.0;  // steeper surfaces are not floor
  double headroom = 2.0;          // free space above the floor, metres
  double wallClearance = 0.25;    // free radius around the standing point, metres
  double stepHeight = 0.25;       // neighbouring cells connect when their floors differ less
  double minRegionArea = 2.0;     // m^2; smaller walkable islands are dropped
  double minRegionShare = 0.1;    // ... and so are regions smaller than this share of the largest
};

class FloorMap {
 public:
  // Casts the rays and builds the map. Empty when the scene has no walkable floor.
  FloorMap(const Scene& scene, const RayCaster& caster, const FloorOptions& options = {});

  bool empty() const { return points_.empty(); }
  size_t size() const { return points_.size(); }
  double area() const;  // walkable area, m^2
  bool hasCeiling() const { return hasCeiling_; }
  const std::vector<Eigen::Vector3f>& points() const { return points_; }

  // A uniformly drawn walkable point (a cell, jittered within it).
  Eigen::Vector3f sample(Rng& rng) const;
  // The walkable point nearest to `p` within `radius` metres, as habitat's snap_point.
  std::optional<Eigen::Vector3f> snap(const Eigen::Vector3f& p, double radius = 2.0) const;

 private:
  Eigen::Vector3f up_, axisA_, axisB_;
  double cell_ = 0.1;
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();  // (a, b) of cell (0, 0)'s corner
  int nA_ = 0, nB_ = 0;
  bool hasCeiling_ = false;
  std::vector<Eigen::Vector3f> points_;       // walkable points, cell centres on the floor
  std::vector<std::vector<int>> cellPoints_;  // [nA * nB] indices into points_
};

}  // namespace paircast
