// CroCo's own co-visibility, for comparison and ablations (naver/croco
// datasets/habitat_sim/multiview_habitat_sim_generator.py, compute_pointcloud_overlaps_scikit):
// unproject the valid pixels of both views to world points, and count the points of view i
// that have a neighbour in view j's cloud strictly closer than `radius`. CroCo divides by all
// pixels of i (Normalize::All, the default here). It sees no occlusion: a point hidden from j
// still counts when j sees another surface within the radius of it.
//
// Our camera convention unprojects pixel centres (u + 0.5, v + 0.5); CroCo's generator uses
// (u, v) with cx = W/2, half a pixel off. ../shared/tools/ref_covis.py --pixel-offset 0.5 (its
// default) is this function.
#pragma once

#include "covis/covisibility.h"

namespace paircast {

struct PointCloudCovisOptions {
  float radius = 0.05f;  // metres; a neighbour must be strictly closer
  CovisOptions::Normalize normalize = CovisOptions::Normalize::All;
};

// A kd-tree (nanoflann) over each view's world points; allocates, and is far slower than
// computeCovisibility (docs/covis.md has figures). The result's fields mean what they mean there.
CovisResult computePointCloudCovisibility(const Camera& ci, const ImageF& depthI, const Camera& cj,
                                          const ImageF& depthJ,
                                          const PointCloudCovisOptions& options = {});

}  // namespace paircast
