// Hand-made samples of N views for the shard and record tests: no scene, no renderer.
#pragma once

#include <string>

#include "dataset/pair_generator.h"

namespace paircast::testing {

// Views of 16x16 pixels with distinct colours and poses; covis[k] = v_ij = `covis`, v_ji =
// `covis` + 0.1, valid fractions 1.
inline PairSample fakeSample(const std::string& scene, uint64_t index, int views = 2,
                             bool depth = false, double covis = 0.6, bool masks = false) {
  PairSample s;
  s.scene = scene;
  s.index = index;
  s.seed = 5;
  s.visibility.assign(views, std::vector<double>(views, 1.0));
  for (int k = 0; k < views; ++k) {
    s.camera.push_back(Camera::fromHfov(16, 16, 60));
    s.camera[k].t_cam2world = Eigen::Vector3d(k, 1.5, static_cast<double>(index));
    s.rgb.push_back(Image8(16, 16, 3, static_cast<uint8_t>(40 * k + index)));
    s.depth.push_back(depth ? ImageF(16, 16, 1, 2.0f + k) : ImageF());
    if (masks) s.covisMask.push_back(Image8(16, 16, 1, k ? 255 : 0));
    CovisResult c;
    c.covis = c.v_ij = k ? covis : 1.0;
    c.v_ji = k ? covis + 0.1 : 1.0;
    c.valid_i = c.valid_j = 1.0;
    s.covis.push_back(c);
    if (k) {
      s.visibility[0][k] = c.v_ij;
      s.visibility[k][0] = c.v_ji;
    }
  }
  return s;
}

}  // namespace paircast::testing
