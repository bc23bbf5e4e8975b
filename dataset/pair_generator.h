// One CroCo pair at a time: a reference view with enough valid depth, then second views from a
// random walk until one's co-visibility lies in the band, as CroCo's habitat generator does.
// A pair is a pure function of (scene, seed, index), so any thread may make any pair and the
// output does not depend on how work was split.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "covis/covisibility.h"
#include "dataset/viewpoint_sampler.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "util/image.h"

namespace paircast {

struct PairOptions {
  int resolution = 256;   // square images, pixels
  double hfov = 60.0;     // degrees
  double minCovis = 0.5;  // keep a pair when covis lies in [minCovis, maxCovis]
  double maxCovis = 1.0;
  // When set, decides instead of [minCovis, maxCovis] (covis_sweep's buckets). Must be pure.
  std::function<bool(double covis)> accept;
  double minValidFraction = 0.7;  // of each view's pixels with depth > 0
  int maxAttempts = 100;          // second views tried per reference view
  int maxReferences = 20;         // reference views tried per pair before it is given up
  bool keepDepth = true;          // keep the depth maps in the sample
  CovisOptions covis;
  SamplerOptions sampler;
  RenderOptions render;
};

struct PairSample {
  std::string scene;  // scene name (unique within a run)
  uint64_t index = 0;
  uint64_t seed = 0;
  Camera camera[2];
  Image8 rgb[2];    // [H, W, 3] sRGB
  ImageF depth[2];  // [H, W, 1] z-depth, metres, 0 on a miss (empty unless keepDepth)
  CovisResult covis;
  std::vector<float> candidateCovis;  // covis of every second view tried, accepted one last
  double renderSeconds = 0;
  double covisSeconds = 0;
};

class PairGenerator {
 public:
  // All references must outlive the generator. Thread-safe: generate() is const.
  PairGenerator(const Scene& scene, const RayCaster& caster, const ViewpointSampler& sampler,
                const PairOptions& options);

  // The pair of `index`, or nullopt when no pair was found within the attempt limits
  // (`candidates`, when given, still receives the covis of every candidate tried).
  std::optional<PairSample> generate(uint64_t seed, uint64_t index,
                                     std::vector<float>* candidates = nullptr) const;

  const PairOptions& options() const { return options_; }

 private:
  const Scene& scene_;
  const RayCaster& caster_;
  const ViewpointSampler& sampler_;
  PairOptions options_;
  Camera intrinsics_;
};

// Mean world point of the valid pixels of a depth map (CroCo's "observed point").
Eigen::Vector3d meanWorldPoint(const Camera& camera, const ImageF& depth);

}  // namespace paircast
