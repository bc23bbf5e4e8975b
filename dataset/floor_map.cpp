#include "dataset/floor_map.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "util/error.h"

namespace paircast {
namespace {

constexpr int kMaxLayers = 16;  // floor candidates per column (storeys, furniture)

struct Candidate {
  int cell;
  Eigen::Vector3f point;
  float headroom;  // distance to the first surface above; inf when none
};

int findRoot(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

// The up axis and two horizontal axes, (a, b, up) right-handed.
struct Axes {
  Eigen::Vector3f up, a, b;
  // The d-th of n horizontal directions, evenly spaced.
  Eigen::Vector3f horizontal(int d, int n) const {
    const float angle = static_cast<float>(2.0 * M_PI * d / n);
    return std::cos(angle) * a + std::sin(angle) * b;
  }
  // All n of them.
  std::vector<Eigen::Vector3f> horizontals(int n) const {
    std::vector<Eigen::Vector3f> out(n);
    for (int d = 0; d < n; ++d) out[d] = horizontal(d, n);
    return out;
  }
};

constexpr int kFootprintRays = 8;

// Whether a candidate's footprint is flat: its kFootprintRays hits (heights measured down from
// `lift` above it, at `offsets`) and the candidate itself, fitted by a plane h = c0 + c1 a + c2 b
// (least squares, normal equations in double), with enough hits, a gentle enough slope and no
// point further off the plane than the roughness limit.
bool fitsFlat(const Hit* hits, const Eigen::Vector2f* offsets, float lift, float tanSlope,
              const FloorOptions& o) {
  Eigen::Vector3d rows[kFootprintRays + 1];  // (1, a, b) per point; the candidate first
  double heights[kFootprintRays + 1];
  int n = 0;
  rows[n] = Eigen::Vector3d(1, 0, 0), heights[n++] = 0.0;
  for (int d = 0; d < kFootprintRays; ++d) {
    if (hits[d].triangle < 0) continue;
    rows[n] = Eigen::Vector3d(1, offsets[d].x(), offsets[d].y());
    heights[n++] = lift - hits[d].t;
  }
  if (n - 1 < o.minFootprintHits) return false;
  Eigen::Matrix3d AtA = Eigen::Matrix3d::Zero();
  Eigen::Vector3d Ath = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) AtA += rows[i] * rows[i].transpose(), Ath += heights[i] * rows[i];
  const Eigen::Vector3d c = AtA.ldlt().solve(Ath);
  if (c.tail<2>().norm() > tanSlope) return false;
  double roughness = 0.0;
  for (int i = 0; i < n; ++i)
    roughness = std::max(roughness, std::abs(rows[i].dot(c) - heights[i]));
  return roughness <= o.maxRoughness;
}

// The candidates whose flag is set, in order.
std::vector<Candidate> kept(const std::vector<Candidate>& candidates,
                            const std::vector<char>& keep) {
  std::vector<Candidate> out;
  for (size_t k = 0; k < candidates.size(); ++k)
    if (keep[k]) out.push_back(candidates[k]);
  return out;
}

// Casts `perItem` rays for each of `count` items and judges each item by its hits: make(k, rays)
// writes item k's rays, judge(k, hits) says whether it passes. Items go a block at a time, so
// that the ray and hit buffers stay small and are reused (fresh memory is slow to write).
template <typename Make, typename Judge>
std::vector<char> castAndJudge(const RayCaster& caster, long count, int perItem, const Make& make,
                               const Judge& judge) {
  constexpr long kBlock = 2048;
  std::vector<Ray> rays(std::min(count, kBlock) * perItem);
  std::vector<Hit> hits(rays.size());
  std::vector<char> pass(count);
  for (long first = 0; first < count; first += kBlock) {
    const long n = std::min(kBlock, count - first);
#pragma omp parallel for schedule(static)
    for (long k = 0; k < n; ++k) make(first + k, &rays[k * perItem]);
    caster.intersect(rays.data(), hits.data(), n * perItem);
#pragma omp parallel for schedule(static)
    for (long k = 0; k < n; ++k) pass[first + k] = judge(first + k, &hits[k * perItem]);
  }
  return pass;
}

// The candidates flat at the scale of a footprint: downward rays at kFootprintRays points on a
// circle around each (from a little above it, so that noise and small steps are seen), fitted
// with the candidate by a plane (fitsFlat). A wall's edge, a step's nosing, the rim of a table
// and clutter fail; millimetres of noise on centimetre triangles do not.
std::vector<Candidate> flatCandidates(const std::vector<Candidate>& candidates,
                                      const RayCaster& caster, const FloorOptions& o,
                                      const Axes& axes) {
  const float radius = static_cast<float>(o.footprintRadius);
  const float tanSlope = static_cast<float>(std::tan(o.maxSlopeDegrees * M_PI / 180.0));
  const float lift = std::max(0.3f, 2.0f * radius * tanSlope + static_cast<float>(o.maxRoughness));
  std::vector<Eigen::Vector2f> offsets(kFootprintRays);  // [8] (a, b) of the footprint's rays
  for (int d = 0; d < kFootprintRays; ++d)
    offsets[d] = radius * Eigen::Vector2f(std::cos(2.0 * M_PI * d / kFootprintRays),
                                          std::sin(2.0 * M_PI * d / kFootprintRays));
  const auto footprint = [&](long k, Ray* rays) {
    for (int d = 0; d < kFootprintRays; ++d) {
      const Eigen::Vector3f from =
          candidates[k].point + offsets[d].x() * axes.a + offsets[d].y() * axes.b + lift * axes.up;
      rays[d] = Ray{from, -axes.up, 0.0f, 2.0f * lift};
    }
  };
  const auto flat = [&](long, const Hit* hits) {
    return fitsFlat(hits, offsets.data(), lift, tanSlope, o);
  };
  return kept(candidates, castAndJudge(caster, static_cast<long>(candidates.size()), kFootprintRays,
                                       footprint, flat));
}

// For each point, whether walls surround it: horizontal rays at 1 m, in 8 directions, hit
// something in at least 6 (a scan's walls have holes, and rooms have doors).
std::vector<char> enclosedPoints(const std::vector<Candidate>& points, const RayCaster& caster,
                                 const Axes& axes) {
  constexpr int kDirs = 8, kMinHits = 6;
  const std::vector<Eigen::Vector3f> dirs = axes.horizontals(kDirs);
  const auto around = [&](long k, Ray* rays) {
    for (int d = 0; d < kDirs; ++d) rays[d] = Ray{points[k].point + axes.up, dirs[d], 0.0f, 1e30f};
  };
  const auto enclosed = [&](long, const Hit* hits) {
    return std::count_if(hits, hits + kDirs, [](const Hit& h) { return h.triangle >= 0; }) >=
           kMinHits;
  };
  return castAndJudge(caster, static_cast<long>(points.size()), kDirs, around, enclosed);
}

// The grid of columns over the scene's horizontal extent.
struct Grid {
  Axes axes;
  double cell;             // metres
  Eigen::Vector2d origin;  // (a, b) of cell (0, 0)'s corner
  int nA, nB;
  float top;  // 1 m above the highest vertex, where the columns' rays start
  size_t cells() const { return static_cast<size_t>(nA) * nB; }
};

Grid gridOver(const Scene& scene, const FloorOptions& o) {
  Grid g;
  g.axes.up = scene.upVector();
  g.axes.a = Eigen::Vector3f::UnitX();   // both up axes (y, z) are perpendicular to x
  g.axes.b = g.axes.up.cross(g.axes.a);  // right-handed (a, b, up)
  double aMin = 1e30, aMax = -1e30, bMin = 1e30, bMax = -1e30, hMax = -1e30;
  for (const auto& p : scene.mesh.positions) {
    const double a = p.dot(g.axes.a), b = p.dot(g.axes.b), h = p.dot(g.axes.up);
    aMin = std::min(aMin, a), aMax = std::max(aMax, a);
    bMin = std::min(bMin, b), bMax = std::max(bMax, b);
    hMax = std::max(hMax, h);
  }
  const double extent = std::max(aMax - aMin, bMax - bMin);
  // Keep the grid bounded on huge scenes: at most ~4M columns.
  g.cell = std::max(o.cellSize, extent / 2000.0);
  g.origin = {aMin, bMin};
  g.nA = std::max(1, static_cast<int>(std::ceil((aMax - aMin) / g.cell)));
  g.nB = std::max(1, static_cast<int>(std::ceil((bMax - bMin) / g.cell)));
  g.top = static_cast<float>(hMax + 1.0);
  return g;
}

// Peels each column from the top: every surface a downward ray hits is a candidate, up to
// kMaxLayers per column.
std::vector<Candidate> peelColumns(const Grid& g, const RayCaster& caster) {
  const size_t cells = g.cells();
  const Eigen::Vector3f& up = g.axes.up;
  std::vector<Candidate> candidates;
  std::vector<Ray> rays(cells);
  std::vector<float> tStart(cells, 0.0f);
  std::vector<Hit> hits(cells);
  std::vector<Eigen::Vector3f> origins(cells);
  for (int i = 0; i < g.nA; ++i) {
    for (int j = 0; j < g.nB; ++j) {
      const float a = static_cast<float>(g.origin.x() + (i + 0.5) * g.cell);
      const float b = static_cast<float>(g.origin.y() + (j + 0.5) * g.cell);
      origins[static_cast<size_t>(i) * g.nB + j] = a * g.axes.a + b * g.axes.b + g.top * up;
    }
  }
  std::vector<int> active(cells);
  std::iota(active.begin(), active.end(), 0);
  for (int layer = 0; layer < kMaxLayers && !active.empty(); ++layer) {
    rays.resize(active.size());
    hits.resize(active.size());
    for (size_t k = 0; k < active.size(); ++k)
      rays[k] = Ray{origins[active[k]], -up, tStart[active[k]], 1e30f};
    caster.intersect(rays.data(), hits.data(), rays.size());
    std::vector<int> next;
    for (size_t k = 0; k < active.size(); ++k) {
      if (hits[k].triangle < 0) continue;
      const int c = active[k];
      candidates.push_back({c, origins[c] - hits[k].t * up, 0.0f});
      tStart[c] = hits[k].t + 1e-3f;
      next.push_back(c);
    }
    active.swap(next);
  }
  return candidates;
}

// The candidates with headroom and wall clearance, by rays from each: one up (its distance to
// the first hit is the candidate's headroom), and 8 horizontal ones at 0.5 and 1.5 m that must
// not hit within the clearance.
std::vector<Candidate> openCandidates(std::vector<Candidate> candidates, const RayCaster& caster,
                                      const FloorOptions& o, const Axes& axes) {
  const int kDirs = 8;
  const float heights[2] = {0.5f, 1.5f};
  const int perCand = 1 + 2 * kDirs;
  const std::vector<Eigen::Vector3f> dirs = axes.horizontals(kDirs);
  const auto around = [&](long k, Ray* rays) {
    rays[0] = Ray{candidates[k].point + 0.02f * axes.up, axes.up, 0.0f, 1e30f};
    for (int h = 0; h < 2; ++h)
      for (int d = 0; d < kDirs; ++d)
        rays[1 + h * kDirs + d] = Ray{candidates[k].point + heights[h] * axes.up, dirs[d], 0.0f,
                                      static_cast<float>(o.wallClearance)};
  };
  const auto open = [&](long k, const Hit* hits) {
    candidates[k].headroom =
        hits[0].triangle >= 0 ? hits[0].t : std::numeric_limits<float>::infinity();
    return candidates[k].headroom >= o.headroom &&
           std::none_of(hits + 1, hits + perCand, [](const Hit& h) { return h.triangle >= 0; });
  };
  const std::vector<char> pass =
      castAndJudge(caster, static_cast<long>(candidates.size()), perCand, around, open);
  return kept(candidates, pass);
}

// A scene with a ceiling over a room's worth of open floor (minRegionArea) is an interior: then
// a standing point with nothing above is inside only when walls surround it (a gap in a scan's
// ceiling), not on a roof or the ground outside. No share of the open floor would do: a roof
// is about as large as the floors under it, and the ground around a house can be far larger.
bool hasCeilingOver(const std::vector<Candidate>& open, double cell, const FloorOptions& o) {
  size_t covered = 0;
  for (const Candidate& c : open) covered += std::isfinite(c.headroom);
  return covered * cell * cell >= o.minRegionArea;
}

// The points under a ceiling, and those without one that walls surround.
std::vector<Candidate> insidePoints(const std::vector<Candidate>& open, const RayCaster& caster,
                                    const Axes& axes) {
  std::vector<Candidate> uncovered;
  for (const Candidate& c : open)
    if (!std::isfinite(c.headroom)) uncovered.push_back(c);
  const std::vector<char> enclosed = enclosedPoints(uncovered, caster, axes);
  std::vector<Candidate> inside;
  for (size_t k = 0, u = 0; k < open.size(); ++k) {
    if (std::isfinite(open[k].headroom) || enclosed[u++]) inside.push_back(open[k]);
  }
  return inside;
}

// Which points lie in a region large enough to walk in: regions connect 4-neighbouring cells
// whose floors differ less than a step, and are kept when they cover minRegionArea and
// minRegionShare of the largest.
std::vector<bool> inLargeRegions(const std::vector<Candidate>& open, const Grid& g,
                                 const FloorOptions& o) {
  std::vector<std::vector<int>> byCell(g.cells());
  for (size_t k = 0; k < open.size(); ++k) byCell[open[k].cell].push_back(static_cast<int>(k));
  std::vector<int> parent(open.size());
  std::iota(parent.begin(), parent.end(), 0);
  for (size_t k = 0; k < open.size(); ++k) {
    const int c = open[k].cell, i = c / g.nB, j = c % g.nB;
    const int nbrs[2][2] = {{i + 1, j}, {i, j + 1}};
    for (const auto& n : nbrs) {
      if (n[0] >= g.nA || n[1] >= g.nB) continue;
      for (int m : byCell[static_cast<size_t>(n[0]) * g.nB + n[1]]) {
        if (std::abs((open[m].point - open[k].point).dot(g.axes.up)) < o.stepHeight)
          parent[findRoot(parent, m)] = findRoot(parent, static_cast<int>(k));
      }
    }
  }
  std::vector<int> regionSize(open.size(), 0);
  for (size_t k = 0; k < open.size(); ++k) ++regionSize[findRoot(parent, static_cast<int>(k))];
  const int largest = *std::max_element(regionSize.begin(), regionSize.end());
  const double cellArea = g.cell * g.cell;
  const double minCells =
      std::max(o.minRegionArea / cellArea, o.minRegionShare * static_cast<double>(largest));
  std::vector<bool> keep(open.size());
  for (size_t k = 0; k < open.size(); ++k)
    keep[k] = !(regionSize[findRoot(parent, static_cast<int>(k))] < minCells);
  return keep;
}

}  // namespace

FloorMap::FloorMap(const Scene& scene, const RayCaster& caster, const FloorOptions& o) {
  PAIRCAST_CHECK(o.cellSize > 0);
  const Grid grid = gridOver(scene, o);
  up_ = grid.axes.up;
  axisA_ = grid.axes.a;
  axisB_ = grid.axes.b;
  cell_ = grid.cell;
  origin_ = grid.origin;
  nA_ = grid.nA;
  nB_ = grid.nB;

  // 1. Every surface down each column, of which the flat ones.
  const std::vector<Candidate> flat =
      flatCandidates(peelColumns(grid, caster), caster, o, grid.axes);
  if (flat.empty()) return;

  // 2. Headroom and wall clearance; inside only, in an interior.
  std::vector<Candidate> open = openCandidates(flat, caster, o, grid.axes);
  hasCeiling_ = hasCeilingOver(open, cell_, o);
  if (hasCeiling_) open = insidePoints(open, caster, grid.axes);
  if (open.empty()) return;

  // 3. Connected regions large enough to walk in.
  const std::vector<bool> keep = inLargeRegions(open, grid, o);
  std::vector<size_t> cells;  // of each point
  for (size_t k = 0; k < open.size(); ++k) {
    if (!keep[k]) continue;
    points_.push_back(open[k].point);
    cells.push_back(open[k].cell);
  }
  indexByCell(cells, grid.cells());
  measureEmptyRings();
}

// The points again, cell by cell (in points_' order within a cell), with where each cell's run
// starts: snap reads a cell's points from one place.
void FloorMap::indexByCell(const std::vector<size_t>& cellOf, size_t cells) {
  cellStart_.assign(cells + 1, 0);
  for (size_t c : cellOf) ++cellStart_[c + 1];
  for (size_t c = 0; c < cells; ++c) cellStart_[c + 1] += cellStart_[c];
  std::vector<uint32_t> next(cellStart_.begin(), cellStart_.end() - 1);
  byCell_.resize(points_.size());
  for (size_t k = 0; k < points_.size(); ++k) byCell_[next[cellOf[k]]++] = points_[k];
}

// Chebyshev distances to the nearest cell with points: the two-pass chamfer transform with
// unit steps to all eight neighbours, which is exact for that metric.
void FloorMap::measureEmptyRings() {
  constexpr int kFar = std::numeric_limits<int>::max() / 2;
  const size_t cells = cellStart_.size() - 1;
  std::vector<int> rings(cells, kFar);
  for (size_t c = 0; c < cells; ++c)
    if (cellStart_[c + 1] > cellStart_[c]) rings[c] = 0;
  auto at = [&](int i, int j) -> int& { return rings[static_cast<size_t>(i) * nB_ + j]; };
  auto relax = [&](int i, int j, int di, int dj) {
    const int ni = i + di, nj = j + dj;
    if (ni >= 0 && ni < nA_ && nj >= 0 && nj < nB_) at(i, j) = std::min(at(i, j), at(ni, nj) + 1);
  };
  for (int i = 0; i < nA_; ++i)
    for (int j = 0; j < nB_; ++j)
      for (const auto& [di, dj] : {std::pair{-1, -1}, {-1, 0}, {-1, 1}, {0, -1}})
        relax(i, j, di, dj);
  for (int i = nA_ - 1; i >= 0; --i)
    for (int j = nB_ - 1; j >= 0; --j)
      for (const auto& [di, dj] : {std::pair{1, 1}, {1, 0}, {1, -1}, {0, 1}}) relax(i, j, di, dj);
  // Capped: a ring below the true one only starts snap's search early.
  emptyRings_.resize(cells);
  for (size_t c = 0; c < cells; ++c)
    emptyRings_[c] = static_cast<uint16_t>(std::min<int>(rings[c], kMaxRing));
}

double FloorMap::area() const {
  return points_.size() * cell_ * cell_;
}

Eigen::Vector3f FloorMap::sample(Rng& rng) const {
  PAIRCAST_CHECK(!points_.empty());
  const Eigen::Vector3f& p = points_[rng.below(points_.size())];
  const float da = static_cast<float>(rng.uniform(-0.5, 0.5) * cell_);
  const float db = static_cast<float>(rng.uniform(-0.5, 0.5) * cell_);
  return p + da * axisA_ + db * axisB_;
}

// Rings of cells around p's, nearest first, until no farther ring can hold a nearer point: the
// same answer as a scan of the whole (2 reach + 1)^2 square, ties to the point first in that
// scan's order (cell row, column, then the cell's list), at a fraction of the cost (a candidate
// view takes several snaps of radius 2 m over 0.1 m cells).
std::optional<Eigen::Vector3f> FloorMap::snap(const Eigen::Vector3f& p, double radius) const {
  if (points_.empty() || !p.allFinite()) return std::nullopt;
  const double a = p.dot(axisA_) - origin_.x(), b = p.dot(axisB_) - origin_.y();
  const int ci = static_cast<int>(std::floor(a / cell_)),
            cj = static_cast<int>(std::floor(b / cell_));
  const int reach = static_cast<int>(std::ceil(radius / cell_));
  // A cell's points lie over its centre, so none lies nearer than the centre across the floor.
  // Distances are compared with kSlack to spare, for the rounding of points in float.
  constexpr double kSlack = 1e-4;
  float best = std::numeric_limits<float>::infinity();
  double beyond =
      best;  // (|best| + kSlack)^2: cells whose centres lie farther hold no nearer point
  // Where the best point lies in byCell_, which is the full scan's order of meeting points.
  int64_t bestIndex = -1;
  const auto visit = [&](int i, int j) {
    if (i < 0 || i >= nA_ || j < 0 || j >= nB_) return;
    const double da = (i + 0.5) * cell_ - a, db = (j + 0.5) * cell_ - b;
    if (da * da + db * db > beyond) return;
    const size_t cell = static_cast<size_t>(i) * nB_ + j;
    for (uint32_t k = cellStart_[cell]; k < cellStart_[cell + 1]; ++k) {
      const float d = (byCell_[k] - p).squaredNorm();
      if (d < best || (d == best && k < bestIndex)) {
        best = d, bestIndex = k;
        beyond = (std::sqrt(best) + kSlack) * (std::sqrt(best) + kSlack);
      }
    }
  };
  // Rings nearer than the nearest cell with points are empty. Outside the grid, that cell lies
  // at least as far as the grid's edge, and no nearer than the nearest from the edge's cell
  // (clamped) less the way to it.
  const int ki = std::clamp(ci, 0, nA_ - 1), kj = std::clamp(cj, 0, nB_ - 1);
  const int toEdge = std::max(std::abs(ci - ki), std::abs(cj - kj));
  const int first = std::max(toEdge, emptyRings_[static_cast<size_t>(ki) * nB_ + kj] - toEdge);
  if (first > reach) return std::nullopt;
  // Along the axis of its ring, a cell's centre in ring r lies at least r cells less p's offset
  // from its own cell's centre.
  const double offset =
      std::max(std::abs(a - (ci + 0.5) * cell_), std::abs(b - (cj + 0.5) * cell_));
  for (int r = first; r <= reach; ++r) {
    if (bestIndex >= 0 && r * cell_ - offset > std::sqrt(best) + kSlack) break;
    if (r == 0) {
      visit(ci, cj);
      continue;
    }
    for (int j = cj - r; j <= cj + r; ++j) {
      visit(ci - r, j);
      visit(ci + r, j);
    }
    for (int i = ci - r + 1; i <= ci + r - 1; ++i) {
      visit(i, cj - r);
      visit(i, cj + r);
    }
  }
  if (bestIndex < 0 || best > radius * radius) return std::nullopt;
  return byCell_[bestIndex];
}

}  // namespace paircast
