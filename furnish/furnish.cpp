#include "furnish/furnish.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "render/obj_writer.h"
#include "render/scene_loader.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace fs = std::filesystem;

namespace paircast {
namespace {

struct Rect {
  float x0, z0, x1, z1;
  float area() const { return (x1 - x0) * (z1 - z0); }
  bool overlaps(const Rect& o, float gap) const {
    return x0 < o.x1 + gap && o.x0 < x1 + gap && z0 < o.z1 + gap && o.z0 < z1 + gap;
  }
};

// The draws of one room: std::mt19937_64 is the same on every platform, and the conversion
// to [0, 1) is ours (the standard's distributions are not).
class RoomDraws {
 public:
  RoomDraws(uint64_t seed, int room) : gen_(seed * 0x9E3779B97F4A7C15ull + 7919u * (room + 1)) {}
  double unit() { return static_cast<double>(gen_() >> 11) * 0x1.0p-53; }
  size_t below(size_t n) { return static_cast<size_t>(unit() * static_cast<double>(n)) % n; }
  float between(float a, float b) { return a + static_cast<float>(unit()) * (b - a); }

 private:
  std::mt19937_64 gen_;
};

std::string makeScratchDir() {
  const char* tmp = std::getenv("TMPDIR");
  std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/paircast-furniture-XXXXXX";
  if (!mkdtemp(pattern.data())) throw Error(pattern, "cannot make a scratch folder for models");
  return pattern;
}

std::string entryName(const CatalogModel& m) {
  return fs::path(m.catalogue).filename().string() + "#" + m.id + " (" + m.name + ")";
}

std::string folderOf(const std::string& model) {
  const size_t slash = model.rfind('/');
  return slash == std::string::npos ? "" : model.substr(0, slash + 1);
}

// The footprint of a model of `width` x `depth` turned by `quarter` turns, centred at (x, z).
Rect footprint(float x, float z, float width, float depth, int quarter) {
  const float hx = (quarter % 2 ? depth : width) / 2, hz = (quarter % 2 ? width : depth) / 2;
  return {x - hx, z - hz, x + hx, z + hz};
}

// What planRoom needs besides the room.
struct RoomPlan {
  const LayoutSpec& layout;
  const FurnitureLibrary& library;
  const std::set<size_t>& excluded;
  const std::vector<Rect>& keepOut;  // doorways, in plan coordinates
};

// A placement of model `m` against wall `wall` (0: z0, 1: x1, 2: z1, 3: x0; 4: free standing)
// of the room's interior `in`, or nothing when it does not fit there.
std::optional<Placement> drawPlacement(const CatalogModel& m, size_t index, int room,
                                       const Rect& in, int wall, RoomDraws& draw) {
  // The model's front (+z) faces into the room: quarter turns about +y for each wall.
  static constexpr int kWallQuarter[4] = {0, 3, 2, 1};
  const int quarter = wall < 4 ? kWallQuarter[wall] : static_cast<int>(draw.below(4));
  const Rect size = footprint(0, 0, m.width, m.depth, quarter);
  const float hx = size.x1, hz = size.z1, g = kFurnitureGap;
  const float xlo = in.x0 + g + hx, xhi = in.x1 - g - hx, zlo = in.z0 + g + hz,
              zhi = in.z1 - g - hz;
  if (xlo > xhi || zlo > zhi) return std::nullopt;
  float x = draw.between(xlo, xhi), z = draw.between(zlo, zhi);
  if (wall == 0) z = zlo;
  if (wall == 1) x = xhi;
  if (wall == 2) z = zhi;
  if (wall == 3) x = xlo;
  const Rect r = footprint(x, z, m.width, m.depth, quarter);
  return Placement{index, room, x, z, quarter, r.x0, r.z0, r.x1, r.z1};
}

// The floor pieces of room `room`: drawn from its category until kMaxCover of its floor is
// covered, a count reached, or the attempts run out.
std::vector<Placement> planFloor(const RoomPlan& plan, int room,
                                 const std::vector<size_t>& candidates, RoomDraws& draw) {
  const RoomSpec& r = plan.layout.rooms[static_cast<size_t>(room)];
  const float t = kWallThickness / 2;
  const Rect in{r.x0 + t, r.z0 + t, r.x1 - t, r.z1 - t};
  const float cx = 0.5f * (in.x0 + in.x1), cz = 0.5f * (in.z0 + in.z1), c = kFreeCentre / 2;
  std::vector<Rect> blocked = plan.keepOut;
  blocked.push_back({cx - c, cz - c, cx + c, cz + c});
  std::vector<Placement> out;
  const size_t most = std::clamp<size_t>(static_cast<size_t>(in.area() / 2.0f), 3, 14);
  float covered = 0;
  for (int attempt = 0; attempt < 120 && out.size() < most; ++attempt) {
    const size_t index = candidates[draw.below(candidates.size())];
    const CatalogModel& m = plan.library.models()[index];
    const int wall = static_cast<int>(draw.below(5));
    if (m.elevation + m.height > plan.layout.height - 0.05f) continue;
    if (m.elevation > 0.05f && wall == 4) continue;  // hung pieces go on walls
    auto p = drawPlacement(m, index, room, in, wall, draw);
    if (!p) continue;
    const Rect f{p->x0, p->z0, p->x1, p->z1};
    if (covered + f.area() > kMaxCover * in.area()) continue;
    const auto hits = [&](const Rect& o) { return f.overlaps(o, 0); };
    const auto near = [&](const Placement& o) {
      return f.overlaps({o.x0, o.z0, o.x1, o.z1}, kFurnitureGap);
    };
    if (std::any_of(blocked.begin(), blocked.end(), hits) ||
        std::any_of(out.begin(), out.end(), near))
      continue;
    covered += f.area();
    p->y = m.elevation;
    out.push_back(*p);
  }
  return out;
}

// Up to two small pieces on each floor piece that can hold them, inside its top and apart.
void planTops(const RoomPlan& plan, int room, const std::vector<size_t>& small,
              std::vector<Placement>& placed, RoomDraws& draw) {
  const size_t floorPieces = placed.size();
  for (size_t h = 0; h < floorPieces && !small.empty(); ++h) {
    const CatalogModel& host = plan.library.models()[placed[h].model];
    if (!canHold(host)) continue;
    const Rect top{placed[h].x0, placed[h].z0, placed[h].x1, placed[h].z1};
    const float y = placed[h].y + host.height;
    const size_t first = placed.size();
    for (int attempt = 0; attempt < 6 && placed.size() - first < 2; ++attempt) {
      const size_t index = small[draw.below(small.size())];
      const CatalogModel& m = plan.library.models()[index];
      if (y + m.height > plan.layout.height - 0.05f) continue;
      auto p = drawPlacement(m, index, room, top, 4, draw);
      if (!p) continue;
      const Rect f{p->x0, p->z0, p->x1, p->z1};
      const bool apart = std::none_of(placed.begin() + static_cast<long>(first), placed.end(),
                                      [&](const Placement& o) {
                                        return f.overlaps({o.x0, o.z0, o.x1, o.z1}, kFurnitureGap);
                                      });
      if (!apart) continue;
      p->y = y;
      p->host = static_cast<int>(h);
      placed.push_back(*p);
    }
  }
}

// The models of room `room`: floor pieces of its category, then small ones on their tops.
std::vector<Placement> planRoom(const RoomPlan& plan, int room) {
  const RoomSpec& r = plan.layout.rooms[static_cast<size_t>(room)];
  std::vector<size_t> large, small;
  for (size_t i : plan.library.ofCategory(roomCategory(r)))
    if (!plan.excluded.count(i))
      (isTabletop(plan.library.models()[i]) ? small : large).push_back(i);
  if (large.empty()) return {};
  RoomDraws draw(plan.layout.seed, room);
  std::vector<Placement> out = planFloor(plan, room, large, draw);
  planTops(plan, room, small, out, draw);
  return out;
}

// Doors of the catalogue in about half the openings, each scaled to its opening's width and
// height, its depth (at most 0.2 m) centred on the wall.
std::vector<Placement> planDoors(const LayoutSpec& layout, const FurnitureLibrary& library,
                                 const std::set<size_t>& excluded) {
  std::vector<size_t> doors;
  for (size_t i = 0; i < library.models().size(); ++i)
    if (isDoor(library.models()[i]) && inSet(library.models()[i], library.options().models) &&
        !excluded.count(i))
      doors.push_back(i);
  std::vector<Placement> out;
  const std::vector<DoorOpening> openings = doorOpenings(layout);
  for (size_t k = 0; k < openings.size() && !doors.empty(); ++k) {
    RoomDraws draw(layout.seed, -1 - static_cast<int>(k));
    if (draw.unit() >= kClosedDoorShare) continue;
    const size_t index = doors[draw.below(doors.size())];
    const CatalogModel& m = library.models()[index];
    const DoorOpening& d = openings[k];
    const int quarter = (d.alongZ ? 1 : 0) + 2 * static_cast<int>(draw.below(2));
    const float depth = std::min(m.depth, 0.2f);
    const Rect f = footprint(d.x, d.z, d.width, depth, quarter);
    Placement p{index, layout.doors[k].roomA, d.x, d.z, quarter, f.x0, f.z0, f.x1, f.z1};
    p.door = static_cast<int>(k);
    p.widthScale = d.width / m.width;
    p.heightScale = kDoorHeight / m.height;
    p.depthScale = depth / m.depth;
    out.push_back(p);
  }
  return out;
}

std::vector<Placement> planLayout(const LayoutSpec& layout, const FurnitureLibrary& library,
                                  const std::set<size_t>& excluded) {
  std::vector<Rect> keepOut;
  for (const Eigen::Vector4f& k : doorwayKeepOuts(layout))
    keepOut.push_back({k[0], k[1], k[2], k[3]});
  const RoomPlan plan{layout, library, excluded, keepOut};
  std::vector<Placement> all = planDoors(layout, library, excluded);
  for (size_t i = 0; i < layout.rooms.size(); ++i) {
    auto some = planRoom(plan, static_cast<int>(i));
    for (Placement& p : some)
      if (p.host >= 0) p.host += static_cast<int>(all.size());
    all.insert(all.end(), some.begin(), some.end());
  }
  return all;
}

// The model's mesh scaled (a door's), turned by p.quarter about +y and moved to its place.
Mesh placed(const Mesh& model, const Placement& p) {
  Mesh m = model;
  const Eigen::Vector3f scale(p.widthScale, p.heightScale, p.depthScale);
  for (Eigen::Vector3f& v : m.positions) v = v.cwiseProduct(scale);
  const float angle = static_cast<float>(M_PI / 2) * static_cast<float>(p.quarter);
  const float c = std::round(std::cos(angle)), s = std::round(std::sin(angle));
  for (Eigen::Vector3f& v : m.positions)
    v = Eigen::Vector3f(c * v.x() + s * v.z() + p.x, v.y() + p.y, -s * v.x() + c * v.z() + p.z);
  return m;
}

nlohmann::json creditsOf(const std::string& name, const std::vector<Placement>& placements,
                         const FurnitureLibrary& library) {
  std::map<size_t, int> count;
  for (const Placement& p : placements) ++count[p.model];
  nlohmann::json models = nlohmann::json::array();
  for (const auto& [index, n] : count) {
    const CatalogModel& m = library.models()[index];
    models.push_back({{"catalogue", fs::path(m.catalogue).filename().string()},
                      {"catalogue_name", m.catalogueName},
                      {"id", m.id},
                      {"name", m.name},
                      {"category", m.category},
                      {"creator", m.creator},
                      {"license", m.license},
                      {"instances", n}});
  }
  return {{"scene", name},
          {"source", "Sweet Home 3D furniture catalogues (Debian package sweethome3d-furniture)"},
          {"models", models}};
}

}  // namespace

FurnitureLibrary::FurnitureLibrary(const FurnishOptions& options)
    : options_(options), models_(readCatalogs(options.catalogDir, &warnings)) {
  scratch_ = makeScratchDir();
}

FurnitureLibrary::~FurnitureLibrary() {
  std::error_code ec;
  fs::remove_all(scratch_, ec);
}

std::vector<size_t> FurnitureLibrary::ofCategory(const std::string& category) const {
  std::vector<size_t> out;
  for (size_t i = 0; i < models_.size(); ++i)
    if (models_[i].category == category && !models_[i].doorOrWindow &&
        inSet(models_[i], options_.models))
      out.push_back(i);
  return out;
}

void FurnitureLibrary::load(const std::set<size_t>& indices) {
  std::map<std::string, std::set<std::string>> folders;  // by catalogue
  std::vector<size_t> todo;
  for (size_t i : indices) {
    if (meshes_.count(i) || unusable_.count(i)) continue;
    todo.push_back(i);
    folders[models_[i].catalogue].insert(folderOf(models_[i].model));
  }
  std::map<std::string, std::string> catalogueError;
  for (const auto& [catalogue, wanted] : folders) {
    try {
      extractFolders(catalogue, wanted, scratch_);
    } catch (const Error& e) {
      catalogueError[catalogue] = e.what();
    }
  }
  for (size_t i : todo) {
    const CatalogModel& m = models_[i];
    try {
      if (catalogueError.count(m.catalogue)) throw Error(catalogueError[m.catalogue]);
      meshes_.emplace(i, normalised(m, (fs::path(scratch_) / m.model).string()));
    } catch (const Error& e) {
      unusable_.insert(i);
      warnings.push_back("model skipped: " + entryName(m) + ": " + e.what());
    }
  }
}

const Mesh* FurnitureLibrary::mesh(size_t index) const {
  const auto it = meshes_.find(index);
  return it == meshes_.end() ? nullptr : &it->second;
}

Mesh FurnitureLibrary::normalised(const CatalogModel& m, const std::string& objPath) const {
  if (!fs::is_regular_file(objPath)) throw Error(m.model, "the catalogue has no such model file");
  LoadOptions load;
  load.maxTriangles = options_.maxModelTriangles;
  Scene scene = loadScene(objPath, load);
  Mesh mesh = std::move(scene.mesh);
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(INFINITY), hi = -lo;
  for (Eigen::Vector3f& v : mesh.positions) {
    v = m.rotation * v;
    lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  }
  const Eigen::Vector3f size(m.width, m.height, m.depth), extent = hi - lo;
  Eigen::Vector3f scale;
  for (int k = 0; k < 3; ++k) scale[k] = extent[k] > 1e-6f ? size[k] / extent[k] : 1.0f;
  const Eigen::Vector3f centre = 0.5f * (lo + hi);
  for (Eigen::Vector3f& v : mesh.positions) {
    v = (v - centre).cwiseProduct(scale);
    v.y() += 0.5f * extent.y() * scale.y();  // base on y = 0
  }
  // Names unique to the model, so that two models' "wood.jpg" stay apart when written.
  const std::string prefix = fs::path(m.catalogue).stem().string() + "_" + m.id + "_";
  for (size_t t = 0; t < mesh.textures.size(); ++t)
    mesh.textures[t].name = prefix + std::to_string(t);
  return mesh;
}

bool isDoor(const CatalogModel& m) {
  std::string name = m.name;
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  const bool door = name.find("door") != std::string::npos;
  const bool excluded = name.find("garage") != std::string::npos ||
                        name.find("elevator") != std::string::npos ||
                        name.find("double") != std::string::npos;
  return (m.doorOrWindow || m.category == "Doors and windows") && door && !excluded &&
         m.width <= 1.2f;
}

bool isTabletop(const CatalogModel& m) {
  return std::max(m.width, m.depth) < 0.35f && m.height < 0.45f && m.elevation <= 0.0f;
}

bool canHold(const CatalogModel& m) {
  return m.dropOnTop < 0 && m.elevation <= 0.0f && m.height >= 0.5f && m.height <= 1.2f &&
         std::min(m.width, m.depth) >= 0.3f;
}

std::string roomCategory(const RoomSpec& room) {
  switch (room.kind) {
    case RoomKind::Living:
      return "Living room";
    case RoomKind::Bedroom:
      return "Bedroom";
    case RoomKind::Kitchen:
      return "Kitchen";
    case RoomKind::Office:
      return "Office";
    case RoomKind::Hall:
      break;
  }
  return (room.x1 - room.x0) * (room.z1 - room.z0) < 12.0f ? "Bathroom" : "Living room";
}

FurnishedScene furnishLayout(const LayoutSpec& layout, FurnitureLibrary& library) {
  LayoutSpec shell = layout;
  shell.furnished = true;
  FurnishedScene out;
  out.mesh = buildLayout(shell);
  // Plan, load what the plan uses, and plan again without the models that could not be used,
  // until every planned model loads.
  std::set<size_t> excluded;
  for (int round = 0; round < 8; ++round) {
    out.placements = planLayout(layout, library, excluded);
    std::set<size_t> used;
    for (const Placement& p : out.placements) used.insert(p.model);
    library.load(used);
    size_t before = excluded.size();
    for (size_t i : used)
      if (library.unusable(i)) excluded.insert(i);
    if (excluded.size() == before) break;
  }
  // Whatever still failed to load is left out, with what stands on it.
  std::vector<Placement> kept;
  std::vector<int> keptAs(out.placements.size(), -1);
  for (size_t i = 0; i < out.placements.size(); ++i) {
    Placement p = out.placements[i];
    const Mesh* model = library.mesh(p.model);
    if (!model || (p.host >= 0 && keptAs[static_cast<size_t>(p.host)] < 0)) continue;
    if (p.host >= 0) p.host = keptAs[static_cast<size_t>(p.host)];
    out.mesh.append(placed(*model, p));
    keptAs[i] = static_cast<int>(kept.size());
    kept.push_back(p);
  }
  out.placements = std::move(kept);
  out.mesh.validate(layout.name);
  out.credits = creditsOf(layout.name, out.placements, library);
  return out;
}

std::string writeFurnishedScene(const FurnishedScene& scene, const std::string& out,
                                const std::string& name) {
  const fs::path dir = fs::path(out) / name;
  const std::string path = (dir / (name + ".obj")).string();
  writeObj(path, scene.mesh);
  writeFileAtomic((dir / "credits.json").string(), scene.credits.dump(1) + "\n");
  return path;
}

}  // namespace paircast
