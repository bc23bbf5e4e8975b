#include "covis/covisibility.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "covis/unproject.h"
#include "render/procedural_scene.h"
#include "render/ray_caster.h"
#include "test_errors.h"
#include "util/error.h"
#include "util/random.h"

namespace paircast {
namespace {

// ---- An analytic scene: axis-aligned rectangles, so depth maps need no renderer ----

// Points X with X[axis] == at and the other two coordinates within [lo, hi] (infinite bounds
// make an unbounded plane).
struct Rect {
  int axis;
  double at;
  Eigen::Vector3d lo, hi;
};

constexpr double kInf = std::numeric_limits<double>::infinity();

Rect plane(int axis, double at) {
  return {axis, at, Eigen::Vector3d::Constant(-kInf), Eigen::Vector3d::Constant(kInf)};
}

// The six faces of a box.
void addBoxFaces(std::vector<Rect>& scene, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  for (int a = 0; a < 3; ++a) {
    scene.push_back({a, lo[a], lo, hi});
    scene.push_back({a, hi[a], lo, hi});
  }
}

// Z-depth of the nearest rectangle through each pixel centre, in double; 0 on a miss.
ImageF analyticDepth(const Camera& c, const std::vector<Rect>& scene) {
  ImageF depth(c.width, c.height, 1, 0.0f);
  const Eigen::Vector3d o = c.t_cam2world;
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      // z = 1 in the camera, so the ray parameter is the z-depth.
      const Eigen::Vector3d d = c.R_cam2world * c.rayCamera(u + 0.5, v + 0.5);
      double best = kInf;
      for (const Rect& r : scene) {
        if (d[r.axis] == 0) continue;
        const double t = (r.at - o[r.axis]) / d[r.axis];
        if (!(t > 1e-9 && t < best)) continue;
        const Eigen::Vector3d p = o + t * d;
        bool inside = true;
        for (int a = 0; a < 3; ++a)
          if (a != r.axis) inside = inside && p[a] >= r.lo[a] && p[a] <= r.hi[a];
        if (inside) best = t;
      }
      if (best < kInf) depth.data[static_cast<size_t>(v) * c.width + u] = static_cast<float>(best);
    }
  return depth;
}

Camera cameraAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int width = 64,
                int height = 64, double hfov = 90.0, Eigen::Vector3d up = {0, -1, 0}) {
  Camera c = Camera::fromHfov(width, height, hfov);
  c.lookAt(eye, target, up);  // default: image x = world x, image y = world y for +z views
  return c;
}

// The same definition as ../shared/tools/ref_covis.py, written plainly in double precision.
VisibleCount referenceCount(const Camera& ci, const ImageF& di, const Camera& cj, const ImageF& dj,
                            double absTol, double relTol) {
  VisibleCount c;
  for (int v = 0; v < ci.height; ++v)
    for (int u = 0; u < ci.width; ++u) {
      ++c.total;
      const double z = di.data[static_cast<size_t>(v) * ci.width + u];
      if (!(z > 0) || !std::isfinite(z)) continue;
      ++c.valid;
      const Eigen::Vector3d world = ci.worldFromCamera() * (z * ci.rayCamera(u + 0.5, v + 0.5));
      const Eigen::Vector3d q = cj.cameraFromWorld() * world;
      if (q.z() <= 0) continue;
      const Eigen::Vector2d p = cj.project(q);
      if (!(p.x() >= 0 && p.y() >= 0 && p.x() < cj.width && p.y() < cj.height)) continue;
      const double d = dj.data[static_cast<size_t>(p.y()) * cj.width + static_cast<size_t>(p.x())];
      c.visible += d > 0 && std::abs(q.z() - d) <= absTol + relTol * d;
    }
  return c;
}

// A room with random boxes in it, and camera poses inside the room and outside the boxes.
struct RandomScene {
  std::vector<Rect> rects;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;

