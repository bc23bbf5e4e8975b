#include "dataset/pair_generator.h"

#include <chrono>

#include "util/error.h"
#include "util/random.h"
#include "util/timer.h"

namespace paircast {
namespace {

using Clock = SteadyClock;
constexpr auto since = secondsSince;

double validFraction(const ImageF& depth) {
  size_t valid = 0;
  for (float d : depth.data) valid += d > 0.0f;
  return depth.data.empty() ? 0.0 : static_cast<double>(valid) / depth.data.size();
}

}  // namespace

Eigen::Vector3d meanWorldPoint(const Camera& camera, const ImageF& depth) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  size_t n = 0;
  for (int v = 0; v < depth.height; ++v) {
    for (int u = 0; u < depth.width; ++u) {
      const float d = depth.data[static_cast<size_t>(v) * depth.width + u];
      if (d <= 0.0f) continue;
      sum += d * camera.rayCamera(u + 0.5, v + 0.5);
      ++n;
    }
  }
  PAIRCAST_CHECK(n > 0);
  return camera.R_cam2world * (sum / static_cast<double>(n)) + camera.t_cam2world;
}

PairGenerator::PairGenerator(const Scene& scene, const RayCaster& caster,
                             const ViewpointSampler& sampler, const PairOptions& options)
    : scene_(scene),
      caster_(caster),
      sampler_(sampler),
      options_(options),
      intrinsics_(Camera::fromHfov(options.resolution, options.resolution, options.hfov)) {
  if (!(options.minCovis >= 0 && options.maxCovis <= 1 && options.minCovis <= options.maxCovis))
    throw Error("the covis band must satisfy 0 <= min <= max <= 1");
  if (options.maxAttempts < 1 || options.maxReferences < 1)
    throw Error("attempt limits must be at least 1");
}

std::optional<PairSample> PairGenerator::generate(uint64_t seed, uint64_t index,
                                                  std::vector<float>* candidates) const {
  Rng rng(mixSeed(seed, scene_.name, index));
  PairSample s;
  s.scene = scene_.name;
  s.index = index;
  s.seed = seed;
  ImageF depth[2];
  for (int ref = 0; ref < options_.maxReferences; ++ref) {
    auto t0 = Clock::now();
    const Viewpoint first = sampler_.sampleReference(intrinsics_, rng);
    caster_.renderDepth(first.camera, depth[0]);
    s.renderSeconds += since(t0);
    const double valid0 = validFraction(depth[0]);
    if (valid0 < options_.minValidFraction) continue;
    const Eigen::Vector3d target = meanWorldPoint(first.camera, depth[0]);
    for (int attempt = 0; attempt < options_.maxAttempts; ++attempt) {
      t0 = Clock::now();
      const Viewpoint second = sampler_.sampleOther(intrinsics_, first, target, rng);
      caster_.renderDepth(second.camera, depth[1]);
      s.renderSeconds += since(t0);
      if (validFraction(depth[1]) < options_.minValidFraction) continue;
      t0 = Clock::now();
      const CovisResult c =
          computeCovisibility(first.camera, depth[0], second.camera, depth[1], options_.covis);
      s.covisSeconds += since(t0);
      s.candidateCovis.push_back(static_cast<float>(c.covis));
      if (options_.accept ? !options_.accept(c.covis)
                          : c.covis < options_.minCovis || c.covis > options_.maxCovis)
        continue;
      // Accepted: render the colour images (the geometry is the same as the depth pass).
      t0 = Clock::now();
      s.camera[0] = first.camera;
      s.camera[1] = second.camera;
      s.covis = c;
      Frame frame;
      for (int k = 0; k < 2; ++k) {
        RenderOptions ro = options_.render;
        ro.normals = false;
        ro.ids = false;
        caster_.render(s.camera[k], ro, frame);
        s.rgb[k] = std::move(frame.rgb);
        if (options_.keepDepth) s.depth[k] = std::move(depth[k]);
      }
      s.renderSeconds += since(t0);
      if (candidates) *candidates = s.candidateCovis;
      return s;
    }
  }
  if (candidates) *candidates = s.candidateCovis;
  return std::nullopt;
}

}  // namespace paircast
