#include "covis/pointcloud_covis.h"

#include <algorithm>
#include <nanoflann.hpp>
#include <vector>

#include "covis/unproject.h"
#include "util/error.h"

namespace paircast {
namespace {

// nanoflann's dataset interface over a point vector.
struct PointCloud {
  const std::vector<Eigen::Vector3f>& points;  // [N] world points
  size_t kdtree_get_point_count() const { return points.size(); }
  float kdtree_get_pt(size_t i, size_t dim) const { return points[i][static_cast<int>(dim)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

// nanoflann 1.5 renamed SearchParams (checks, eps, sorted) to SearchParameters (eps, sorted):
// Debian 12 ships 1.4, Debian 13 1.7. Unsorted, exact search in both.
#if NANOFLANN_VERSION >= 0x150
inline nanoflann::SearchParameters unsortedSearch() {
  return nanoflann::SearchParameters(0.0f, false);
}
#else
inline nanoflann::SearchParams unsortedSearch() {
  return nanoflann::SearchParams(0, 0.0f, false);
}
#endif

using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointCloud>,
                                                   PointCloud, 3, uint32_t>;

// A result set that stops the search at the first point strictly inside the radius: we only
// need to know whether a neighbour exists, not which one is nearest.
class AnyWithin {
 public:
  using DistanceType = float;  // nanoflann >= 1.5 reads it
  using IndexType = uint32_t;
  explicit AnyWithin(float radiusSquared) : radiusSquared_(radiusSquared) {}
  bool full() const { return found_; }
  float worstDist() const { return radiusSquared_; }
  bool addPoint(float distSquared, uint32_t) {
    found_ = found_ || distSquared < radiusSquared_;
    return !found_;  // false stops the search
  }
  bool found() const { return found_; }
  void sort() {}  // nanoflann >= 1.5 names it even for unsorted searches

 private:
  float radiusSquared_;
  bool found_ = false;
};

// Points of `query` with a neighbour in `tree` strictly within the radius.
size_t countWithin(const std::vector<Eigen::Vector3f>& query, const KdTree& tree, size_t treeSize,
                   float radius) {
  if (query.empty() || treeSize == 0) return 0;
  size_t n = 0;
  const auto params = unsortedSearch();
  for (const Eigen::Vector3f& p : query) {
    AnyWithin result(radius * radius);
    tree.findNeighbors(result, p.data(), params);
    n += result.found();
  }
  return n;
}

}  // namespace

CovisResult computePointCloudCovisibility(const Camera& ci, const ImageF& depthI, const Camera& cj,
                                          const ImageF& depthJ, const PointCloudCovisOptions& o) {
  if (!(o.radius > 0.0f))
    throw Error("point-cloud covis radius must be > 0, got " + std::to_string(o.radius));
  std::vector<Eigen::Vector3f> pi, pj;  // [N_i], [N_j] world points
  unprojectDepth(ci, depthI, pi);
  unprojectDepth(cj, depthJ, pj);
  const PointCloud cloudI{pi}, cloudJ{pj};
  const nanoflann::KDTreeSingleIndexAdaptorParams params(10);
  const KdTree treeI(3, cloudI, params), treeJ(3, cloudJ, params);
  const size_t ij = countWithin(pi, treeJ, pj.size(), o.radius);
  const size_t ji = countWithin(pj, treeI, pi.size(), o.radius);

  const double allI = static_cast<double>(ci.width) * ci.height;
  const double allJ = static_cast<double>(cj.width) * cj.height;
  const bool all = o.normalize == CovisOptions::Normalize::All;
  const double denI = all ? allI : static_cast<double>(pi.size());
  const double denJ = all ? allJ : static_cast<double>(pj.size());
  CovisResult r;
  r.valid_i = pi.size() / allI;
  r.valid_j = pj.size() / allJ;
  r.v_ij = denI > 0 ? ij / denI : 0.0;
  r.v_ji = denJ > 0 ? ji / denJ : 0.0;
  r.covis = std::min(r.v_ij, r.v_ji);
  return r;
}

}  // namespace paircast