  explicit RandomScene(Rng& rng) {
    addBoxFaces(rects, {-4, 0, -4}, {4, 3, 4});
    const int n = 1 + static_cast<int>(rng.below(5));
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector3d c(rng.uniform(-3, 3), rng.uniform(0.3, 2.5), rng.uniform(-3, 3));
      const Eigen::Vector3d h(rng.uniform(0.1, 0.8), rng.uniform(0.1, 0.8), rng.uniform(0.1, 0.8));
      boxes.push_back({c - h, c + h});
      addBoxFaces(rects, c - h, c + h);
    }
  }
  Eigen::Vector3d freePoint(Rng& rng) const {
    for (;;) {
      const Eigen::Vector3d p(rng.uniform(-3.7, 3.7), rng.uniform(0.2, 2.8),
                              rng.uniform(-3.7, 3.7));
      bool free = true;
      for (const auto& [lo, hi] : boxes)
        free = free && ((p - lo).minCoeff() < -0.1 || (hi - p).minCoeff() < -0.1);
      if (free) return p;
    }
  }
  Camera camera(Rng& rng, int width, int height) const {
    const Eigen::Vector3d eye = freePoint(rng);
    Eigen::Vector3d target = freePoint(rng);
    while ((target - eye).norm() < 0.5) target = freePoint(rng);
    return cameraAt(eye, target, width, height, rng.uniform(40, 100), {0, 1, 0});
  }
};

// ---- Hand-computed cases ----

TEST(Covisibility, IdenticalViewsGiveOne) {
  // Any depth map, holes included, seen by the same camera: every valid pixel maps to itself.
  Rng rng(1);
  for (int trial = 0; trial < 50; ++trial) {
    const int w = 16 + static_cast<int>(rng.below(60)), h = 16 + static_cast<int>(rng.below(60));
    Camera c = cameraAt({rng.normal(), rng.normal(), rng.normal()},
                        {rng.normal(), rng.normal(), 5 + rng.normal()}, w, h, rng.uniform(30, 120));
    ImageF d(w, h, 1);
    size_t valid = 0;
    for (float& z : d.data) {
      z = rng.uniform() < 0.2 ? 0.0f : static_cast<float>(rng.uniform(0.1, 50));
      valid += z > 0;
    }
    const CovisResult r = computeCovisibility(c, d, c, d);
    ASSERT_EQ(r.v_ij, valid ? 1.0 : 0.0) << "trial " << trial;
    ASSERT_EQ(r.v_ji, r.v_ij);
    ASSERT_DOUBLE_EQ(r.valid_i, static_cast<double>(valid) / (w * h));
    CovisOptions all;
    all.normalize = CovisOptions::Normalize::All;
    ASSERT_DOUBLE_EQ(computeCovisibility(c, d, c, d, all).covis, r.valid_i);
  }
}

TEST(Covisibility, DisjointViewsGiveZero) {
  // Back to back: each view's points are behind the other camera.
  const Camera a = cameraAt({0, 0, 0}, {0, 0, 1}), b = cameraAt({0, 0, 0}, {0, 0, -1});
  const std::vector<Rect> room = [] {
    std::vector<Rect> r;
    addBoxFaces(r, {-5, -5, -5}, {5, 5, 5});
    return r;
  }();
  const CovisResult r = computeCovisibility(a, analyticDepth(a, room), b, analyticDepth(b, room));
  EXPECT_EQ(r.valid_i, 1.0);
  EXPECT_EQ(r.v_ij, 0.0);
  EXPECT_EQ(r.v_ji, 0.0);
  // Side by side, looking at different walls: in front, but outside each other's frame.
  const Camera c = cameraAt({0, 0, 0}, {1, 0, 0}, 64, 64, 60);
  EXPECT_EQ(computeCovisibility(a, analyticDepth(a, room), c, analyticDepth(c, room)).covis, 0.0);
}

