// CroCo's folder layout (its habitat_release), shared by generate_pairs and its --from-metadata
// replay: <scene>/<idx:08>_<k>.jpeg for views k = 1..N, with _<k>_depth.exr,
// _<k>_camera_params.json, _<k>_covis.png and _<k>_flow.flo when asked for; pairs.txt lists the (1, k) pairs.
#pragma once

#include <string>
#include <vector>

#include "dataset/shard.h"
#include "util/camera.h"

namespace paircast {

// "00000042": CroCo's 8-digit sample index.
std::string crocoIndex(uint64_t index);

// Writes one sample's files under `stem` (<dir>/<idx:08>), each atomically (no fsync: a kill
// cannot lose them). The last view's image is written last, so that its presence means the
// sample is whole. Depth and camera files come with `enc.depthExr`, masks with `enc.covisPng`,
// flow with `enc.flowFlo`.
void writeCrocoSample(const std::string& stem, const EncodedPair& enc,
                      const std::vector<Camera>& cameras);

// pairs.txt lines of a sample: "scene/idx_1.jpeg scene/idx_k.jpeg\n" for k = 2..views.
std::string crocoPairLines(const std::string& scene, const std::string& index, int views);

}  // namespace paircast
