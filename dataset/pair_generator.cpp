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

// outOfFrame projects a kFrameScreenSide^2 grid of the reference's pixels.
constexpr int kFrameScreenSide = 64;

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

int screenResolution(const PairOptions& o) {
  if (o.screenResolution != kAutoScreen) return o.screenResolution;
  return o.resolution >= 64 ? std::max(kMinAutoScreen, o.resolution / kAutoScreenDivisor) : 0;
}

// The margin at `side`: screenCovisMargin at 32, screenFineMargin at 64, and the same ratio per
// doubling beyond (a margin of 0 applies as given).
double stageMargin(int side, const PairOptions& o) {
  const double m32 = o.screenCovisMargin, m64 = o.screenFineMargin;
  if (m32 <= 0 || m64 <= 0) return side < 64 ? m32 : m64;
  return std::min(1.0, m32 * std::pow(m64 / m32, std::log2(side / 32.0)));
}

std::vector<ScreenStageSpec> screenStages(const PairOptions& o) {
  std::vector<ScreenStageSpec> stages;
  for (int side = screenResolution(o); side > 0 && (stages.empty() || 4 * side <= o.resolution);
       side *= 2)
    stages.push_back({side, stageMargin(side, o)});
  return stages;
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
        screenValidMargin >= 0))
    throw OptionError("screen_margin", "screening margins must be in [0, 1]");
}

// One view while a sample is being made.
struct PairGenerator::View {
  Viewpoint at;
  ImageF depth;  // [H, W, 1] full resolution
  // Per screening stage: [S, S, 1]. A reference gets its later stages when a candidate first
  // reaches them (most references never need them), hence mutable.
  mutable std::vector<ImageF> screenDepth;
  Image8 rgb;                // [H, W, 3], empty until rendered
  double valid = 0;          // share of depth's pixels with depth > 0
  CovisResult covis;         // against view 0, full resolution
  double renderSeconds = 0;  // its full-resolution renders
  int renders = 0;
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
  for (const ScreenStageSpec& stage : screenStages(options_))
    screens_.push_back({Camera::fromHfov(stage.side, stage.side, options.hfov), stage.margin});
  // A reference is judged on its valid pixels: the stages up to the first of 32x32 or more.
  for (const ScreenStage& stage : screens_) {
    ++referenceStages_;
    if (stage.intrinsics.width >= 32) break;
  }
}

std::optional<PairSample> PairGenerator::generate(uint64_t seed, uint64_t index,
                                                  GenerationCost* spent) const {
  const auto start = Clock::now();
  Rng rng(mixSeed(seed, scene_.name, index));
  GenerationCost cost;
  std::optional<PairSample> found;
  std::vector<View> views;
  views.reserve(options_.views);
  for (int ref = 0; ref < options_.maxReferences && !found; ++ref) {
    views.clear();
    std::optional<View> first = referenceView(rng, cost);
    if (!first) continue;
    const Eigen::Vector3d target = meanWorldPoint(first->at.camera, first->depth);
    views.push_back(std::move(*first));
    while (static_cast<int>(views.size()) < options_.views) {
      std::optional<View> other = otherView(views[0], target, rng, cost);
      if (!other) break;
      views.push_back(std::move(*other));
    }
    if (static_cast<int>(views.size()) < options_.views) continue;
    found.emplace();
    found->scene = scene_.name;
    found->index = index;
    found->seed = seed;
    finish(views, *found, cost);
    for (const View& v : views) {  // the renders that end in the sample; the rest were wasted
      cost.keptRenderSeconds += v.renderSeconds;
      cost.keptRenders += v.renders;
    }
    found->candidateCovis = cost.candidateCovis;
  }
  cost.totalSeconds = since(start);
  if (spent) *spent = std::move(cost);
  return found;
}

std::optional<PairGenerator::View> PairGenerator::referenceView(Rng& rng,
                                                                GenerationCost& cost) const {
  View v;
  v.at = sampler_.sampleReference(intrinsics_, rng);
  if (screenedOut(nullptr, v, cost)) return std::nullopt;
  renderFull(v, options_.screenResolution > 0, cost);
  v.valid = validFraction(v.depth);
  if (v.valid < options_.minValidFraction) return std::nullopt;
  return v;
}

