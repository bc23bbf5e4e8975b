// A helper of the render tests.
#pragma once

#include "render/ray_caster.h"

namespace paircast {

// Renders `mesh` from `camera` lit by ambient light only, so that each pixel shows its albedo.
inline Frame renderAlbedo(const Mesh& mesh, const Camera& camera) {
  const RayCaster caster(mesh);
  RenderOptions options;
  options.shading.ambient = 1.0f;
  options.shading.headlight = 0.0f;
  options.shading.sun = 0.0f;
  Frame frame;
  caster.render(camera, options, frame);
  return frame;
}

}  // namespace paircast
