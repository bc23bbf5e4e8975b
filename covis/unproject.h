// From depth maps back to 3D. A pixel is named by its integer index (u, v); its centre lies at
// (u + 0.5, v + 0.5) in the coordinates K maps to (render/camera.h). A depth map is z-depth in
// metres, [H, W, 1], with 0 (or anything not finite and positive) where nothing was hit.
//
// Everything here is one affine map of (u, v, z): the point of pixel (u, v) at z-depth z is
// z * A (u, v, 1)^T + b, in whatever frame A and b are built for. The +0.5 offset and K^-1 are
// folded into A, so a loop along a row costs one multiply-add per coordinate.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <vector>

#include "util/camera.h"
#include "util/image.h"

namespace paircast {

// A depth value that names a surface point: finite and > 0.
inline bool validDepth(float z) {
  return (z > 0.0f) & (z <= 3.4e38f);  // rejects 0, negatives, NaN and +inf; branch-free
}

// The 3x4 map [A | b] from (u, v, z) to z * A (u, v, 1)^T + b. Built in double, applied in float.
struct PixelDepthMap {
  Eigen::Matrix3f A = Eigen::Matrix3f::Identity();
  Eigen::Vector3f b = Eigen::Vector3f::Zero();

  Eigen::Vector3f apply(float u, float v, float z) const {
    return z * (A * Eigen::Vector3f(u, v, 1.0f)) + b;
  }
};

// Pixel (u, v) at z-depth z of `camera` -> world point.
PixelDepthMap worldFromPixelDepth(const Camera& camera);
// Pixel (u, v) at z-depth z of `from` -> homogeneous pixel coordinates (x z', y z', z') of `to`,
// where z' is the point's z-depth in `to` and (x, y) its continuous pixel coordinates there
// (pixel centres at +0.5, so the pixel containing it is (floor(x), floor(y))).
PixelDepthMap pixelFromPixelDepth(const Camera& from, const Camera& to);

// World points of the valid pixels of `depth` ([H, W, 1], matching `camera`), row-major order,
// visiting every `stride`-th pixel of every `stride`-th row. `points` is cleared and reused.
void unprojectDepth(const Camera& camera, const ImageF& depth, std::vector<Eigen::Vector3f>& points,
                    int stride = 1);
std::vector<Eigen::Vector3f> unprojectDepth(const Camera& camera, const ImageF& depth);

// Mean world point of the valid pixels (CroCo's "mean 3D point seen by the first view", which
// its pair sampler aims the second camera at); nullopt when no pixel is valid. Accumulated in
// double.
std::optional<Eigen::Vector3d> meanValidPoint(const Camera& camera, const ImageF& depth);

// Throws paircast::Error unless `depth` is [camera.height, camera.width, 1].
void checkDepthMatches(const Camera& camera, const ImageF& depth);

// Number of valid pixels.
size_t countValidDepth(const ImageF& depth);

}  // namespace paircast