TEST(Covisibility, TranslatedCameraFacingAPlaneMatchesHandComputation) {
  // hfov 90 on 64 px: f = 32. A plane at depth 2; moving the camera 1 m sideways shifts the
  // image by f * 1 / 2 = 16 px, so 48 of 64 columns stay in view: v = 0.75 both ways.
  const Camera a = cameraAt({0, 0, 0}, {0, 0, 1});
  const Camera b = cameraAt({1, 0, 0}, {1, 0, 1});
  const ImageF d(64, 64, 1, 2.0f);
  const CovisResult r = computeCovisibility(a, d, b, d);
  EXPECT_DOUBLE_EQ(r.v_ij, 0.75);
  EXPECT_DOUBLE_EQ(r.v_ji, 0.75);
  EXPECT_DOUBLE_EQ(r.covis, 0.75);
  // The top half sees nothing (sky): normalised by valid pixels the value stays, by all
  // pixels it halves.
  ImageF half = d;
  for (int v = 0; v < 32; ++v)
    for (int u = 0; u < 64; ++u) half.data[v * 64 + u] = 0.0f;
  CovisOptions all;
  all.normalize = CovisOptions::Normalize::All;
  const CovisResult rv = computeCovisibility(a, half, b, half);
  const CovisResult ra = computeCovisibility(a, half, b, half, all);
  EXPECT_DOUBLE_EQ(rv.valid_i, 0.5);
  EXPECT_DOUBLE_EQ(rv.v_ij, 0.75);
  EXPECT_DOUBLE_EQ(ra.valid_i, 0.5);
  EXPECT_DOUBLE_EQ(ra.v_ij, 0.375);
  EXPECT_DOUBLE_EQ(visibleFraction(a, half, b, half, all), 0.375);
}

TEST(Covisibility, OccluderBetweenCamerasMatchesHandComputation) {
  // 100x100, hfov 90: f = 50, principal point 50. Camera i at the origin and j at x = 0.9, both
  // looking along +z at a wall z = 4. Between them, at z = 2, a strip 0.21 <= x <= 0.61,
  // unbounded in y. Every row is the same, so count columns; column u's centre is s = u + 0.5.
  //  - i sees the strip where 2 (s - 50) / 50 is in [0.21, 0.61]: s in [55.25, 65.25], 10 columns.
  //  - j's view of the wall behind the strip, its shadow, is x in [0.9 + 2 (0.21 - 0.9),
  //    0.9 + 2 (0.61 - 0.9)] = [-0.48, 0.32]; i sees it where 4 (s - 50) / 50 is in there:
  //    s in [44, 54], 10 more columns that j cannot see.
  //  - j's frame covers the wall for x >= 0.9 - 4 = -3.1: i's columns with s < 11.25, 11 of them,
  //    lie outside it. The strip, as i sees it, is in j's frame and unoccluded.
  // So v_ij = (100 - 10 - 11) / 100 = 0.79, against 0.89 without the strip.
  const Camera ci = cameraAt({0, 0, 0}, {0, 0, 4}, 100, 100, 90);
  const Camera cj = cameraAt({0.9, 0, 0}, {0.9, 0, 4}, 100, 100, 90);
  std::vector<Rect> scene = {plane(2, 4.0)};
  const CovisResult open =
      computeCovisibility(ci, analyticDepth(ci, scene), cj, analyticDepth(cj, scene));
  EXPECT_DOUBLE_EQ(open.v_ij, 0.89);
  scene.push_back({2, 2.0, {0.21, -kInf, 0}, {0.61, kInf, 0}});
  const ImageF di = analyticDepth(ci, scene), dj = analyticDepth(cj, scene);
  const CovisResult r = computeCovisibility(ci, di, cj, dj);
  EXPECT_DOUBLE_EQ(r.v_ij, 0.79);
  // The same count from the plain double-precision definition.
  const VisibleCount ref = referenceCount(ci, di, cj, dj, 0.03, 0.03);
  EXPECT_EQ(static_cast<double>(ref.visible) / ref.valid, 0.79);
}

