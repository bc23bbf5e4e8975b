// Procedural indoor scans, written in the formats the scan datasets ship, so that tests and
// benchmarks meet what users render without committing large files:
//   scannet:  <name>_vh_clean_2.ply, binary little-endian, float x y z, uchar RGBA per vertex;
//   replica:  mesh.ply, binary, float x y z nx ny nz, uchar RGB, quad faces (lists of 4);
//   mp3d:     matterport_mesh/<name>.obj + .mtl + many JPEG textures.
// All are z up, in metres. Like a real scan, the surfaces are densely tessellated grids with
// millimetre noise along their normals, holes in the floor and walls, a ceiling with gaps, and
// furniture (a table, a sofa, a cabinet, a bed, boxes on the floor). Deterministic in the seed.
#pragma once

#include <cstdint>
#include <string>

#include "render/mesh.h"

namespace paircast {

enum class ScanKind { ScanNet, Replica, Matterport };
ScanKind parseScanKind(const std::string& text);  // "scannet", "replica" or "mp3d"
std::string scanKindName(ScanKind kind);

struct ScanSpec {
  ScanKind kind = ScanKind::ScanNet;
  size_t triangles = 1'300'000;  // target; the result is within a few percent of it
  uint64_t seed = 1;
  float noise = 0.003f;  // standard deviation of the noise along the normals, metres
};

// The scan as one mesh, z up. Triangles come in pairs: 2k and 2k+1 are the two halves of quad
// k, (t[2k][0], t[2k][1], t[2k][2], t[2k+1][2]), which the Replica writer keeps as one face.
// Vertex colours hold the scan's colours; for the Matterport kind, materials and textures too.
Mesh buildScan(const ScanSpec& spec);

// Writes the scan into `dir` in its dataset's layout and returns the path of the scene file;
// `stats`, when given, receives the mesh's statistics.
std::string writeScan(const ScanSpec& spec, const std::string& dir, MeshStats* stats = nullptr);

}  // namespace paircast
