#include "dataset/pair_generator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "util/error.h"
#include "util/random.h"
#include "util/timer.h"

namespace paircast {
namespace {

using Clock = SteadyClock;
constexpr auto since = secondsSince;

// outOfFrame projects about a kFrameScreenSide^2 grid of the reference's pixels.
constexpr int kFrameScreenSide = 64;
constexpr int kMaxScreenBatch = 64;
// How much wider a stage's covis margin is than the next finer one's, below 32x32 (16x16: 0.075
// with the default 0.03 at 32x32, docs/dataset.md).
constexpr double kCoarseMarginRatio = 2.5;
// Screening stages of this side or more take the fine valid margin.
constexpr int kFineSide = 64;
// The candidate funnel's slots: the in-frame bound, the sight lines, then the stages.
constexpr size_t kBoundSlot = 0, kSightSlot = 1, kFirstStageSlot = 2;
// A sight line stops short of its point by this share of its length, or this many metres if more,
// so that the surface the point lies on does not block it.
constexpr float kSightRelTol = 0.02f, kSightAbsTol = 0.05f;
// Sight lines are cast this many at a time (RayCaster::occluded's packet).
constexpr size_t kSightPacket = 8;

}  // namespace

// The camera ray is affine in the pixel coordinates, so the sum of depth x ray over the pixels
// is the ray at the depth-weighted mean pixel, times the depth sum: three sums, no per-pixel ray.
Eigen::Vector3d meanWorldPoint(const Camera& camera, const ImageF& depth) {
  double sumD = 0, sumDU = 0, sumDV = 0;
  size_t n = 0;
  for (int v = 0; v < depth.height; ++v) {
    const float* row = depth.data.data() + static_cast<size_t>(v) * depth.width;
    double rowD = 0, rowDU = 0;
    size_t rowN = 0;
    for (int u = 0; u < depth.width; ++u) {
      const double d = row[u] > 0.0f ? row[u] : 0.0;
      rowD += d;
      rowDU += d * (u + 0.5);
      rowN += row[u] > 0.0f;
    }
    sumD += rowD;
    sumDU += rowDU;
    sumDV += rowD * (v + 0.5);
    n += rowN;
  }
  PAIRCAST_CHECK(n > 0);
  const Eigen::Vector3d sum = sumD * camera.rayCamera(sumDU / sumD, sumDV / sumD);
  return camera.R_cam2world * (sum / static_cast<double>(n)) + camera.t_cam2world;
}

// As failsStage compares a share with its bound.
long fewestToPass(double share, long n) {
  const auto passes = [&](long k) { return !(static_cast<double>(k) / n < share); };
  long k = std::clamp(static_cast<long>(std::ceil(share * n)), 0L, n + 1);
  while (k > 0 && passes(k - 1)) --k;
  while (k <= n && !passes(k)) ++k;
  return k;
}

int screenResolution(const PairOptions& o) {
  if (o.screenResolution != kAutoScreen) return o.screenResolution;
  return o.resolution >= 64 ? std::max(kMinAutoScreen, o.resolution / kAutoScreenDivisor) : 0;
}

// The margin at `side`: screenCovisMargin at 32, screenFineMargin at 64, half as much per doubling
// beyond 64, and kCoarseMarginRatio times as much per halving below 32 (a margin of 0 applies as
// given).
double stageMargin(int side, const PairOptions& o) {
  const double m32 = o.screenCovisMargin, m64 = o.screenFineMargin;
  if (side < 32) return std::min(1.0, m32 * std::pow(kCoarseMarginRatio, std::log2(32.0 / side)));
  if (side < 64) return m32 * std::pow(m64 / std::max(m32, 1e-12), std::log2(side / 32.0));
  return m64 * std::pow(0.5, std::log2(side / 64.0));
}

// The covis options of a stage's estimate against the lower bound: the tolerances times half the
// ratio of the output's side to the stage's, at least 1 (PairOptions::screenScaleTolerance).
static CovisOptions stageCovisOptions(int side, const PairOptions& o) {
  CovisOptions c = o.covis;
  if (!o.screenScaleTolerance) return c;
  const float scale = std::max(1.0f, 0.5f * static_cast<float>(o.resolution) / side);
  c.absTol *= scale;
  c.relTol *= scale;
  return c;
}

std::vector<ScreenStageSpec> screenStages(const PairOptions& o) {
  std::vector<ScreenStageSpec> stages;
  for (int side = screenResolution(o); side > 0 && (stages.empty() || 4 * side <= o.resolution);
       side *= 2)
    stages.push_back({side, stageMargin(side, o)});
  return stages;
}

std::optional<ScreenStageSpec> confirmStage(const PairOptions& o) {
  const std::vector<ScreenStageSpec> stages = screenStages(o);
  if (!o.screenConfirm || stages.empty() || 4 * stages.back().side > o.resolution)
    return std::nullopt;
  const int side = 2 * stages.back().side;
  return ScreenStageSpec{side, stageMargin(side, o)};
}

// A reference is judged on its valid pixels at the glance, the first regular stage and the
// next (32x32 at 256), which its points come from; the finest stage (64x64) only checks its valid
// pixels before a full render, when they are near the bound, as most references never need it
// (their candidates skip it). A candidate glances (with its v_ji estimate), then skips the first
// regular stage, which turned down almost none after it, and goes through the rest; without the
// glance, through every stage. Its first stage is made for a whole batch at once.
// docs/dataset.md has the measurements.
ScreenPlan screenPlan(const PairOptions& o) {
  ScreenPlan plan;
  const std::vector<ScreenStageSpec> regular = screenStages(o);
  if (regular.empty()) return plan;
  const bool glance = o.screenGlanceSide > 0 && o.screenGlanceSide < regular.front().side;
  if (glance) plan.stages.push_back({o.screenGlanceSide, 1.0, true});
  for (const ScreenStageSpec& stage : regular)
    plan.stages.push_back({stage.side, stage.margin, false});
  plan.regular = plan.stages.size();
  if (const auto confirm = confirmStage(o))
    plan.stages.push_back({confirm->side, confirm->margin, false});
  const size_t firstRegular = glance ? 1 : 0;
  const size_t points = std::min(firstRegular + 1, plan.regular - 1);
  for (size_t k = 0; k <= points; ++k)
    if (k <= firstRegular || k == points) plan.reference.push_back(k);
  if (points + 1 < plan.regular) plan.referenceFine = plan.regular - 1;
  const bool candidateGlance = glance && o.screenCandidateGlance;
  for (size_t k = 0; k < plan.stages.size(); ++k) {
    if (k == 0 && glance && !candidateGlance) continue;
    if (k == firstRegular && candidateGlance && plan.regular > 2) continue;
    plan.candidate.push_back(k);
  }
  return plan;
}

namespace {

std::string stageName(const ScreenPlan::Stage& stage, const char* glance) {
  return stage.validOnly ? glance : std::to_string(stage.side) + "^2";
}

}  // namespace

std::vector<std::string> ScreenPlan::candidateNames() const {
  std::vector<std::string> names = {"bound", "sight"};
  for (const Stage& stage : stages) names.push_back(stageName(stage, "(glance)"));
  return names;
}

std::vector<std::string> ScreenPlan::referenceNames() const {
  std::vector<std::string> names;
  for (size_t k : reference) names.push_back(stageName(stages[k], "glance"));
  if (referenceFine) names.push_back(stageName(stages[*referenceFine], "glance") + " valid");
  return names;
}

void GenerationCost::add(const GenerationCost& o) {
  screened += o.screened;
  falseRejections += o.falseRejections;
  renderSeconds += o.renderSeconds;
  keptRenderSeconds += o.keptRenderSeconds;
  fullRenders += o.fullRenders;
  keptRenders += o.keptRenders;
  wastedReferenceRenders += o.wastedReferenceRenders;
  wastedCandidateRenders += o.wastedCandidateRenders;
  screenSeconds += o.screenSeconds;
  covisSeconds += o.covisSeconds;
  totalSeconds += o.totalSeconds;
  referencesGivenUp += o.referencesGivenUp;
  auto addFunnel = [](std::vector<FunnelStage>& to, const std::vector<FunnelStage>& from) {
    if (to.size() < from.size()) to.resize(from.size());
    for (size_t k = 0; k < from.size(); ++k) {
      to[k].entered += from[k].entered;
      to[k].rejected += from[k].rejected;
      to[k].seconds += from[k].seconds;
      to[k].falseRejections += from[k].falseRejections;
    }
  };
  addFunnel(candidateFunnel, o.candidateFunnel);
  addFunnel(referenceFunnel, o.referenceFunnel);
}

void PairOptions::validate() const {
  auto in = [](double v, double lo, double hi) { return v >= lo && v <= hi; };
  if (!in(resolution, kMinResolution, kMaxResolution))
    throw OptionError("resolution", "resolution must be in " + std::to_string(kMinResolution) +
                                        ".." + std::to_string(kMaxResolution) + " pixels, got " +
                                        std::to_string(resolution));
  if (!in(hfov, kMinHfov, kMaxHfov))
    throw OptionError("hfov", "hfov must be in [1, 179] degrees, got " + std::to_string(hfov));
  if (!(minCovis >= 0 && maxCovis <= 1 && minCovis <= maxCovis))
    throw OptionError("min_covis", "the covis band must satisfy 0 <= min_covis <= max_covis <= 1");
  if (!in(minValidFraction, 0, 1))
    throw OptionError("min_valid", "the minimum valid fraction must be in [0, 1]");
  if (maxAttempts < 1 || maxReferences < 1)
    throw OptionError("max_attempts", "attempt limits must be at least 1");
  if (!in(sampler.nearTranslation, 0, 100))
    throw OptionError("near_translation", "the near motion's translation must be in [0, 100] m");
  if (!in(sampler.nearRotation, 0, 90))
    throw OptionError("near_rotation", "the near motion's rotation must be in [0, 90] degrees");
  if (views < 1 || views > kMaxViews)
    throw OptionError("views", "views must be in [1, " + std::to_string(kMaxViews) + "], got " +
                                   std::to_string(views));
  if (screenResolution < 0 && screenResolution != kAutoScreen)
    throw OptionError("screen_resolution",
                      "the screening resolution must be >= 0 (0 turns screening off), got " +
                          std::to_string(screenResolution));
  if (screenResolution > resolution)
    throw OptionError("screen_resolution",
                      "the screening resolution (" + std::to_string(screenResolution) +
                          ") must not exceed the resolution (" + std::to_string(resolution) + ")");
  if (!(in(screenCovisMargin, 0, 1) && in(screenFineMargin, 0, 1) && in(screenFrameMargin, 0, 1) &&
        screenValidMargin >= 0 && in(screenFineValidMargin, 0, 1) &&
        in(screenGlanceValidMargin, 0, 1) && in(screenSightMargin, 0, 1) &&
        in(screenGlanceCovisMargin, 0, 1)))
    throw OptionError("screen_margin", "screening margins must be in [0, 1]");
  if (screenBatch < 1 || screenBatch > kMaxScreenBatch)
    throw OptionError("screen_batch", "the screening batch must be in 1.." +
                                          std::to_string(kMaxScreenBatch) + ", got " +
                                          std::to_string(screenBatch));
  if (screenGlanceSide < 0 || screenSightSide < 0)
    throw OptionError("screen_glance", "the glance and sight-line sides must be >= 0 (0: off)");
  if (giveUpAfter < 0)
    throw OptionError("give_up_after", "the give-up count must be >= 0 (0: never), got " +
                                           std::to_string(giveUpAfter));
}

// One view while a sample is being made.
struct PairGenerator::View {
  Viewpoint at;
  ImageF depth;  // [H, W, 1] full resolution, once rendered
  // Per screening stage: [S, S, 1], rendered when the view first reaches the stage (a reference
  // gets its later stages when a candidate needs them), hence mutable.
  mutable std::vector<ImageF> screenDepth;
  mutable ImageF auditDepth;  // a reference's full depth for the audit, apart from its state
  // A reference's sight-line targets (world points), made when a first candidate needs them.
  mutable std::vector<Eigen::Vector3f> sightPoints;
  mutable bool sightPointsMade = false;
  Image8 rgb;                // [H, W, 3], empty until rendered
  bool full = false;         // depth (and, when screening, colour) rendered at full resolution
  std::optional<bool> fine;  // a reference: whether it passed the plan's fine check, once made
  double valid = 0;          // share of depth's pixels with depth > 0
  double estimate = 0;       // covis estimate at the last screening stage it went through
  double screenValid = 0;    // valid fraction there
  CovisResult covis;         // against view 0, full resolution
  double renderSeconds = 0;  // its full-resolution renders
  int renders = 0;
};

// The state of one generate() call: its random stream and what it has spent.
struct PairGenerator::Search {
  Rng rng;
  GenerationCost cost;
};

PairGenerator::PairGenerator(const Scene& scene, const RayCaster& caster,
                             const ViewpointSampler& sampler, const PairOptions& options)
    : scene_(scene),
      caster_(caster),
      sampler_(sampler),
      options_(options),
      intrinsics_(Camera::fromHfov(options.resolution, options.resolution, options.hfov)) {
  options.validate();
  options_.screenResolution = screenResolution(options);
  plan_ = screenPlan(options_);
  for (const ScreenPlan::Stage& stage : plan_.stages) {
    const double validMargin = stage.validOnly           ? options_.screenGlanceValidMargin
                               : stage.side >= kFineSide ? options_.screenFineValidMargin
                                                         : options_.screenValidMargin;
    screens_.push_back({Camera::fromHfov(stage.side, stage.side, options.hfov), stage.margin,
                        validMargin, stage.validOnly, stageCovisOptions(stage.side, options_)});
  }
  if (!plan_.reference.empty()) pointsStage_ = plan_.reference.back();
}

std::optional<PairSample> PairGenerator::generate(uint64_t seed, uint64_t index,
                                                  GenerationCost* spent) const {
  const auto start = Clock::now();
  Search search{Rng(mixSeed(seed, scene_.name, index)), {}};
  search.cost.candidateFunnel.resize(screens_.empty() ? 0 : screens_.size() + kFirstStageSlot);
  search.cost.referenceFunnel.resize(plan_.reference.size() + (plan_.referenceFine ? 1 : 0));
  std::optional<PairSample> found;
  PairSample sample;
  if (makeSample(search, sample)) {
    sample.scene = scene_.name;
    sample.index = index;
    sample.seed = seed;
    found = std::move(sample);
  }
  search.cost.totalSeconds = since(start);
  if (spent) *spent = std::move(search.cost);
  return found;
}

// References until one finds its partners: a reference, then each further view in turn.
bool PairGenerator::makeSample(Search& search, PairSample& sample) const {
  GenerationCost& cost = search.cost;
  std::vector<View> views;
  views.reserve(options_.views);
  for (int ref = 0; ref < options_.maxReferences; ++ref) {
    views.clear();
    std::optional<View> first = referenceView(search);
    if (!first) continue;
    const Eigen::Vector3d target = referenceTarget(*first);
    views.push_back(std::move(*first));
    while (static_cast<int>(views.size()) < options_.views) {
      std::optional<View> other = otherView(views[0], target, search);
      if (!other) break;
      views.push_back(std::move(*other));
    }
    const bool complete = static_cast<int>(views.size()) == options_.views;
    if (complete && referenceIsValid(views[0], search)) {
      finish(views, sample, cost);
      for (const View& v : views) {  // the renders that end in the sample; the rest were wasted
        cost.keptRenderSeconds += v.renderSeconds;
        cost.keptRenders += v.renders;
      }
      sample.candidateCovis = cost.candidateCovis;
      return true;
    }
    cost.wastedReferenceRenders += views[0].renders;
    for (size_t k = 1; k < views.size(); ++k) cost.wastedCandidateRenders += views[k].renders;
  }
  return false;
}

// A reference pose and, with screening, its low-resolution checks; without, its full depth.
std::optional<PairGenerator::View> PairGenerator::referenceView(Search& search) const {
  View v;
  v.at = sampler_.sampleReference(intrinsics_, search.rng);
  if (!screens_.empty()) {
    // A reference needs a valid pixel for its target, even with --min-valid 0.
    if (!screenReference(v, search.cost) || v.screenValid == 0) return std::nullopt;
    // Below the bound there, a reference takes its fine check now, before any candidate is drawn:
    // such references rarely find a partner (on simple_room 2 of 380 did), and their candidates
    // were a sixth of all. Above the bound, most pass, so it waits until a partner passes
    // screening.
    if (v.screenValid < options_.minValidFraction && !referenceIsFine(v, search.cost))
      return std::nullopt;
    return v;
  }
  renderFull(v, false, search.cost);
  v.full = true;
  v.valid = validFraction(v.depth);
  if (v.valid >= options_.minValidFraction && v.valid > 0) return v;
  search.cost.wastedReferenceRenders += v.renders;
  return std::nullopt;
}

// The point the further views look at (CroCo's mean observed point): from the full depth without
// screening, else from the stage the reference's points come from, so that no full render is
// spent on a reference before a partner has passed screening.
Eigen::Vector3d PairGenerator::referenceTarget(const View& ref) const {
  if (ref.full) return meanWorldPoint(ref.at.camera, ref.depth);
  return meanWorldPoint(stageCamera(pointsStage_, ref), ref.screenDepth[pointsStage_]);
}

// Candidates for one further view, drawn a batch at a time and screened, until one passes the
// full-resolution test, the attempts run out, or the reference is given up.
std::optional<PairGenerator::View> PairGenerator::otherView(View& ref,
                                                            const Eigen::Vector3d& target,
                                                            Search& search) const {
  const int batchSize = screens_.empty() ? 1 : options_.screenBatch;
  int misses = 0;  // candidates in a row turned down in screenFirstStage (no render beyond 8x8)
  std::vector<bool> out;
  for (int attempt = 0; attempt < options_.maxAttempts;) {
    const int n = std::min(batchSize, options_.maxAttempts - attempt);
    attempt += n;
    std::vector<View> batch = drawCandidates(ref, target, n, search);
    out.assign(n, false);
    if (!screens_.empty()) screenFirstStage(ref, batch, out, search);
    for (int k = 0; k < n; ++k) {
      if (out[k]) {
        if (options_.giveUpAfter > 0 && ++misses >= options_.giveUpAfter) {
          ++search.cost.referencesGivenUp;
          return std::nullopt;
        }
        continue;
      }
      misses = 0;
      if (!screens_.empty() && !screenLaterStages(ref, batch[k], search)) continue;
      if (!referenceIsValid(ref, search)) return std::nullopt;
      if (passesFull(ref, batch[k], search)) return std::move(batch[k]);
    }
  }
  return std::nullopt;
}

std::vector<PairGenerator::View> PairGenerator::drawCandidates(const View& ref,
                                                               const Eigen::Vector3d& target,
                                                               int count, Search& search) const {
  std::vector<View> batch(count);
  for (View& v : batch) v.at = sampler_.sampleOther(intrinsics_, ref.at, target, search.rng);
  return batch;
}

// Runs one screening test of view v, counted (and timed) in `stage` of the funnel, and audited
// when it turns v down; whether it did.
template <typename Test>
bool PairGenerator::funnelTest(FunnelStage& stage, const View* ref, const View& v,
                               GenerationCost& cost, const Test& test) const {
  const auto t0 = Clock::now();
  ++stage.entered;
  const bool out = test();
  stage.seconds += since(t0);
  if (!out) return false;
  ++stage.rejected;
  ++cost.screened;
  stage.falseRejections += audit(ref, v, cost);
  return true;
}

// The in-frame bound and the sight lines of every candidate of the batch, then the candidates'
// first stage (the glance) for those they leave, their depth maps rendered in one pass; out[k]
// says which were turned down.
void PairGenerator::screenFirstStage(const View& ref, std::vector<View>& batch,
                                     std::vector<bool>& out, Search& search) const {
  GenerationCost& cost = search.cost;
  std::vector<FunnelStage>& funnel = cost.candidateFunnel;
  std::vector<size_t> left;
  for (size_t k = 0; k < batch.size(); ++k) {
    const View& v = batch[k];
    out[k] =
        (frameBound() &&
         funnelTest(funnel[kBoundSlot], &ref, v, cost, [&] { return outOfFrame(ref, v, cost); })) ||
        funnelTest(funnel[kSightSlot], &ref, v, cost, [&] { return outOfSight(ref, v, cost); });
    if (!out[k]) left.push_back(k);
  }
  const size_t stage = plan_.candidate.front();
  renderStageBatch(stage, batch, left, funnel[kFirstStageSlot + stage], cost);
  for (size_t k : left) {
    View& v = batch[k];
    out[k] = funnelTest(funnel[kFirstStageSlot + stage], &ref, v, cost, [&] {
      return screens_[stage].validOnly ? failsGlance(ref, v, cost)
                                       : failsStage(stage, &ref, v, cost);
    });
  }
}

// A candidate's glance: too few valid pixels in its 8x8 map, or too few of them seen by the
// reference (tested against the depth its points come from, with that stage's tolerances): that
// share estimates v_ji, and covis <= v_ji.
bool PairGenerator::failsGlance(const View& ref, View& v, GenerationCost& cost) const {
  if (failsStage(0, nullptr, v, cost)) return true;
  if (options_.accept) return false;
  const size_t points = pointsStage_;
  const auto t0 = Clock::now();
  const double seen = visibleFraction(stageCamera(0, v), v.screenDepth[0], stageCamera(points, ref),
                                      ref.screenDepth[points], screens_[points].covis);
  cost.screenSeconds += since(t0);
  if (seen >= options_.minCovis - options_.screenGlanceCovisMargin) return false;
  cost.candidateCovis.push_back(static_cast<float>(seen));
  return true;
}

// The depth maps of batch[which] at the stage, in one pass; its time counts in `funnel`.
void PairGenerator::renderStageBatch(size_t stage, std::vector<View>& batch,
                                     const std::vector<size_t>& which, FunnelStage& funnel,
                                     GenerationCost& cost) const {
  std::vector<Camera> cameras;
  for (size_t k : which) cameras.push_back(stageCamera(stage, batch[k]));
  std::vector<ImageF> depths(which.size());
  const auto t0 = Clock::now();
  caster_.renderDepthBatch(cameras.data(), depths.data(), which.size());
  const double seconds = since(t0);
  cost.screenSeconds += seconds;
  funnel.seconds += seconds;
  for (size_t i = 0; i < which.size(); ++i) {
    View& v = batch[which[i]];
    v.screenDepth.resize(screens_.size());
    v.screenDepth[stage] = std::move(depths[i]);
  }
}

// The finer stages, then the confirm stage, each while the estimate before it may go either way
// (PairOptions::screenSkipClear; the confirm stage always); whether v passed.
bool PairGenerator::screenLaterStages(const View& ref, View& v, Search& search) const {
  GenerationCost& cost = search.cost;
  for (size_t k = 1; k < plan_.candidate.size(); ++k) {
    const size_t stage = plan_.candidate[k], before = plan_.candidate[k - 1];
    const bool clear = !screens_[before].validOnly && !ambiguous(before, v);
    if (clear && (stage == plan_.regular || options_.screenSkipClear)) break;
    if (funnelTest(cost.candidateFunnel[kFirstStageSlot + stage], &ref, v, cost,
                   [&] { return failsStage(stage, &ref, v, cost); }))
      return false;
  }
  return true;
}

// Renders v in full (colour too, as it is likely kept) and judges it as without screening.
bool PairGenerator::passesFull(View& ref, View& v, Search& search) const {
  GenerationCost& cost = search.cost;
  renderFull(v, !screens_.empty(), cost);
  v.full = true;
  v.valid = validFraction(v.depth);
  if (v.valid >= options_.minValidFraction) {
    const auto t0 = Clock::now();
    v.covis = computeCovisibility(ref.at.camera, ref.depth, v.at.camera, v.depth, options_.covis);
    cost.covisSeconds += since(t0);
    cost.candidateCovis.push_back(static_cast<float>(v.covis.covis));
    if (inBand(v.covis.covis)) return true;
  }
  cost.wastedCandidateRenders += v.renders;
  return false;
}

// Renders the reference in full when a first candidate has passed screening; whether it has
// enough valid pixels there.
bool PairGenerator::referenceIsValid(View& ref, Search& search) const {
  if (!ref.full) {
    if (!referenceIsFine(ref, search.cost)) return false;
    renderFull(ref, !screens_.empty(), search.cost);
    ref.full = true;
    ref.valid = validFraction(ref.depth);
  }
  return ref.valid >= options_.minValidFraction;
}

// The plan's fine check of a reference whose last stage left its valid pixels near the bound
// (the finest stage, rendered unless a candidate needed it already); whether it passed.
bool PairGenerator::referenceIsFine(View& ref, GenerationCost& cost) const {
  if (!plan_.referenceFine) return true;
  if (!ref.fine) {
    const double validEdge = options_.minValidFraction + screens_[pointsStage_].validMargin;
    const size_t stage = *plan_.referenceFine;
    ref.fine = ref.screenValid >= validEdge ||
               !funnelTest(cost.referenceFunnel[plan_.reference.size()], nullptr, ref, cost,
                           [&] { return failsStage(stage, nullptr, ref, cost); });
  }
  return *ref.fine;
}

bool PairGenerator::inBand(double covis) const {
  return options_.accept ? options_.accept(covis)
                         : covis >= options_.minCovis && covis <= options_.maxCovis;
}

// A reference's low-resolution stages (valid pixels only); whether it passed. Only the stage its
// points come from keeps a depth map: the others count its valid pixels.
bool PairGenerator::screenReference(View& v, GenerationCost& cost) const {
  for (size_t k = 0; k < plan_.reference.size(); ++k) {
    const size_t stage = plan_.reference[k];
    if (funnelTest(cost.referenceFunnel[k], nullptr, v, cost, [&] {
          return stage == pointsStage_ ? failsStage(stage, nullptr, v, cost)
                                       : tooFewValid(stage, v, cost);
        }))
      return false;
  }
  return true;
}

// Whether v has too few valid pixels at the stage, as failsStage judges it, with its pixels cast
// only until the verdict is known and no depth map kept (a stage that needs it later renders
// it). Most references that fail the glance (93 % on an open room) look over the walls, so their
// top rows decide it at half the rays.
bool PairGenerator::tooFewValid(size_t stage, const View& v, GenerationCost& cost) const {
  const Camera camera = stageCamera(stage, v);
  const auto t0 = Clock::now();
  const bool enough = caster_.hitsAtLeast(
      camera, fewestToPass(options_.minValidFraction - screens_[stage].validMargin,
                           static_cast<long>(camera.width) * camera.height));
  cost.screenSeconds += since(t0);
  return !enough;
}

// Whether a stage's estimates of v (covis, valid fraction) lie within its margins of a bound, so
// that a finer stage should decide.
bool PairGenerator::ambiguous(size_t stage, const View& v) const {
  const ScreenStage& s = screens_[stage];
  const double validEdge = options_.minValidFraction + s.validMargin;
  if (v.screenValid < validEdge) return true;
  if (options_.accept) return false;
  const double m = s.covisMargin;
  return v.estimate < options_.minCovis + m || v.estimate > options_.maxCovis - m;
}

// With the audit on, renders a turned-down view at full resolution and counts it when the full
// test would have kept it. Changes no state of the search and no cost but falseRejections.
bool PairGenerator::audit(const View* ref, const View& v, GenerationCost& cost) const {
  if (!options_.auditScreening) return false;
  ImageF depth;
  caster_.renderDepth(v.at.camera, depth);
  bool kept = validFraction(depth) >= options_.minValidFraction;
  if (kept && ref) {
    const ImageF* refDepth = &ref->depth;
    if (!ref->full) {
      if (ref->auditDepth.data.empty()) caster_.renderDepth(ref->at.camera, ref->auditDepth);
      refDepth = &ref->auditDepth;
    }
    kept = validFraction(*refDepth) >= options_.minValidFraction &&
           inBand(computeCovisibility(ref->at.camera, *refDepth, v.at.camera, depth, options_.covis)
                      .covis);
  }
  cost.falseRejections += kept;
  return kept;
}

// Whether too little of the reference lands inside v's frame for v to pass: no rendering of v,
// the reference's points (the depth of its last stage) projected into v's camera, occlusion
// left out. Called only when frameBound().
bool PairGenerator::outOfFrame(const View& ref, const View& v, GenerationCost& cost) const {
  const size_t points = pointsStage_;
  CovisOptions o = options_.covis;
  o.stride = std::max(1, screens_[points].intrinsics.width / kFrameScreenSide);
  const auto t0 = Clock::now();
  const double bound =
      inFrameFraction(stageCamera(points, ref), ref.screenDepth[points], v.at.camera, o);
  cost.screenSeconds += since(t0);
  if (bound >= options_.minCovis - options_.screenFrameMargin) return false;
  cost.candidateCovis.push_back(static_cast<float>(bound));
  return true;
}

// Whether the in-frame bound is on: with screening, a band and a margin that leaves a bound above
// 0 (PairOptions::screenFrameMargin).
bool PairGenerator::frameBound() const {
  return !options_.accept && !screens_.empty() && options_.minCovis > options_.screenFrameMargin;
}

// Whether v sees too few of the reference's sight-line points to pass: each point must lie in v's
// frame, in front of it, with nothing between it and v's eye (a shadow ray). Its share estimates
// v_ij, an upper bound of covis, from a few dozen rays and no rendering of v.
bool PairGenerator::outOfSight(const View& ref, const View& v, GenerationCost& cost) const {
  if (options_.accept || screens_.empty() || options_.screenSightSide <= 0) return false;
  const auto t0 = Clock::now();
  const std::vector<Eigen::Vector3f>& points = sightPoints(ref);
  const Camera& c = v.at.camera;
  const Eigen::Matrix3f worldToCamera = c.R_cam2world.transpose().cast<float>();
  const Eigen::Matrix3f K = c.K.cast<float>();
  const Eigen::Vector3f eye = c.t_cam2world.cast<float>();
  std::vector<Ray> rays;
  rays.reserve(points.size());
  for (const Eigen::Vector3f& p : points) {
    const Eigen::Vector3f q = K * (worldToCamera * (p - eye));
    if (!(q.z() > 0)) continue;
    const float u = q.x() / q.z(), w = q.y() / q.z();
    if (!(u >= 0 && u < c.width && w >= 0 && w < c.height)) continue;
    const float length = (p - eye).norm();
    rays.push_back({eye, p - eye, 0.0f, 1.0f - std::max(kSightRelTol, kSightAbsTol / length)});
  }
  // A packet of rays at a time, until enough are seen to pass: a candidate that passes needs no
  // exact share, one that is turned down casts them all (its share is recorded).
  const double needed = options_.minCovis - options_.screenSightMargin;
  const size_t enough = points.empty() ? (needed <= 0 ? 0 : 1)
                                       : static_cast<size_t>(fewestToPass(needed, points.size()));
  size_t seen = 0;
  uint8_t blocked[kSightPacket];
  for (size_t k0 = 0; k0 < rays.size() && seen < enough; k0 += kSightPacket) {
    const size_t n = std::min(kSightPacket, rays.size() - k0);
    caster_.occluded(rays.data() + k0, blocked, n);
    seen += n - std::count(blocked, blocked + n, uint8_t{1});
  }
  const double share = points.empty() ? 0.0 : static_cast<double>(seen) / points.size();
  cost.screenSeconds += since(t0);
  if (seen >= enough) return false;
  cost.candidateCovis.push_back(static_cast<float>(share));
  return true;
}

// The reference's valid pixels on a screenSightSide^2 grid of its points' depth, as world
// points.
const std::vector<Eigen::Vector3f>& PairGenerator::sightPoints(const View& ref) const {
  if (ref.sightPointsMade) return ref.sightPoints;
  ref.sightPointsMade = true;
  const Camera cam = stageCamera(pointsStage_, ref);
  const ImageF& depth = ref.screenDepth[pointsStage_];
  const int side = std::min(options_.screenSightSide, depth.width);
  for (int gy = 0; gy < side; ++gy) {
    for (int gx = 0; gx < side; ++gx) {
      const int x = (2 * gx + 1) * depth.width / (2 * side);
      const int y = (2 * gy + 1) * depth.height / (2 * side);
      const float d = depth.data[static_cast<size_t>(y) * depth.width + x];
      if (!(d > 0)) continue;
      const Eigen::Vector3d pc = d * cam.rayCamera(x + 0.5, y + 0.5);
      ref.sightPoints.push_back((cam.R_cam2world * pc + cam.t_cam2world).cast<float>());
    }
  }
  return ref.sightPoints;
}

// The covis estimate of v against the reference at the stage's resolution, with the stage's
// tolerances (lower) or covis' own (upper).
double PairGenerator::stageEstimate(size_t stage, const View& ref, const View& v, bool upper,
                                    GenerationCost& cost) const {
  renderStage(stage, ref, cost);
  const auto t0 = Clock::now();
  const double estimate =
      computeCovisibility(stageCamera(stage, ref), ref.screenDepth[stage], stageCamera(stage, v),
                          v.screenDepth[stage], upper ? options_.covis : screens_[stage].covis)
          .covis;
  cost.screenSeconds += since(t0);
  return estimate;
}

// Renders v's depth at the stage's resolution (unless it has it) and says whether it cannot
// pass: too few valid pixels, or (with a reference) a covis estimate outside the band by more
// than the stage's margin.
bool PairGenerator::failsStage(size_t stage, const View* ref, View& v, GenerationCost& cost) const {
  const ScreenStage& screen = screens_[stage];
  renderStage(stage, v, cost);
  v.screenValid = validFraction(v.screenDepth[stage]);
  if (v.screenValid < options_.minValidFraction - screen.validMargin) return true;
  if (!ref || options_.accept || screen.validOnly) return false;
  v.estimate = stageEstimate(stage, *ref, v, false, cost);
  bool out = v.estimate < options_.minCovis - screen.covisMargin;
  // The upper bound, when it can be passed: an estimate with the plain tolerances, which falls
  // below covis rather than above it.
  if (!out && options_.maxCovis + screen.covisMargin < 1.0) {
    const double plain = stageEstimate(stage, *ref, v, true, cost);
    out = plain > options_.maxCovis + screen.covisMargin;
    if (out) v.estimate = plain;
  }
  if (out) cost.candidateCovis.push_back(static_cast<float>(v.estimate));
  return out;
}

// v's camera at the stage's resolution.
Camera PairGenerator::stageCamera(size_t stage, const View& v) const {
  Camera cam = screens_[stage].intrinsics;
  cam.R_cam2world = v.at.camera.R_cam2world;
  cam.t_cam2world = v.at.camera.t_cam2world;
  return cam;
}

// Renders v's depth at the stage's resolution unless it has it already.
void PairGenerator::renderStage(size_t stage, const View& v, GenerationCost& cost) const {
  v.screenDepth.resize(screens_.size());
  if (!v.screenDepth[stage].data.empty()) return;
  const auto t0 = Clock::now();
  caster_.renderDepth(stageCamera(stage, v), v.screenDepth[stage]);
  cost.screenSeconds += since(t0);
}

void PairGenerator::renderFull(View& v, bool rgb, GenerationCost& cost) const {
  const auto t0 = Clock::now();
  if (rgb) {
    RenderOptions ro = options_.render;
    ro.rgb = true;
    ro.normals = false;
    ro.ids = false;
    Frame frame;
    caster_.render(v.at.camera, ro, frame);
    v.depth = std::move(frame.depth);
    v.rgb = std::move(frame.rgb);
  } else {
    caster_.renderDepth(v.at.camera, v.depth);
  }
  const double seconds = since(t0);
  cost.renderSeconds += seconds;
  ++cost.fullRenders;
  v.renderSeconds += seconds;
  ++v.renders;
}

// Colour for views rendered depth-first, the visibility matrix, the masks, then the views move
// into the sample.
void PairGenerator::finish(std::vector<View>& views, PairSample& s, GenerationCost& cost) const {
  const int V = static_cast<int>(views.size());
  for (View& v : views) {
    if (!v.rgb.data.empty()) continue;
    ImageF depth = std::move(v.depth);
    renderFull(v, true, cost);
    v.depth = std::move(depth);
  }
  const auto t0 = Clock::now();
  s.covis.assign(V, CovisResult{});
  s.visibility.assign(V, std::vector<double>(V, 1.0));
  for (int i = 0; i < V; ++i) s.visibility[i][i] = views[i].valid;
  s.covis[0] = {1.0, 1.0, 1.0, s.visibility[0][0], s.visibility[0][0]};
  for (int k = 1; k < V; ++k) {
    s.covis[k] = views[k].covis;
    s.visibility[0][k] = views[k].covis.v_ij;
    s.visibility[k][0] = views[k].covis.v_ji;
  }
  for (int i = 1; i < V; ++i) {
    for (int j = i + 1; j < V; ++j) {
      const CovisResult c = computeCovisibility(views[i].at.camera, views[i].depth,
                                                views[j].at.camera, views[j].depth, options_.covis);
      s.visibility[i][j] = c.v_ij;
      s.visibility[j][i] = c.v_ji;
    }
  }
  if (options_.covisMasks) makeMasks(views, s);
  cost.covisSeconds += since(t0);
  for (View& v : views) {
    s.camera.push_back(v.at.camera);
    s.orientation.push_back(v.at.orientation);
    s.rgb.push_back(std::move(v.rgb));
    s.depth.push_back(options_.keepDepth ? std::move(v.depth) : ImageF());
  }
}

void PairGenerator::makeMasks(const std::vector<View>& views, PairSample& s) const {
  const View& first = views[0];
  s.covisMask.assign(views.size(), Image8());
  Image8 seenFromOthers(first.depth.width, first.depth.height, 1, 0);
  for (size_t k = 1; k < views.size(); ++k) {
    const Camera &c0 = first.at.camera, &ck = views[k].at.camera;
    const Image8 m = visibilityMask(c0, first.depth, ck, views[k].depth, options_.covis);
    for (size_t p = 0; p < m.data.size(); ++p) seenFromOthers.data[p] |= m.data[p];
    s.covisMask[k] = visibilityMask(ck, views[k].depth, c0, first.depth, options_.covis);
  }
  s.covisMask[0] = std::move(seenFromOthers);
}

}  // namespace paircast
