#include "covis/covisibility.h"

#include <cmath>

#include "util/error.h"

namespace paircast {

VisibleCount countVisible(const Camera& ci, const ImageF& depthI, const Camera& cj,
                          const ImageF& depthJ, const CovisOptions& o) {
  PAIRCAST_CHECK_MSG(depthI.width == ci.width && depthI.height == ci.height && depthI.channels == 1,
                     "depth i does not match its camera");
  PAIRCAST_CHECK_MSG(depthJ.width == cj.width && depthJ.height == cj.height && depthJ.channels == 1,
                     "depth j does not match its camera");
  // Pixel (u, v) of i with depth z maps to homogeneous pixel coordinates of j:
  //   q = z * M (u + 0.5, v + 0.5, 1) + b,  M = Kj R_ji Ki^-1,  b = Kj t_ji,
  // where (R_ji, t_ji) = jFromWorld * worldFromI; q.z is the z-depth in j.
  const Eigen::Isometry3d jFromI = cj.cameraFromWorld() * ci.worldFromCamera();
  const Eigen::Matrix3f M = (cj.K * jFromI.linear() * ci.K.inverse()).cast<float>();
  const Eigen::Vector3f b = (cj.K * jFromI.translation()).cast<float>();
  const int Wi = ci.width, Hi = ci.height, Wj = cj.width, Hj = cj.height;
  const float* dj = depthJ.data.data();
  const float absTol = o.absTol, relTol = o.relTol;
  VisibleCount count;
  for (int v = 0; v < Hi; ++v) {
    const float* row = depthI.data.data() + static_cast<size_t>(v) * Wi;
    const Eigen::Vector3f rowBase = M * Eigen::Vector3f(0.5f, v + 0.5f, 1.0f);
    const Eigen::Vector3f step = M.col(0);
    for (int u = 0; u < Wi; ++u) {
      const float z = row[u];
      if (!(z > 0.0f)) continue;
      ++count.valid;
      const Eigen::Vector3f q = z * (rowBase + static_cast<float>(u) * step) + b;
      if (!(q.z() > 1e-6f)) continue;  // behind view j
      const float inv = 1.0f / q.z();
      const float x = q.x() * inv, y = q.y() * inv;
      if (!(x >= 0.0f && y >= 0.0f && x < Wj && y < Hj)) continue;
      const float d = dj[static_cast<size_t>(y) * Wj + static_cast<size_t>(x)];
      if (d > 0.0f && std::abs(q.z() - d) <= absTol + relTol * d) ++count.visible;
    }
  }
  return count;
}

CovisResult computeCovisibility(const Camera& ci, const ImageF& depthI, const Camera& cj,
                                const ImageF& depthJ, const CovisOptions& o) {
  const VisibleCount ij = countVisible(ci, depthI, cj, depthJ, o);
  const VisibleCount ji = countVisible(cj, depthJ, ci, depthI, o);
  const double allI = static_cast<double>(ci.width) * ci.height;
  const double allJ = static_cast<double>(cj.width) * cj.height;
  CovisResult r;
  r.valid_i = ij.valid / allI;
  r.valid_j = ji.valid / allJ;
  const bool all = o.normalize == CovisOptions::Normalize::All;
  const double denI = all ? allI : static_cast<double>(ij.valid);
  const double denJ = all ? allJ : static_cast<double>(ji.valid);
  r.v_ij = denI > 0 ? ij.visible / denI : 0.0;
  r.v_ji = denJ > 0 ? ji.visible / denJ : 0.0;
  r.covis = std::min(r.v_ij, r.v_ji);
  return r;
}

}  // namespace paircast
