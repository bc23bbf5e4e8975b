// Sweet Home 3D furniture catalogues (.sh3f): zip archives holding
// PluginFurnitureCatalog.properties and textured OBJ models, as Debian's sweethome3d-furniture
// package installs them under /usr/share/sweethome3d/furniture/. Read in place through libarchive;
// never copied.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace paircast {

// Where Debian's sweethome3d-furniture package puts its catalogues.
inline constexpr const char* kDebianFurnitureDir = "/usr/share/sweethome3d/furniture";

// One piece of a catalogue, as its properties describe it. Sizes in metres.
struct CatalogModel {
  std::string catalogue;      // the .sh3f file
  std::string catalogueName;  // its "name" property
  std::string license;        // its "license" property (UTF-8)
  std::string id, name, category, creator;
  std::string model;  // the OBJ's path inside the archive, without a leading '/'
  float width = 0, depth = 0, height = 0, elevation = 0;  // x, z, y extents; height above floor
  float dropOnTop = -1;  // where pieces dropped on it rest, above its base (< 0: its height)
  Eigen::Matrix3f rotation = Eigen::Matrix3f::Identity();  // modelRotation: file axes -> SH3D's
  bool doorOrWindow = false;
};

// A Java .properties text (ISO 8859-1, \uXXXX escapes, '\' line continuations, '#' and '!'
// comments, '=', ':' or blanks between key and value) as UTF-8 key -> value.
std::map<std::string, std::string> parseProperties(const std::string& text);

// The models of one catalogue, in the order of their index (name#1, name#2, ...). Entries
// without a model or with non-positive sizes are left out. Throws paircast::Error naming
// `path` when the archive cannot be read or has no PluginFurnitureCatalog.properties.
std::vector<CatalogModel> readCatalog(const std::string& path);

// Every catalogue in `dir` (*.sh3f, by name). A catalogue that cannot be read is a warning
// naming it. Throws paircast::Error when `dir` has no readable catalogue, saying which Debian
// package installs them.
std::vector<CatalogModel> readCatalogs(const std::string& dir, std::vector<std::string>* warnings);

// The models' split, deterministic in the model's catalogue file name and id: about a fifth
// held out (a 64-bit FNV-1a hash of "<catalogue file name>#<id>", modulo 5, equal to 0).
enum class ModelSet { Train, HeldOut, All };
ModelSet parseModelSet(const std::string& name);  // "train", "heldout", "all"
bool isHeldOut(const CatalogModel& m);
bool inSet(const CatalogModel& m, ModelSet set);

// Writes the files under each of `folders` (archive paths ending in '/') of the catalogue `path`
// into `out`, keeping their relative paths, in one pass over the archive. Entries that would
// leave `out` (absolute paths, "..") or exceed `maxBytes` are skipped. Throws paircast::Error
// naming `path` when the archive is corrupt.
void extractFolders(const std::string& path, const std::set<std::string>& folders,
                    const std::string& out, uint64_t maxBytes = 256ull << 20);

}  // namespace paircast
