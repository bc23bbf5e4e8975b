// The shard format: the one place where paircast's tar shards are defined. Every writer and
// reader goes through it (docs/dataset.md, "The shard format").
//
// A shard is a ustar archive of samples. The sample with key K and V views is the consecutive
// members K.1.jpg ... K.V.jpg, each optionally followed by K.k.depth.exr, K.k.covis.png and
// K.k.flow.flo, then K.json, its record. Depth, masks and flow are there for every view or for
// none. The record carries
// paircast_shard_version; a reader refuses a shard of another version.
//
// Legend: V views.
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "util/camera.h"

namespace paircast {

constexpr int kShardVersion = 1;
// The most views a sample may have: names stay at two digits (<idx>_<k>.jpeg, <key>.<k>.jpg).
constexpr int kMaxViews = 99;

// The key of a sample: "<scene>-<index:08>", with the scene name reduced to [A-Za-z0-9_-].
std::string sampleKey(const std::string& scene, uint64_t index);
std::string sanitizeName(const std::string& name);

// ---- Member names ------------------------------------------------------------------------------

enum class MemberKind { kImage, kDepth, kCovisMask, kFlow, kRecord };
// The kinds stored per view, in the order a sample's members of one view are written.
constexpr int kViewMemberKinds = 4;

// "K.k.jpg", "K.k.depth.exr", "K.k.covis.png", "K.k.flow.flo" (view k from 1) or "K.json".
std::string memberName(const std::string& key, MemberKind kind, int view = 0);

struct MemberName {
  std::string key;
  MemberKind kind = MemberKind::kRecord;
  int view = 0;  // from 1; 0 for the record
};
// What memberName() wrote, or nullopt for a name it never writes (another extension, a view
// number out of [1, kMaxViews] or with a leading zero). Keys have no dots.
std::optional<MemberName> parseMemberName(const std::string& name);

// The view that view `view`'s flow (K.k.flow.flo, from 0 here) goes into: view 0's flow goes
// into view 1 (CroCo's views 1 and 2 of a pair), every other view's into view 0, the reference.
inline int flowTarget(int view) { return view == 0 ? 1 : 0; }

// ---- The record --------------------------------------------------------------------------------

// A sample's record, complete. Views are numbered from 0 here (view 0 is CroCo's view 1).
struct SampleRecord {
  std::string scene;
  uint64_t index = 0;
  std::optional<uint64_t> seed;  // the sample's seed (written by generate_pairs)
  int views = 2;
  std::vector<Camera> camera;                   // [V]
  std::vector<std::array<double, 4>> rotation;  // [V] habitat quaternions (w, x, y, z)
  double covis = 0, v_ij = 0, v_ji = 0;         // views 0 and 1, in [0, 1] (0 with one view)
  // [V] CroCo's covisibility_ratios: view 0's valid fraction, then each view's covis with view 0.
  std::vector<double> covisibilityRatios;
  std::vector<double> validFractions;  // [V] each view's share of pixels that hit the scene
  // [V][V] CroCo's pairwise_visibility_ratios: v_ij off the diagonal, valid fractions on it.
  std::vector<std::vector<double>> pairwiseVisibility;
  std::optional<uint64_t> candidates;  // candidates tried for the sample
};

// The JSON record of `r` (with the version); `extra` keys (e.g. generate_pairs' candidate_covis,
// screened, up) are added as they are.
nlohmann::json recordToJson(const SampleRecord& r,
                            const nlohmann::json& extra = nlohmann::json::object());

// Throws paircast::Error naming `source` when a field is missing, of the wrong type or out of
// range. Fields that older records lack (seed, orientations, the ratios, the matrix, candidates)
// are optional, and checked when present.
SampleRecord parseSampleRecord(const nlohmann::json& record, const std::string& source);

// Throws paircast::Error naming `shard` when `record` is of another paircast_shard_version than
// this code reads: one line with both versions, and how to regenerate the shard.
void checkShardVersion(const nlohmann::json& record, const std::string& shard);

}  // namespace paircast
