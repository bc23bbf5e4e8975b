// Optical flow and relative pose from the renderer's geometry: exact ground truth for a pair.
//
// The flow of a pixel of view `from` into view `to` is where its surface point lands in `to`
// minus where it lies in `from`, in pixels: the centre (u + 0.5, v + 0.5) with depth z is
// lifted to 3D and projected by `to`'s camera. Everything is computed in double.
//   - Occluded and out-of-frame pixels keep their geometric flow, as MPI-Sintel's do (the
//     co-visibility mask says which pixels are seen).
//   - A pixel without depth, or whose point lies at or behind `to`'s image plane, is +inf in
//     both channels: unknown, as stereoflow's readFlowFile treats what is not finite.
#pragma once

#include <Eigen/Geometry>

#include "util/camera.h"
#include "util/image.h"

namespace paircast {

// [H, W, 2] float32 (u, v): the flow of `from`'s pixels into `to`. `depth` is `from`'s z-depth,
// [H, W, 1], matching its camera. Throws paircast::Error when it does not match.
ImageF opticalFlow(const Camera& from, const ImageF& depth, const Camera& to);

// Whether a flow vector is known: both channels finite.
inline bool knownFlow(const float* f) {
  return (f[0] - f[0] == 0.0f) & (f[1] - f[1] == 0.0f);
}

// The pose of camera `b` in camera `a`'s frame: maps points from b's camera coordinates to a's
// (R = R_a^T R_b, t = R_a^T (t_b - t_a) with the cameras' R_cam2world and t_cam2world).
Eigen::Isometry3d relativePose(const Camera& a, const Camera& b);

}  // namespace paircast
