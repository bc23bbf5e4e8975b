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
  // outside the band, a 64x64 one screenFineMargin, finer ones half as far per doubling (128:
  // 0.005), coarser ones 2.5 times as far per halving (16: 0.075). docs/dataset.md has the
  // measurements behind the defaults.
  int screenResolution = kAutoScreen;
  double screenCovisMargin = 0.03;
  double screenFineMargin = 0.01;
  // A stage's estimate against the band's lower bound takes covis' depth tolerances times half
  // the ratio of the output's side to the stage's (at 256: 4 at 32x32, 2 at 64x64, 1 from 128x128
  // on), as the nearest pixel of a coarse depth map lies farther from the point looked up. Without
  // it, estimates fall below full resolution's covis (by 0.05 for one candidate in 100 at 64x64)
  // and the margins must cover that; with it, they are tight. The upper bound (below 1) takes
  // the plain tolerances. false: plain tolerances throughout, which need margins of about 0.18
  // and 0.04.
  bool screenScaleTolerance = true;
  // A candidate whose estimate lies inside the band by its stage's margin or more, with valid
  // pixels as clear, skips the finer stages (at 256: a 32x32 estimate of 0.53 or more goes to
  // full resolution). 1-4 % of those fail at full resolution, which costs less than rendering
  // them all at 64x64 (docs/dataset.md). false: every candidate takes every stage.
  bool screenSkipClear = true;
  // Before any rendering, a candidate is turned down when the share of the reference's points
  // (the pixels of its last stage's depth, 32x32 at 256; screenPlan) inside its frame, an upper
  // bound of covis, is below minCovis by more than this. At minCovis or more it is off, the
  // default: the sight lines turn down what it would, and it turned down too few (2-9 %) to pay
  // for itself (docs/dataset.md).
  double screenFrameMargin = 1.0;
  double screenValidMargin = 0.05;
  // The glance: before its first stage, a view is rendered as a screenGlanceSide^2 depth map and
  // turned down when its valid fraction is below minValidFraction by more than
  // screenGlanceValidMargin. It drops the references that look out of a scene (open floors, rooms
  // without walls) at a quarter of the first stage's cost. 0: off.
  int screenGlanceSide = 8;
  double screenGlanceValidMargin = 0.15;
  // Candidates glance too, a batch in one pass, and are also turned down when the share of their
  // glance's points that the reference sees (against its points' depth), an estimate of
  // v_ji, is below minCovis by more than screenGlanceCovisMargin. They then skip the first
  // regular stage (16x16 at 256), which turns down almost none after it.
  bool screenCandidateGlance = true;
  double screenGlanceCovisMargin = 0.15;
  // Sight lines: after the in-frame bound, a candidate casts shadow rays to a screenSightSide^2
  // grid of the reference's points (from its last stage's depth); the share that lies in its
  // frame with nothing in between estimates v_ij, and covis <= v_ij. A candidate whose share is
  // below minCovis by more than screenSightMargin is turned down before any rendering. 0: off.
  int screenSightSide = 8;
  double screenSightMargin = 0.25;
  // The confirm stage: a candidate whose last-stage estimate lies within that stage's margin of
  // a bound of the band (so it may go either way) is rendered once more at twice the side, when
  // that is at most half the output's, and must then come within the confirm margin (128 at 256:
  // 0.005, half the 64x64 one). The rest of the candidates skip it. Off by default: at 256 it
  // costs more than the full renders it saves (docs/dataset.md).
  bool screenConfirm = false;
  // The valid-pixel margin of the stages of side 64 or more (and of the confirm stage), whose
  // valid fractions lie within 0.004 of full resolution's (references that failed at full
  // resolution, simple_room); coarser stages take screenValidMargin.
  double screenFineValidMargin = 0.005;
  // Candidates are drawn this many at a time; their in-frame bounds and first-stage depth maps
  // are made in one pass, then they go on in the order drawn.
  int screenBatch = 8;
  // A reference is given up when this many of its candidates in a row are turned down by the
  // in-frame bound, the sight lines or the glance (0: never, the default: on simple_room it lost
  // pairs and saved no time, docs/dataset.md).
  int giveUpAfter = 0;
  // Benchmarks: also render every screened-out view at full resolution, to count the ones that
  // would have passed (PairSample::falseRejections). It changes no output.
  bool auditScreening = false;
  CovisOptions covis;
  SamplerOptions sampler;
  RenderOptions render;
};

// The screening resolution in use (kAutoScreen resolved), 0 when off.
int screenResolution(const PairOptions& options);
// The fewest of n pixels whose share (count / n, in double) is not below `share`: 0 to n + 1,
// where n + 1 means that no count passes.
long fewestToPass(double share, long n);

// One screening stage: the side of its depth maps and how far outside the band its covis
// estimate may fall.
struct ScreenStageSpec {
  int side;
  double margin;
};
// The stages `options` give, coarse to fine (empty when screening is off): sides S, 2S, 4S, ...
// while at most a quarter of the output's, each with its side's margin (PairOptions).
std::vector<ScreenStageSpec> screenStages(const PairOptions& options);
// The confirm stage (PairOptions::screenConfirm): twice the last stage's side when that is at most
// half the output's, with its side's margin; nullopt when there is none.
std::optional<ScreenStageSpec> confirmStage(const PairOptions& options);

