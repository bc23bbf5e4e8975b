// The mechanism probes of covis_sweep: does a model use the second view? Run on held-out pairs
// (covis in [0.3, 0.7] by default), each with one fixed mask:
//   reference use: the completion loss of view 1 with its true view 2 (L_true) against the same
//     with a view 2 from another held-out scene (L_other), same masks: ref_gain = 1 - L_true /
//     L_other over the masked patches; ref_gain_covisible over the masked patches at least half
//     seen by view 2, ref_gain_hidden over those not seen at all (of them, those with depth on
//     at least half their pixels: a patch of empty sky is not "hidden").
//   correspondence: with view 1 unmasked, each view-1 patch is matched to a view-2 patch and
//     scored against the truth from depth and poses (patch_correspondence.h):
//     xattn: the decoder's cross-attention scores, averaged over blocks and heads, made
//     reciprocal with the swapped pair (S12 + S21^T) and read by argmax (ZeroCo);
//     enc: the frozen encoder's patch features, cosine nearest neighbour.
// Shapes: M pairs, N patches per view (G x G), S = the model's img_size.
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "dataset/pair_generator.h"
#include "model/croco_net.h"
#include "sweep/patch_correspondence.h"

namespace paircast {

struct MechanismPairs {
  torch::Tensor img1, img2;                // [M, 3, S, S] ImageNet-normalised
  torch::Tensor mask;                      // [M, N] bool, the fixed mask of each pair
  torch::Tensor seen;                      // [M, N] float, share of each view-1 patch view 2 sees
  torch::Tensor valid;                     // [M, N] float, share of it with depth
  std::vector<int64_t> other;              // [M] whose view 2 is pair i's foreign reference
  std::vector<PatchCorrespondence> truth;  // [M] view 1's patch centres in view 2
  std::vector<double> covis;               // [M]
  std::vector<std::string> scene;          // [M]

  int64_t size() const { return static_cast<int64_t>(covis.size()); }
};

// For every pair, a pair of another scene whose view 2 serves as its foreign reference: the k-th
// pair of a scene takes the (k mod n)-th of the n pairs of the next scene (scenes in order of
// first appearance, cyclically). So the choice is fixed, and never of the same scene. Empty
// when the pairs come from fewer than two scenes.
std::vector<int64_t> otherSceneReferences(const std::vector<std::string>& scenes);

struct MechanismPairOptions {
  int pairsPerScene = 48;
  double minCovis = 0.3, maxCovis = 0.7;
  int size = 112, patch = 16;  // the model's img_size and patch_size: pairs render at that size
  int maskedPatches = 44;      // per pair, drawn once
  uint64_t seed = 0;
  int threads = 0;  // generation threads (0: OpenMP's default)
};

// Generates the pairs, scene by scene (indices 0, 1, ... until pairsPerScene, at most 8 times
// as many tried), with `generators` (one per scene, with its name). Throws paircast::Error when
// a scene gives no pair.
MechanismPairs makeMechanismPairs(const std::vector<const PairGenerator*>& generators,
                                  const std::vector<std::string>& names,
                                  const MechanismPairOptions& options);
// The pair options makeMechanismPairs expects its generators to have.
PairOptions mechanismPairOptions(const MechanismPairOptions& options);

struct ReferenceUse {
  double gain = NAN, covisible = NAN, hidden = NAN;
};
ReferenceUse referenceUse(CroCoNet& model, const MechanismPairs& pairs, int batch = 16);

// Per pair, its seen patches' scores.
std::vector<MatchTally> crossAttentionMatches(CroCoNet& model, const MechanismPairs& pairs,
                                              int batch = 16);
std::vector<MatchTally> encoderMatches(CroCoNet& model, const MechanismPairs& pairs,
                                       int batch = 16);
// Argmax per row of a cost volume [N1, N2].
std::vector<int64_t> argmaxMatches(const torch::Tensor& cost);
// The reciprocal cost volume [B, N1, N2] of the scores of (view 1, view 2) [B, N1, N2] and of the
// swapped pair (view 2, view 1) [B, N2, N1]: S12 + S21^T.
torch::Tensor reciprocalCost(const torch::Tensor& s12, const torch::Tensor& s21);

// A model's figures: ref_gain, ref_gain_covisible, ref_gain_hidden, xattn_pck1, xattn_epe and
// enc_pck1, plus "probe_by_covis": per covis bin of 0.1 of the held-out pairs, its pairs and the
// correspondence figures. A model of task "mae" has no reference: only enc_pck1 is measured
// (the others are NaN, null in files); a "cat" decoder has no cross-attention (xattn_* NaN).
nlohmann::json mechanismProbes(CroCoNet& model, const MechanismPairs& pairs,
                               const std::string& task);

}  // namespace paircast
