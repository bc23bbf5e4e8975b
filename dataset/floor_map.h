// The walkable floor of a scene, found from the mesh alone (no navmesh is given): a grid of
// columns over the scene's horizontal extent, each holding the floor levels where a person
// could stand. A level is a surface hit by a downward ray that is flat at the scale of a
// footprint, with enough headroom, clear of walls, inside the scene, and part of a connected
// region large enough to walk in (so table tops and beds are not).
//
// Scans decide the shape of these tests. Their floors are centimetre triangles with millimetres
// of noise, so the normal of one triangle says little (at 1.5 cm and 3 mm, many tilt past
// 20 degrees): flatness is judged from the heights of downward rays over a footprint, fitted
// with a plane. They have holes (a footprint may miss a few rays), clutter and stairs (a
// footprint over an edge is not flat), and often part of a ceiling or none: a point without a
// ceiling above is inside when walls surround it (horizontal rays hit something in most
// directions), so the floor under a gap in the ceiling stays, and a roof or the ground outside a
// building does not.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "util/random.h"

namespace paircast {

struct FloorOptions {
  double cellSize = 0.1;          // grid spacing, metres
  double maxSlopeDegrees = 20.0;  // steeper surfaces are not floor (of the footprint's plane)
  double footprintRadius = 0.2;   // metres; flatness is judged over this disc
  double maxRoughness = 0.03;     // metres; largest height of a footprint ray off its plane
  int minFootprintHits = 6;       // of 8 rays around the footprint (holes lose a few)
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
  std::vector<Eigen::Vector3f> points_;  // walkable points, cell centres on the floor
  // The same points cell by cell: cell c's are byCell_[cellStart_[c], cellStart_[c + 1]). Small
  // and in one place, as snap visits dozens of cells for each step of a walk.
  std::vector<Eigen::Vector3f> byCell_;
  std::vector<uint32_t> cellStart_;  // [nA * nB + 1]
  // [nA * nB] the ring (Chebyshev distance in cells) of the nearest cell with points, at most
  // kMaxRing, so that snap starts its search there
  static constexpr int kMaxRing = 65535;
  std::vector<uint16_t> emptyRings_;
  void indexByCell(const std::vector<size_t>& cellOf, size_t cells);
  void measureEmptyRings();
};

}  // namespace paircast
