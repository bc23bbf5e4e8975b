// Ground-truth patch correspondences between two rendered views, from depth and poses, and the
// scores of a matcher against them (PCK at one patch, end-point error in patches). Patch (c, r)
// of a G x G grid covers pixels [c p, (c + 1) p) x [r p, (r + 1) p); positions in "patch units"
// are pixel coordinates divided by p, so patch (c, r)'s centre is (c + 0.5, r + 0.5).
#pragma once

#include <cstdint>
#include <vector>

#include "covis/covisibility.h"
#include "util/camera.h"
#include "util/image.h"

namespace paircast {

// Where the centre of every view-1 patch lands in view 2.
struct PatchCorrespondence {
  int grid = 0;               // G: patches per side
  std::vector<float> x, y;    // [N] the centre's position in view 2, patch units
  std::vector<uint8_t> seen;  // [N] 1 when view 2 sees it: depth at the centre, inside view 2's
                              // frame, in front of it, and not occluded (covis's tolerances)
  int seenCount() const;
};

// The patch centre (c p + p / 2, r p + p / 2) is lifted with view 1's depth at the pixel whose
// corner it is (column c p + p / 2, row r p + p / 2) and projected into view 2. Depth maps are
// [S, S, 1] with S = G p, as the cameras. Throws paircast::Error when sizes disagree.
PatchCorrespondence truePatchCorrespondence(const Camera& view1, const ImageF& depth1,
                                            const Camera& view2, const ImageF& depth2, int patch,
                                            const CovisOptions& tolerances = {});

// The share of each patch's pixels that are 255 in an 8-bit mask [S, S, 1]: [N], row-major.
std::vector<float> patchShare(const Image8& mask, int patch);

// Scores of matches over the seen patches of many pairs. A match is the index of a view-2 patch
// (row-major); its error is the distance in patch units from its centre to the true position.
struct MatchTally {
  int64_t patches = 0, hits = 0;  // seen patches scored; those with an error of at most 1
  double errorSum = 0;

  // matches [N] for one pair.
  void add(const std::vector<int64_t>& matches, const PatchCorrespondence& truth);
  void add(const MatchTally& other);
  double pck1() const;  // hits / patches (NaN without patches)
  double epe() const;   // mean error in patches (NaN without patches)
};

}  // namespace paircast
