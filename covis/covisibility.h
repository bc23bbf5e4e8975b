// Co-visibility of two views from their depth maps, by reprojection. For each valid pixel of
// view i (depth > 0), its 3D point is projected into view j; it is visible there when it lands
// inside the frame, in front of the camera, and agrees with view j's depth d at the pixel that
// contains the projection (nearest pixel) within absTol + relTol * d. Otherwise something nearer
// to j hides it, or it hides what j sees.
//   v_ij = visible pixels of i / valid pixels of i      (Normalize::Valid, the paper's)
//   v_ij = visible pixels of i / all pixels of i        (Normalize::All, CroCo's generator)
//   covis = min(v_ij, v_ji)
// Depth maps are [H, W, 1] z-depth in metres matching their camera's size, 0 on a miss (NaN,
// inf and negative values count as misses too). docs/covis.md has the reasons for the defaults.
#pragma once

#include <cstddef>
#include <string>

#include "util/camera.h"
#include "util/image.h"

namespace paircast {

struct CovisOptions {
  enum class Normalize { Valid, All };
  float absTol = 0.03f;  // metres
  float relTol = 0.03f;  // fraction of view j's depth at the looked-up pixel
  Normalize normalize = Normalize::Valid;
  // Sub-sampling of the source view: every stride-th pixel of every stride-th row of i (and of
  // j for v_ji) is projected; lookups in the other view stay at full resolution. 1 = exact.
  int stride = 1;
};

struct CovisResult {
  double v_ij = 0;     // share of view i seen by view j
  double v_ji = 0;     // share of view j seen by view i
  double covis = 0;    // min(v_ij, v_ji)
  double valid_i = 0;  // fraction of view i's (sampled) pixels with valid depth
  double valid_j = 0;
};

// One direction, as counts over the sampled pixels of i.
struct VisibleCount {
  size_t visible = 0;  // valid pixels of i visible in j
  size_t valid = 0;    // valid pixels of i
  size_t total = 0;    // pixels of i
};
VisibleCount countVisible(const Camera& ci, const ImageF& depthI, const Camera& cj,
                          const ImageF& depthJ, const CovisOptions& options = {});

// The pixels behind countVisible's count, at full resolution (stride ignored): [Hi, Wi, 1], 255
// where view i's pixel is seen by view j (inside its frame, in front of it, not occluded), 0
// elsewhere. Over i's valid pixels, the share of 255 is v_ij exactly.
Image8 visibilityMask(const Camera& ci, const ImageF& depthI, const Camera& cj,
                      const ImageF& depthJ, const CovisOptions& options = {});

// One direction: v_ij, normalised as options.normalize says (0 when the denominator is 0).
double visibleFraction(const Camera& ci, const ImageF& depthI, const Camera& cj,
                       const ImageF& depthJ, const CovisOptions& options = {});

// An upper bound of v_ij that needs no depth of view j: the share of i's valid (sampled)
// pixels that land inside j's frame and in front of it, occlusion left out. With stride 1,
// visibleFraction(ci, depthI, cj, any depthJ) never exceeds it.
double inFrameFraction(const Camera& ci, const ImageF& depthI, const Camera& cj,
                       const CovisOptions& options = {});

// Both directions. Swapping the views swaps v_ij and v_ji exactly.
CovisResult computeCovisibility(const Camera& ci, const ImageF& depthI, const Camera& cj,
                                const ImageF& depthJ, const CovisOptions& options = {});

// Parses "valid" or "all" (the --covis-normalize values); throws paircast::Error otherwise.
CovisOptions::Normalize parseCovisNormalize(const std::string& text);
const char* toString(CovisOptions::Normalize normalize);

}  // namespace paircast