std::optional<PairGenerator::View> PairGenerator::otherView(const View& ref,
                                                            const Eigen::Vector3d& target, Rng& rng,
                                                            GenerationCost& cost) const {
  for (int attempt = 0; attempt < options_.maxAttempts; ++attempt) {
    View v;
    v.at = sampler_.sampleOther(intrinsics_, ref.at, target, rng);
    if (screenedOut(&ref, v, cost)) continue;
    // A view that passed screening is likely kept: its colour comes in the same pass.
    renderFull(v, options_.screenResolution > 0, cost);
    v.valid = validFraction(v.depth);
    if (v.valid < options_.minValidFraction) continue;
    const auto t0 = Clock::now();
    v.covis = computeCovisibility(ref.at.camera, ref.depth, v.at.camera, v.depth, options_.covis);
    cost.covisSeconds += since(t0);
    cost.candidateCovis.push_back(static_cast<float>(v.covis.covis));
    if (inBand(v.covis.covis)) return v;
  }
  return std::nullopt;
}

bool PairGenerator::inBand(double covis) const {
  return options_.accept ? options_.accept(covis)
                         : covis >= options_.minCovis && covis <= options_.maxCovis;
}

// Screens v coarse to fine and says whether it cannot pass; counts it, and audits the verdict
// when asked.
bool PairGenerator::screenedOut(const View* ref, View& v, GenerationCost& cost) const {
  const size_t stages = ref ? screens_.size() : referenceStages_;
  bool out = ref && outOfFrame(*ref, v, cost);
  for (size_t stage = 0; stage < stages && !out; ++stage) out = failsStage(stage, ref, v, cost);
  if (!out) return false;
  ++cost.screened;
  if (options_.auditScreening) {
    View full = v;
    renderFull(full, false, cost);
    bool kept = validFraction(full.depth) >= options_.minValidFraction;
    if (kept && ref)
      kept = inBand(computeCovisibility(ref->at.camera, ref->depth, full.at.camera, full.depth,
                                        options_.covis)
                        .covis);
    cost.falseRejections += kept;
  }
  return true;
}

// Whether too little of the reference lands inside v's frame for v to pass: no rendering, the
// reference's pixels projected into v's camera, occlusion left out.
bool PairGenerator::outOfFrame(const View& ref, const View& v, GenerationCost& cost) const {
  if (options_.accept || screens_.empty()) return false;
  CovisOptions o = options_.covis;
  o.stride = std::max(1, options_.resolution / kFrameScreenSide);
  const auto t0 = Clock::now();
  const double bound = inFrameFraction(ref.at.camera, ref.depth, v.at.camera, o);
  cost.screenSeconds += since(t0);
  if (bound >= options_.minCovis - options_.screenFrameMargin) return false;
  cost.candidateCovis.push_back(static_cast<float>(bound));
  return true;
}

// Renders v's depth at the stage's resolution and says whether it cannot pass: too few valid
// pixels, or (with a reference) a covis estimate outside the band by more than the margin.
bool PairGenerator::failsStage(size_t stage, const View* ref, View& v, GenerationCost& cost) const {
  const ScreenStage& screen = screens_[stage];
  const Camera cam = screenCamera(stage, v, cost);
  if (validFraction(v.screenDepth[stage]) < options_.minValidFraction - options_.screenValidMargin)
    return true;
  if (!ref || options_.accept) return false;
  const Camera refCam = screenCamera(stage, *ref, cost);
  const auto t0 = Clock::now();
  const double estimate = computeCovisibility(refCam, ref->screenDepth[stage], cam,
                                              v.screenDepth[stage], options_.covis)
                              .covis;
  cost.screenSeconds += since(t0);
  const bool out = estimate < options_.minCovis - screen.covisMargin ||
                   estimate > options_.maxCovis + screen.covisMargin;
  if (out) cost.candidateCovis.push_back(static_cast<float>(estimate));
  return out;
}

// v's camera at the stage's resolution; renders v's depth there unless it has it already.
Camera PairGenerator::screenCamera(size_t stage, const View& v, GenerationCost& cost) const {
  Camera cam = screens_[stage].intrinsics;
  cam.R_cam2world = v.at.camera.R_cam2world;
  cam.t_cam2world = v.at.camera.t_cam2world;
  v.screenDepth.resize(screens_.size());
  if (v.screenDepth[stage].data.empty()) {
    const auto t0 = Clock::now();
    caster_.renderDepth(cam, v.screenDepth[stage]);
    cost.screenSeconds += since(t0);
  }
  return cam;
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
