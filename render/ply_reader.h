// PLY files, before and instead of assimp: a strict header reader that refuses what assimp
// 5.2.5 mishandles (hangs, aborts, counts the file cannot hold), and a direct reader for the
// binary little-endian files that scans ship.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "render/mesh.h"
#include "render/scene_loader.h"

namespace paircast {

struct PlyProperty {
  std::string name;
  std::string type;       // of the value, or of a list's items
  std::string countType;  // of a list's length; empty for a scalar property
};
struct PlyElement {
  std::string name;
  uint64_t count = 0;
  uint64_t minBytes = 0;  // per instance
  std::vector<PlyProperty> properties;
};
struct PlyHeader {
  uint64_t bytes = 0;  // up to and including the end_header line
  std::string format;  // ascii, binary_little_endian or binary_big_endian
  std::vector<PlyElement> elements;
};

// Reads a PLY header strictly, and throws paircast::Error on anything but the keywords of the
// format, spaces and tabs: assimp 5.2.5 loops forever when it does not see end_header, and it
// splits lines differently from us (fuzz_scene_ply found "end_header\v" and a missing one).
PlyHeader readPlyHeader(const std::string& path);

// A PLY header states its element counts before the data, and assimp allocates (and zeroes)
// that many vertices before reading one: a 200-byte file claiming 3e8 vertices made it touch
// 9 GB for 195 s. Counts the rest of the file cannot hold, and counts over the limits, are
// refused here.
PlyHeader checkPlyHeader(const std::string& path, uint64_t fileBytes, const LoadOptions& options);

// Whether the fast reader handles the file: binary little-endian, one vertex element with x y z,
// one face element whose only list is the vertex indices, and no other lists.
bool plyFastPathApplies(const PlyHeader& h);

// Reads the body of a PLY file plyFastPathApplies accepted into `mesh` (positions scaled, sRGB
// 8-bit colours made linear, polygons fanned into triangles, one white material). Every count,
// length and index is checked against the bytes there are and the vertices read. assimp's PLY
// importer keeps every property of every vertex in generic containers and took most of the load
// time and memory of a million-triangle scan (ScanNet's *_vh_clean_2.ply, Replica's mesh.ply).
void readBinaryPly(const std::string& path, const PlyHeader& h, const LoadOptions& options,
                   Mesh& mesh);

}  // namespace paircast
