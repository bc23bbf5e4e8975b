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
#include "shard/shard_format.h"  // kMaxViews
#include "util/image.h"

namespace paircast {

constexpr int kAutoScreen = -1;
constexpr int kAutoScreenDivisor = 16;
constexpr int kMinAutoScreen = 16;

struct PairOptions {
  static constexpr int kMinResolution = 16, kMaxResolution = 4096;
  static constexpr double kMinHfov = 1.0, kMaxHfov = 179.0;

  // Checks what a user sets; throws OptionError naming the field.
  void validate() const;

  int resolution = 256;   // square images, pixels
  double hfov = 60.0;     // degrees
  double minCovis = 0.5;  // keep a view when its covis with view 1 lies in [minCovis, maxCovis]
  double maxCovis = 1.0;
  // When set, decides instead of [minCovis, maxCovis] (covis_sweep's buckets). Must be pure.
  // Screening then checks valid depth only.
  std::function<bool(double covis)> accept;
  int views = 2;                  // CroCo's views_count: view 1 (the reference) and views - 1 more
  double minValidFraction = 0.7;  // of each view's pixels with depth > 0
  int maxAttempts = 100;          // candidates tried per view before the reference is given up
  int maxReferences = 20;         // reference views tried per sample before it is given up
  bool keepDepth = true;          // keep the depth maps in the sample
  bool covisMasks = false;        // fill PairSample::covisMask
  // Screening: each view is first rendered as a screenResolution^2 depth map, and only views whose
  // valid fraction and covis there come within the margins of passing go on to full resolution.
  // 0 turns it off; kAutoScreen picks resolution / 16 (at least 16), and off below 64 pixels.
  // A view that passes is screened again at twice the resolution, and so on while that is at most
  // a quarter of the output's side (256: 16, 32, 64). A 32x32 estimate may fall screenCovisMargin
  // outside the band, a 64x64 one screenFineMargin, other sides the same ratio per doubling (16:
  // 0.375, 128: 0.024). docs/dataset.md has the measurements behind the defaults.
  int screenResolution = kAutoScreen;
  double screenCovisMargin = 0.15;
  double screenFineMargin = 0.06;
  // Before any rendering, a candidate is turned down when the share of the reference's pixels
  // (every resolution/64-th) inside its frame, an upper bound of covis, is below minCovis by more
  // than this.
  double screenFrameMargin = 0.03;
  double screenValidMargin = 0.05;
  // Benchmarks: also render every screened-out view at full resolution, to count the ones that
  // would have passed (PairSample::falseRejections). It changes no output.
  bool auditScreening = false;
  CovisOptions covis;
  SamplerOptions sampler;
  RenderOptions render;
};

// The screening resolution in use (kAutoScreen resolved), 0 when off.
int screenResolution(const PairOptions& options);

// One screening stage: the side of its depth maps and how far outside the band its covis
// estimate may fall.
struct ScreenStageSpec {
  int side;
  double margin;
};
// The stages `options` give, coarse to fine (empty when screening is off): sides S, 2S, 4S, ...
// while at most a quarter of the output's, each with its side's margin (PairOptions).
std::vector<ScreenStageSpec> screenStages(const PairOptions& options);

// Views are numbered from 0 here (view 0 is CroCo's view 1, the reference).
struct PairSample {
  std::string scene;  // scene name (unique within a run)
  uint64_t index = 0;
  uint64_t seed = 0;
  std::vector<Camera> camera;  // [V]
  // [V] the habitat quaternions the rotations were made from (metadata.json's "orientations");
  // may be empty (then computed from the rotations)
  std::vector<HabitatQuaternion> orientation;
  std::vector<Image8> rgb;    // [V] [H, W, 3] sRGB
  std::vector<ImageF> depth;  // [V] [H, W, 1] z-depth, metres, 0 on a miss (empty unless keepDepth)
  // [V] covis[k]: view 0 (i) against view k (j). covis[0] is view 0 against itself: all ratios 1,
  // valid fractions its own.
  std::vector<CovisResult> covis;
  // [V][V] visibility[i][j] = v_ij (share of view i seen by view j); the diagonal holds each
  // view's valid fraction (CroCo's pairwise_visibility_ratios).
  std::vector<std::vector<double>> visibility;
  // [V] [H, W, 1] when PairOptions::covisMasks: view k > 0: its pixels seen by view 0; view 0: its
  // pixels seen by at least one other view (with V = 2, the pixels of each seen by the other).
  std::vector<Image8> covisMask;
  // covis of every candidate tried for the sample (screened ones: their estimate), as its record
  // keeps them
  std::vector<float> candidateCovis;

  int views() const { return static_cast<int>(camera.size()); }
};

// What one generate() call spent, with or without a sample: run statistics, kept apart from the
// sample.
struct GenerationCost {
  std::vector<float> candidateCovis;  // covis of every candidate tried (screened ones: estimate)
  size_t screened = 0;                // candidates and references turned down by screening
  size_t falseRejections = 0;         // of those, the ones full resolution would have kept (audit)
  double renderSeconds = 0;           // full resolution
  double keptRenderSeconds = 0;       // of those, the renders of the views in the sample
  size_t fullRenders = 0, keptRenders = 0;
  double screenSeconds = 0;  // screening: low-resolution renders and covis estimates
  double covisSeconds = 0;
  double totalSeconds = 0;  // all of generate(): the rest is pose sampling and bookkeeping
};

class PairGenerator {
 public:
  // All references must outlive the generator. Thread-safe: generate() is const.
  PairGenerator(const Scene& scene, const RayCaster& caster, const ViewpointSampler& sampler,
                const PairOptions& options);

  // The sample of `index`, or nullopt when none was found within the attempt limits.
  // `spent`, when given, receives what the call cost either way.
  std::optional<PairSample> generate(uint64_t seed, uint64_t index,
                                     GenerationCost* spent = nullptr) const;

  const PairOptions& options() const { return options_; }

 private:
  struct View;
  std::optional<View> referenceView(Rng& rng, GenerationCost& cost) const;
  std::optional<View> otherView(const View& ref, const Eigen::Vector3d& target, Rng& rng,
                                GenerationCost& cost) const;
  // One screening pass: the intrinsics it renders with, and how far outside the band its covis
  // estimate may fall.
  struct ScreenStage {
    Camera intrinsics;
    double covisMargin;
  };
  bool screenedOut(const View* ref, View& v, GenerationCost& cost) const;
  bool outOfFrame(const View& ref, const View& v, GenerationCost& cost) const;
  bool failsStage(size_t stage, const View* ref, View& v, GenerationCost& cost) const;
  Camera screenCamera(size_t stage, const View& v, GenerationCost& cost) const;
  void renderFull(View& v, bool rgb, GenerationCost& cost) const;
  bool inBand(double covis) const;
  void finish(std::vector<View>& views, PairSample& s, GenerationCost& cost) const;
  void makeMasks(const std::vector<View>& views, PairSample& s) const;

  const Scene& scene_;
  const RayCaster& caster_;
  const ViewpointSampler& sampler_;
  PairOptions options_;
  Camera intrinsics_;
  std::vector<ScreenStage> screens_;  // coarse to fine; empty without screening
  size_t referenceStages_ = 0;        // the stages a reference goes through (valid depth only)
};

// Mean world point of the valid pixels of a depth map (CroCo's "observed point").
Eigen::Vector3d meanWorldPoint(const Camera& camera, const ImageF& depth);

}  // namespace paircast