TEST(Covisibility, PixelsAreHalfOpenAndLookedUpByFloor) {
  // f = 32 on 64 px, a plane at depth 2: moving the camera by 1/32 m shifts the image by exactly
  // half a pixel, so pixel centres land exactly on pixel borders (all values are exact in
  // binary). A projection at x = k lies in pixel k, and x = 64 is outside the frame.
  const Camera a = cameraAt({0, 0, 0}, {0, 0, 1});
  const ImageF d(64, 64, 1, 2.0f);
  for (const double dx : {1.0 / 32, -1.0 / 32}) {
    const Camera b = cameraAt({dx, 0, 0}, {dx, 0, 1});
    const CovisResult r = computeCovisibility(a, d, b, d);
    // a's centres u + 0.5 land at u + 0.5 -/+ 0.5 in b: all inside for one sign, all but the
    // last column for the other; and b's the other way round.
    EXPECT_DOUBLE_EQ(r.v_ij, dx > 0 ? 1.0 : 63.0 / 64) << dx;
    EXPECT_DOUBLE_EQ(r.v_ji, dx > 0 ? 63.0 / 64 : 1.0) << dx;
  }
  // A shift of 3/4 pixel (dx = 3/64 m): a's column 11 (centre 11.5) lands at x = 10.75 in b, in
  // pixel 10 (floor), whose centre is farther than pixel 11's (which rounding would pick).
  const Camera b = cameraAt({3.0 / 64, 0, 0}, {3.0 / 64, 0, 1});
  ImageF column11(64, 64, 1, 0.0f);
  for (int v = 0; v < 64; ++v) column11.data[v * 64 + 11] = 2.0f;
  for (const int changed : {10, 11}) {
    ImageF db = d;
    for (int v = 0; v < 64; ++v) db.data[v * 64 + changed] = 5.0f;
    EXPECT_EQ(visibleFraction(a, column11, b, db), changed == 10 ? 0.0 : 1.0) << changed;
  }
}

TEST(Covisibility, PointsBehindTheCameraAreNeverVisible) {
  // i looks back at j from 1 m in front of it; i's points lie 1 cm behind j's image plane. The
  // central pixel of an odd-sized i (on the optical axis) projects to j's principal point, where
  // j sees something 1 cm in front: the depth test alone (|-0.01 - 0.01| < 3 cm) would accept it.
  const Camera ci = cameraAt({0, 0, 1}, {0, 0, 0}, 63, 63);
  const Camera cj = cameraAt({0, 0, 0}, {0, 0, 1}, 63, 63);
  const CovisResult r =
      computeCovisibility(ci, ImageF(63, 63, 1, 1.01f), cj, ImageF(63, 63, 1, 0.01f));
  EXPECT_EQ(r.v_ij, 0.0);
}

TEST(Covisibility, ToleranceIsAbsolutePlusRelative) {
  // The same camera; j's depth is i's plus delta. Visible iff delta <= absTol + relTol * d_j.
  const Camera c = cameraAt({0, 0, 0}, {0, 0, 1}, 8, 8);
  CovisOptions o;
  o.absTol = 0.05f;
  o.relTol = 0.01f;
  for (const float z : {0.5f, 2.0f, 10.0f, 40.0f}) {
    const float tol = o.absTol + o.relTol * z;
    for (const float frac : {0.0f, 0.5f, 0.95f, 1.05f, 2.0f}) {
      for (const float sign : {1.0f, -1.0f}) {
        // Solve for dj = z + delta with |delta| = frac * (absTol + relTol * dj).
        const float dj = sign > 0 ? (z + frac * o.absTol) / (1 - frac * o.relTol)
                                  : (z - frac * o.absTol) / (1 + frac * o.relTol);
        ASSERT_NEAR(std::abs(dj - z), frac * (o.absTol + o.relTol * dj), 1e-4f * tol);
        const double v = visibleFraction(c, ImageF(8, 8, 1, z), c, ImageF(8, 8, 1, dj), o);
        EXPECT_EQ(v, frac <= 1.0f ? 1.0 : 0.0) << "z " << z << " frac " << frac << " sign " << sign;
      }
    }
  }
}

TEST(Covisibility, InvalidDepthValuesAreMisses) {
  const Camera c = cameraAt({0, 0, 0}, {0, 0, 1}, 4, 1);
  ImageF d(4, 1, 1, 2.0f);
  d.data = {2.0f, 0.0f, -1.0f, std::numeric_limits<float>::quiet_NaN()};
  ImageF e = d;
  e.data[0] = std::numeric_limits<float>::infinity();
  e.data[1] = 2.0f;
  const CovisResult r = computeCovisibility(c, d, c, e);
  EXPECT_DOUBLE_EQ(r.valid_i, 0.25);
  EXPECT_DOUBLE_EQ(r.valid_j, 0.25);
  EXPECT_EQ(r.v_ij, 0.0);  // its one valid pixel meets inf in j
  EXPECT_EQ(r.v_ji, 0.0);  // and j's meets 0 in i
}