// The order of screening the options give: every stage (the glance first when there is one, the
// confirm stage last), the ones candidates and references go through, and the funnel's names.
struct ScreenPlan {
  struct Stage {
    int side;
    double margin;
    bool validOnly;  // the glance: valid pixels (and a candidate's v_ji estimate) only
  };
  std::vector<Stage> stages;      // empty without screening
  size_t regular = 0;             // stages without the confirm stage
  std::vector<size_t> candidate;  // the stages a candidate goes through, in order
  // The stages a reference goes through, in order (valid pixels only). The last gives its points:
  // its target, the in-frame bound, the sight lines and the glance's v_ji estimate.
  std::vector<size_t> reference;
  // Checked (valid pixels) before a reference is rendered in full, when its last stage's valid
  // fraction lies within that stage's margin of the bound; none when that is the finest stage.
  std::optional<size_t> referenceFine;

  // The funnels' slot names: candidates "bound", "sight", then a name per stage (side^2, the
  // glance "(glance)"); references a name per stage of `reference`, then the fine check's.
  std::vector<std::string> candidateNames() const;
  std::vector<std::string> referenceNames() const;
};
ScreenPlan screenPlan(const PairOptions& options);

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

// The screening funnel of a run, stage by stage: how many views entered each stage, how many it
// turned down, and the seconds it took.
struct FunnelStage {
  size_t entered = 0, rejected = 0;
  size_t falseRejections = 0;  // of those turned down, the ones full resolution would keep (audit)
  double seconds = 0;
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
  // Of the wasted full renders: references (found no partner, or too few valid pixels at full
  // resolution) and candidates (failed the full-resolution test).
  size_t wastedReferenceRenders = 0, wastedCandidateRenders = 0;
  double screenSeconds = 0;  // screening: low-resolution renders and covis estimates
  double covisSeconds = 0;
  double totalSeconds = 0;  // all of generate(): the rest is pose sampling and bookkeeping
  // Candidates: [0] the in-frame bound, [1] the sight lines, then each stage of the plan;
  // references: each of the plan's reference stages, then the fine check (screenPlan).
  std::vector<FunnelStage> candidateFunnel, referenceFunnel;
  size_t referencesGivenUp = 0;  // references dropped early for lack of promising candidates

  // Adds another call's figures (not its candidateCovis).
  void add(const GenerationCost& other);
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
  struct Search;
  bool makeSample(Search& search, PairSample& sample) const;
  std::optional<View> referenceView(Search& search) const;
  Eigen::Vector3d referenceTarget(const View& ref) const;
  std::optional<View> otherView(View& ref, const Eigen::Vector3d& target, Search& search) const;
  std::vector<View> drawCandidates(const View& ref, const Eigen::Vector3d& target, int count,
                                   Search& search) const;
  void screenFirstStage(const View& ref, std::vector<View>& batch, std::vector<bool>& out,
                        Search& search) const;
  bool screenLaterStages(const View& ref, View& v, Search& search) const;
  bool failsGlance(const View& ref, View& v, GenerationCost& cost) const;
  void renderStageBatch(size_t stage, std::vector<View>& batch, const std::vector<size_t>& which,
                        FunnelStage& funnel, GenerationCost& cost) const;
  bool passesFull(View& ref, View& v, Search& search) const;
  bool referenceIsValid(View& ref, Search& search) const;
  bool referenceIsFine(View& ref, GenerationCost& cost) const;
  // One screening pass: the intrinsics it renders with, and how far outside the band its covis
  // estimate may fall.
  struct ScreenStage {
    Camera intrinsics;
    double covisMargin;
    double validMargin;
    bool validOnly;      // the glance: valid pixels only, no covis estimate
    CovisOptions covis;  // for the estimate against the lower bound (screenScaleTolerance)
  };
  bool screenReference(View& v, GenerationCost& cost) const;
  bool tooFewValid(size_t stage, const View& v, GenerationCost& cost) const;
  bool frameBound() const;
  bool outOfFrame(const View& ref, const View& v, GenerationCost& cost) const;
  bool outOfSight(const View& ref, const View& v, GenerationCost& cost) const;
  const std::vector<Eigen::Vector3f>& sightPoints(const View& ref) const;
  double stageEstimate(size_t stage, const View& ref, const View& v, bool upper,
                       GenerationCost& cost) const;
  bool failsStage(size_t stage, const View* ref, View& v, GenerationCost& cost) const;
  bool ambiguous(size_t stage, const View& v) const;
  Camera stageCamera(size_t stage, const View& v) const;
  void renderStage(size_t stage, const View& v, GenerationCost& cost) const;
  bool audit(const View* ref, const View& v, GenerationCost& cost) const;
  template <typename Test>
  bool funnelTest(FunnelStage& stage, const View* ref, const View& v, GenerationCost& cost,
                  const Test& test) const;
  void renderFull(View& v, bool rgb, GenerationCost& cost) const;
  bool inBand(double covis) const;
  void finish(std::vector<View>& views, PairSample& s, GenerationCost& cost) const;
  void makeMasks(const std::vector<View>& views, PairSample& s) const;

  const Scene& scene_;
  const RayCaster& caster_;
  const ViewpointSampler& sampler_;
  PairOptions options_;
  Camera intrinsics_;
  ScreenPlan plan_;
  // plan_'s stages, coarse to fine, then the confirm stage when there is one; empty without
  // screening.
  std::vector<ScreenStage> screens_;
  size_t pointsStage_ = 0;  // the reference stage its points come from (plan_.reference.back())
};

// Mean world point of the valid pixels of a depth map (CroCo's "observed point").
Eigen::Vector3d meanWorldPoint(const Camera& camera, const ImageF& depth);

}  // namespace paircast
