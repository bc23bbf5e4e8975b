// Small analytic scenes for the dataset tests, written as OBJ so that the command-line tools
// can read them too.
#pragma once

#include <Eigen/Core>
#include <fstream>
#include <string>
#include <vector>

namespace paircast::testing {

struct BoxSpec {
  Eigen::Vector3f lo, hi;
};

// Writes axis-aligned boxes as one OBJ file (y up). `zUp` swaps y and z, turning the same scene
// into a z-up file.
inline void writeBoxesObj(const std::string& path, const std::vector<BoxSpec>& boxes,
                          bool zUp = false) {
  std::ofstream out(path);
  int base = 1;
  for (const auto& b : boxes) {
    for (int i = 0; i < 8; ++i) {
      Eigen::Vector3f p((i & 1) ? b.hi.x() : b.lo.x(), (i & 2) ? b.hi.y() : b.lo.y(),
                        (i & 4) ? b.hi.z() : b.lo.z());
      if (zUp) p = Eigen::Vector3f(p.x(), -p.z(), p.y());
      out << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
    }
    const int quads[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1},
                             {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
    for (const auto& q : quads)
      out << "f " << base + q[0] << " " << base + q[1] << " " << base + q[2] << " " << base + q[3]
          << "\n";
    base += 8;
  }
}

// A closed 6 x 2.8 x 5 m room (10 cm walls, floor at y = 0) with a table and a cabinet.
inline std::vector<BoxSpec> roomBoxes() {
  return {
      {{-3.1f, -0.1f, -2.6f}, {3.1f, 0.0f, 2.6f}},  // floor slab
      {{-3.1f, 2.8f, -2.6f}, {3.1f, 2.9f, 2.6f}},   // ceiling slab
      {{-3.1f, 0.0f, -2.6f}, {-3.0f, 2.8f, 2.6f}},  // walls
      {{3.0f, 0.0f, -2.6f}, {3.1f, 2.8f, 2.6f}},
      {{-3.0f, 0.0f, -2.6f}, {3.0f, 2.8f, -2.5f}},
      {{-3.0f, 0.0f, 2.5f}, {3.0f, 2.8f, 2.6f}},
      {{-0.6f, 0.7f, -0.4f}, {0.6f, 0.75f, 0.4f}},  // table top
      {{1.8f, 0.0f, 1.8f}, {2.9f, 1.2f, 2.4f}},     // cabinet
  };
}

}  // namespace paircast::testing
