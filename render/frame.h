// What one rendered view holds. All maps are [H, W, C] row-major, pixel (u, v) at index
// v * W + u.
#pragma once

#include <Eigen/Core>

#include "util/image.h"

namespace paircast {

struct Frame {
  Image8 rgb;         // [H, W, 3] 8-bit sRGB
  ImageF depth;       // [H, W, 1] z-depth in metres (distance along the optical axis), 0 on a miss
  ImageF normals;     // [H, W, 3] unit world-frame normal, turned towards the camera; 0 on a miss
  ImageI triangleId;  // [H, W, 1] index into Mesh::triangles, -1 on a miss
  ImageI materialId;  // [H, W, 1] index into Mesh::materials, -1 on a miss

  // Fraction of pixels with depth > 0.
  double validFraction() const;
};

// Share of a depth map's pixels with depth > 0 (0 for an empty map).
double validFraction(const ImageF& depth);

struct ShadingOptions {
  float ambient = 0.35f;    // light reaching every surface
  float headlight = 0.55f;  // Lambert term from a light at the camera
  float sun = 0.25f;        // Lambert term from a fixed directional light (world `sunDirection`)
  Eigen::Vector3f sunDirection = Eigen::Vector3f(0.3f, 1.0f, 0.2f);  // towards the light
  Eigen::Vector3f background = Eigen::Vector3f::Zero();              // linear RGB on a miss
};

struct RenderOptions {
  bool rgb = true;
  bool normals = true;
  bool ids = true;
  int supersample = 1;  // s x s colour samples per pixel (1..4); geometry maps use the centre
  ShadingOptions shading;
};

}  // namespace paircast
