#include "sweep/patch_correspondence.h"

#include <cmath>

#include "util/error.h"

namespace paircast {

int PatchCorrespondence::seenCount() const {
  int n = 0;
  for (uint8_t s : seen) n += s;
  return n;
}

namespace {

void checkSize(const Camera& camera, const ImageF& depth, int side, const char* what) {
  if (camera.width != side || camera.height != side || depth.width != side ||
      depth.height != side || depth.channels != 1)
    throw Error(std::string(what) + ": camera and depth must be " + std::to_string(side) + "x" +
                std::to_string(side) + " (the patch grid's size)");
}

// Whether view 2 sees the view-2 camera point q, which projects to pixel coordinates xy.
bool seenBy(const ImageF& depth2, const Eigen::Vector3d& q, const Eigen::Vector2d& xy,
            const CovisOptions& tol) {
  if (q.z() <= 0 || xy.x() < 0 || xy.y() < 0 || xy.x() >= depth2.width || xy.y() >= depth2.height)
    return false;
  const float d = *depth2.pixel(static_cast<int>(xy.x()), static_cast<int>(xy.y()));
  return std::isfinite(d) && d > 0 && std::abs(q.z() - d) <= tol.absTol + tol.relTol * d;
}

}  // namespace

PatchCorrespondence truePatchCorrespondence(const Camera& view1, const ImageF& depth1,
                                            const Camera& view2, const ImageF& depth2, int patch,
                                            const CovisOptions& tol) {
  PAIRCAST_CHECK(patch > 0);
  const int side = view1.width, G = side / patch;
  if (side % patch != 0) throw Error("the view's size is not a whole number of patches");
  checkSize(view1, depth1, side, "view 1");
  checkSize(view2, depth2, side, "view 2");
  PatchCorrespondence out;
  out.grid = G;
  out.x.assign(G * G, NAN);
  out.y.assign(G * G, NAN);
  out.seen.assign(G * G, 0);
  const Eigen::Isometry3d view2FromView1 = view2.cameraFromWorld() * view1.worldFromCamera();
  for (int r = 0; r < G; ++r)
    for (int c = 0; c < G; ++c) {
      const int u = c * patch + patch / 2, v = r * patch + patch / 2;
      const float z = *depth1.pixel(u, v);
      if (!std::isfinite(z) || z <= 0) continue;
      // The centre (u, v) as pixel coordinates: a corner of pixel (u, v) for even patches.
      const double cx = c * patch + 0.5 * patch, cy = r * patch + 0.5 * patch;
      const Eigen::Vector3d q = view2FromView1 * (view1.rayCamera(cx, cy) * z);
      if (q.z() <= 0) continue;
      const Eigen::Vector2d xy = view2.project(q);
      const int i = r * G + c;
      out.x[i] = static_cast<float>(xy.x() / patch);
      out.y[i] = static_cast<float>(xy.y() / patch);
      out.seen[i] = seenBy(depth2, q, xy, tol);
    }
  return out;
}

std::vector<float> patchShare(const Image8& mask, int patch) {
  PAIRCAST_CHECK(patch > 0 && mask.channels == 1 && mask.width == mask.height &&
                 mask.width % patch == 0);
  const int G = mask.width / patch;
  std::vector<float> share(G * G, 0.f);
  for (int y = 0; y < mask.height; ++y)
    for (int x = 0; x < mask.width; ++x)
      if (*mask.pixel(x, y) == 255) share[(y / patch) * G + x / patch] += 1.f;
  for (float& s : share) s /= static_cast<float>(patch * patch);
  return share;
}

void MatchTally::add(const std::vector<int64_t>& matches, const PatchCorrespondence& truth) {
  const int G = truth.grid;
  PAIRCAST_CHECK(static_cast<int64_t>(matches.size()) == int64_t{G} * G);
  for (size_t i = 0; i < matches.size(); ++i) {
    if (!truth.seen[i]) continue;
    const double px = matches[i] % G + 0.5, py = matches[i] / G + 0.5;
    const double e = std::hypot(px - truth.x[i], py - truth.y[i]);
    ++patches;
    hits += e <= 1.0;
    errorSum += e;
  }
}

void MatchTally::add(const MatchTally& o) {
  patches += o.patches;
  hits += o.hits;
  errorSum += o.errorSum;
}

double MatchTally::pck1() const {
  return patches ? static_cast<double>(hits) / patches : NAN;
}

double MatchTally::epe() const {
  return patches ? errorSum / patches : NAN;
}

}  // namespace paircast
