// Co-visibility of two views from their depth maps, by reprojection. For each valid pixel of
// view i (depth > 0), its 3D point is projected into view j; it is visible there when it lands
// inside the frame, in front of the camera, and agrees with view j's depth at that pixel within
// absTol + relTol * depth_j (otherwise something else occludes it, or it is occluding).
//   v_ij = visible pixels of i / valid pixels of i      (Normalize::Valid, the paper)
//   v_ij = visible pixels of i / all pixels of i        (Normalize::All, CroCo's generator)
//   covis = min(v_ij, v_ji)
#pragma once

#include "render/camera.h"
#include "util/image.h"

namespace paircast {

struct CovisOptions {
  enum class Normalize { Valid, All };
  float absTol = 0.03f;  // metres
  float relTol = 0.03f;  // fraction of view j's depth
  Normalize normalize = Normalize::Valid;
};

struct CovisResult {
  double v_ij = 0;     // share of view i seen by view j
  double v_ji = 0;     // share of view j seen by view i
  double covis = 0;    // min(v_ij, v_ji)
  double valid_i = 0;  // fraction of view i's pixels with depth > 0
  double valid_j = 0;
};

// One direction: the count of valid pixels of i visible in j, and of valid pixels of i.
struct VisibleCount {
  size_t visible = 0;
  size_t valid = 0;
};
VisibleCount countVisible(const Camera& ci, const ImageF& depthI, const Camera& cj,
                          const ImageF& depthJ, const CovisOptions& options);

// Both directions. Depth maps are [H, W, 1] z-depth matching their camera's size.
CovisResult computeCovisibility(const Camera& ci, const ImageF& depthI, const Camera& cj,
                                const ImageF& depthJ, const CovisOptions& options = {});

}  // namespace paircast