TEST(Covisibility, RejectsBadInput) {
  const Camera c = cameraAt({0, 0, 0}, {0, 0, 1}, 8, 8);
  const ImageF d(8, 8, 1, 1.0f);
  EXPECT_ERROR_CONTAINS(computeCovisibility(c, ImageF(8, 7, 1, 1.0f), c, d),
                        "a depth map of 8x7x1 does not match its camera of 8x8");
  EXPECT_ERROR_CONTAINS(computeCovisibility(c, d, c, ImageF(8, 8, 3, 1.0f)),
                        "a depth map of 8x8x3 does not match its camera of 8x8");
  CovisOptions o;
  o.stride = 0;
  EXPECT_ERROR_CONTAINS(computeCovisibility(c, d, c, d, o), "covis stride must be >= 1, got 0");
  o.stride = 1;
  o.absTol = -1;
  EXPECT_ERROR_CONTAINS(computeCovisibility(c, d, c, d, o), "covis tolerances must be >= 0");
  EXPECT_EQ(parseCovisNormalize("all"), CovisOptions::Normalize::All);
  EXPECT_EQ(parseCovisNormalize("valid"), CovisOptions::Normalize::Valid);
  EXPECT_ERROR_CONTAINS(parseCovisNormalize("some"),
                        "covis normalisation must be 'valid' or 'all', got 'some'");
}

// ---- Properties over many seeded random cases ----

TEST(Covisibility, PlaneSeenFromRandomPosesMatchesGeometry) {
  // A floor y = 0 seen from above, both frames entirely on it. Nothing occludes, so a pixel of
  // i is visible in j exactly when its point lands inside j's frame, computed here in double
  // from the plane, not from depth maps. Float rounding may flip points within ~1e-4 px of
  // j's border.
  Rng rng(7);
  int tested = 0;
  std::vector<double> values;
  for (int trial = 0; tested < 100 && trial < 2000; ++trial) {
    auto pose = [&](int w, int h) {
      const Eigen::Vector3d eye(rng.uniform(-1, 1), rng.uniform(1, 4), rng.uniform(-1, 1));
      const Eigen::Vector3d target(rng.uniform(-2, 2), 0, rng.uniform(-2, 2));
      return cameraAt(eye, target, w, h, rng.uniform(40, 90), {0, 0, 1});
    };
    const Camera ci = pose(48, 40), cj = pose(40, 56);
    const std::vector<Rect> floor = {plane(1, 0.0)};
    const ImageF di = analyticDepth(ci, floor), dj = analyticDepth(cj, floor);
    if (countValidDepth(di) != di.data.size() || countValidDepth(dj) != dj.data.size()) continue;
    // Grazing views make the half-pixel lookup error exceed any fixed tolerance; the
    // tolerance is not what this test is about.
    CovisOptions o;
    o.relTol = 0.2f;
    size_t inFrame = 0;
    for (int v = 0; v < ci.height; ++v)
      for (int u = 0; u < ci.width; ++u) {
        const Eigen::Vector3d d = ci.R_cam2world * ci.rayCamera(u + 0.5, v + 0.5);
        const Eigen::Vector3d p = ci.t_cam2world - ci.t_cam2world.y() / d.y() * d;  // on y = 0
        const Eigen::Vector3d q = cj.cameraFromWorld() * p;
        const Eigen::Vector2d x = cj.project(q);
        inFrame += q.z() > 0 && x.x() >= 0 && x.y() >= 0 && x.x() < cj.width && x.y() < cj.height;
      }
    const VisibleCount c = countVisible(ci, di, cj, dj, o);
    ASSERT_EQ(c.valid, di.data.size());
    EXPECT_NEAR(static_cast<double>(c.visible), static_cast<double>(inFrame), 2.0)
        << "trial " << trial;
    values.push_back(static_cast<double>(c.visible) / c.valid);
    ++tested;
  }
  ASSERT_EQ(tested, 100);
  // The cases must cover the range, or the test proves little.
  EXPECT_LT(*std::min_element(values.begin(), values.end()), 0.2);
  EXPECT_GT(*std::max_element(values.begin(), values.end()), 0.8);
}

