// An Embree 3 BVH over one mesh, and the renderer of pinhole views on top of it. Embree stays
// behind the pImpl. Building happens once, in the constructor; the render calls are const and
// may run concurrently from several threads, each with its own Frame.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>

#include "render/frame.h"
#include "render/mesh.h"
#include "util/camera.h"

namespace paircast {

// One ray of a batch: origin, direction (any length; t is in units of it), [tnear, tfar].
struct Ray {
  Eigen::Vector3f origin;
  Eigen::Vector3f direction;
  float tnear = 0.0f;
  float tfar = std::numeric_limits<float>::infinity();
};

struct Hit {
  float t = 0.0f;         // ray parameter of the hit; meaningless when triangle < 0
  int32_t triangle = -1;  // -1 on a miss
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // unit geometric normal (not flipped)
};

class RayCaster {
 public:
  // Builds the BVH (static scene, high build quality). The mesh must outlive the caster.
  explicit RayCaster(const Mesh& mesh);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // Z-depth only: the fast path. `depth` is resized to the camera; 0 on a miss.
  void renderDepth(const Camera& camera, ImageF& depth) const;
  // Z-depth of many small views in one parallel pass over all their tiles: the per-call set-up
  // (thread team, tile split) is paid once, not per view. depths[k] is resized to cameras[k].
  void renderDepthBatch(const Camera* cameras, ImageF* depths, size_t count) const;
  // Whether at least `count` of the camera's pixels see the scene (depth > 0): pixel rows are
  // cast top-down, a packet at a time, only until that is decided. On the calling thread.
  bool hitsAtLeast(const Camera& camera, long count) const;
  // Everything the options ask for. Buffers in `frame` are reused when the size matches.
  void render(const Camera& camera, const RenderOptions& options, Frame& frame) const;
  // Arbitrary rays, in parallel.
  void intersect(const Ray* rays, Hit* hits, size_t count) const;
  // Whether anything lies on each ray between tnear and tfar (1: blocked): shadow rays, cheaper
  // than intersect, since any hit will do. Runs on the calling thread.
  void occluded(const Ray* rays, uint8_t* blocked, size_t count) const;

  const Mesh& mesh() const { return mesh_; }
  double buildSeconds() const { return buildSeconds_; }

 private:
  struct Impl;
  const Mesh& mesh_;
  std::unique_ptr<Impl> impl_;
  double buildSeconds_ = 0.0;
};

}  // namespace paircast