TEST(Covisibility, MatchesPlainDefinitionOnRandomScenes) {
  // Random rooms with boxes, random poses, different sizes and fields of view: our float
  // kernel against referenceCount in double. Rounding can flip a pixel that projects within
  // ~1e-4 px of a pixel border or whose depth error sits at the tolerance.
  Rng rng(11);
  size_t total = 0, differing = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const RandomScene scene(rng);
    const Camera ci = scene.camera(rng, 48, 40), cj = scene.camera(rng, 56, 44);
    const ImageF di = analyticDepth(ci, scene.rects), dj = analyticDepth(cj, scene.rects);
    const VisibleCount ours = countVisible(ci, di, cj, dj);
    const VisibleCount ref = referenceCount(ci, di, cj, dj, 0.03, 0.03);
    ASSERT_EQ(ours.valid, ref.valid);
    ASSERT_EQ(ours.total, ref.total);
    const size_t diff =
        ours.visible > ref.visible ? ours.visible - ref.visible : ref.visible - ours.visible;
    EXPECT_LE(diff, 2u) << "trial " << trial;
    differing += diff;
    total += ref.valid;
  }
  EXPECT_LE(differing, total / 2000);
}

TEST(Covisibility, InFrameFractionBoundsVisibilityFromAbove) {
  // Hand case: of i's 100 columns, 11 fall outside j's frame (see the occluder case above), so
  // the bound is 0.89 whatever occludes; random scenes: never below v_ij, and equal to it
  // without occluders between the views' surfaces.
  const Camera ci = cameraAt({0, 0, 0}, {0, 0, 4}, 100, 100, 90);
  const Camera cj = cameraAt({0.9, 0, 0}, {0.9, 0, 4}, 100, 100, 90);
  std::vector<Rect> scene = {plane(2, 4.0), {2, 2.0, {0.21, -kInf, 0}, {0.61, kInf, 0}}};
  EXPECT_DOUBLE_EQ(inFrameFraction(ci, analyticDepth(ci, scene), cj), 0.89);
  const Camera away = cameraAt({0, 0, 0}, {0, 0, -4}, 100, 100, 90);
  EXPECT_EQ(inFrameFraction(ci, analyticDepth(ci, scene), away), 0.0);
  Rng rng(12);
  int tighter = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const RandomScene room(rng);
    const Camera a = room.camera(rng, 48, 40), b = room.camera(rng, 56, 44);
    const ImageF da = analyticDepth(a, room.rects), db = analyticDepth(b, room.rects);
    const double bound = inFrameFraction(a, da, b), v = visibleFraction(a, da, b, db);
    EXPECT_GE(bound, v) << "trial " << trial;
    tighter += bound > v;
  }
  EXPECT_GT(tighter, 0) << "occlusion never mattered: the bound is not tested";
  CovisOptions bad;
  bad.stride = 0;
  EXPECT_ERROR_CONTAINS(inFrameFraction(ci, analyticDepth(ci, scene), cj, bad),
                        "covis stride must be >= 1, got 0");
}

TEST(Covisibility, SwappingViewsSwapsTheDirections) {
  Rng rng(9);
  int partial = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const RandomScene scene(rng);
    const Camera a = scene.camera(rng, 40, 32), b = scene.camera(rng, 48, 48);
    const ImageF da = analyticDepth(a, scene.rects), db = analyticDepth(b, scene.rects);
    for (const auto normalize : {CovisOptions::Normalize::Valid, CovisOptions::Normalize::All}) {
      CovisOptions o;
      o.normalize = normalize;
      const CovisResult ab = computeCovisibility(a, da, b, db, o);
      const CovisResult ba = computeCovisibility(b, db, a, da, o);
      ASSERT_EQ(ab.v_ij, ba.v_ji);
      ASSERT_EQ(ab.v_ji, ba.v_ij);
      ASSERT_EQ(ab.covis, ba.covis);
      ASSERT_EQ(ab.valid_i, ba.valid_j);
      ASSERT_EQ(ab.covis, std::min(ab.v_ij, ab.v_ji));
      ASSERT_GE(ab.covis, 0.0);
      ASSERT_LE(std::max(ab.v_ij, ab.v_ji), 1.0);
      ASSERT_EQ(ab.v_ij, visibleFraction(a, da, b, db, o));
      partial += ab.covis > 0.05 && ab.covis < 0.95;
    }
  }
  EXPECT_GT(partial, 20);  // the cases are not all trivial
}

TEST(Covisibility, StrideEstimatesTheFullValue) {
  Rng rng(5);
  for (int trial = 0; trial < 30; ++trial) {
    const RandomScene scene(rng);
    const Camera a = scene.camera(rng, 96, 80), b = scene.camera(rng, 96, 80);
    const ImageF da = analyticDepth(a, scene.rects), db = analyticDepth(b, scene.rects);
    const CovisResult full = computeCovisibility(a, da, b, db);
    for (const int stride : {2, 3, 4}) {
      CovisOptions o;
      o.stride = stride;
      const VisibleCount c = countVisible(a, da, b, db, o);
      const size_t nu = (96 + stride - 1) / stride, nv = (80 + stride - 1) / stride;
      ASSERT_EQ(c.total, nu * nv);
      const CovisResult r = computeCovisibility(a, da, b, db, o);
      EXPECT_NEAR(r.v_ij, full.v_ij, 0.04) << "trial " << trial << " stride " << stride;
      EXPECT_NEAR(r.v_ji, full.v_ji, 0.04) << "trial " << trial << " stride " << stride;
    }
  }
}

// ---- Against the renderer ----

TEST(Covisibility, OccluderMatchesExactVisibilityFromShadowRays) {
  // A wall and a box floating between the cameras, rendered. The exact v_ij: the fraction of
  // view i's surface points that view j sees unobstructed and inside its frame, found with
  // shadow rays. Depth reprojection must agree within the edge pixels.
  Mesh m;
  const int mat = m.addMaterial(Material{});
  addBox(m, {-20, -20, 4}, {20, 20, 4.2f}, mat);
  addBox(m, {-0.4f, -0.4f, 1.8f}, {0.3f, 0.4f, 2.2f}, mat);
  RayCaster caster(m);
  const Camera ci = cameraAt({0, 0, 0}, {0, 0, 4}, 96, 96, 70);
  const Camera cj = cameraAt({1.2, 0.1, 0.3}, {0, 0, 4}, 96, 96, 70);
  ImageF di, dj;
  caster.renderDepth(ci, di);
  caster.renderDepth(cj, dj);
  const CovisResult r = computeCovisibility(ci, di, cj, dj);

  size_t valid = 0, visible = 0;
  std::vector<Ray> rays;
  for (int v = 0; v < 96; ++v)
    for (int u = 0; u < 96; ++u) {
      const float z = di.data[v * 96 + u];
      if (z <= 0) continue;
      ++valid;
      const Eigen::Vector3d p = ci.worldFromCamera() * (z * ci.rayCamera(u + 0.5, v + 0.5));
      const Eigen::Vector3d q = cj.cameraFromWorld() * p;
      if (q.z() <= 0) continue;
      const Eigen::Vector2d px = cj.project(q);
      if (px.x() < 0 || px.y() < 0 || px.x() >= 96 || px.y() >= 96) continue;
      const Eigen::Vector3d toCam = cj.t_cam2world - p;
      rays.push_back(Ray{p.cast<float>(), toCam.cast<float>(), 1e-4f, 1.0f - 1e-4f});
    }
  std::vector<Hit> hits(rays.size());
  caster.intersect(rays.data(), hits.data(), rays.size());
  for (const Hit& h : hits) visible += h.triangle < 0;
  const double exact = static_cast<double>(visible) / valid;
  EXPECT_LT(exact, 0.95) << "the occluder should hide part of view i";
  EXPECT_NEAR(r.v_ij, exact, 0.02);
}

}  // namespace
}  // namespace paircast
