// Furnished homes: the Sweet Home 3D catalogue reader, the placement of models in the floor
// plans, the held-out split, the credits, and make_scenes --furnish end to end. Most tests use
// small catalogues written here (a few box models); one uses Debian's sweethome3d-furniture.
#include <archive.h>
#include <archive_entry.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>

#include "dataset/generate_job.h"
#include "furnish/catalog.h"
#include "furnish/furnish.h"
#include "render/scene_loader.h"
#include "test_errors.h"
#include "test_files.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/image_io.h"

namespace fs = std::filesystem;

namespace paircast {
namespace {

// A zip of `files` (name -> bytes) at `path`.
void writeZip(const std::string& path, const std::map<std::string, std::string>& files) {
  archive* a = archive_write_new();
  archive_write_set_format_zip(a);
  ASSERT_EQ(archive_write_open_filename(a, path.c_str()), ARCHIVE_OK);
  for (const auto& [name, bytes] : files) {
    archive_entry* e = archive_entry_new();
    archive_entry_set_pathname(e, name.c_str());
    archive_entry_set_size(e, static_cast<la_int64_t>(bytes.size()));
    archive_entry_set_filetype(e, AE_IFREG);
    archive_entry_set_perm(e, 0644);
    ASSERT_EQ(archive_write_header(a, e), ARCHIVE_OK);
    ASSERT_EQ(archive_write_data(a, bytes.data(), bytes.size()),
              static_cast<la_ssize_t>(bytes.size()));
    archive_entry_free(e);
  }
  archive_write_close(a);
  archive_write_free(a);
}

// A unit cube, [0, 1]^3, in OBJ with a textured material.
std::string cubeObj(const std::string& mtl) {
  std::string s = "mtllib " + mtl + "\nusemtl skin\n";
  for (int i = 0; i < 8; ++i)
    s += "v " + std::to_string(i & 1) + " " + std::to_string((i >> 1) & 1) + " " +
         std::to_string((i >> 2) & 1) + "\n";
  s += "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";
  const int quads[6][4] = {{1, 3, 4, 2}, {5, 6, 8, 7}, {1, 2, 6, 5},
                           {3, 7, 8, 4}, {1, 5, 7, 3}, {2, 4, 8, 6}};
  for (const auto& q : quads)
    s += "f " + std::to_string(q[0]) + "/1 " + std::to_string(q[1]) + "/2 " + std::to_string(q[2]) +
         "/3 " + std::to_string(q[3]) + "/4\n";
  return s;
}

std::string pngBytes(uint8_t shade) {
  Image8 img(4, 4, 3);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<uint8_t>(shade + i);
  const auto bytes = encodeImage(img, "png");
  return std::string(bytes.begin(), bytes.end());
}

struct FakeModel {
  std::string id, category;
  float width, depth, height;  // cm
  bool broken = false;
  float elevation = 0;
};

// A catalogue of `models`, each a textured cube in its own folder (a broken one's OBJ is not
// an OBJ), with the properties Sweet Home 3D writes.
void writeCatalog(const std::string& path, const std::vector<FakeModel>& models,
                  const std::string& license = "CC-BY 3.0 \\u00a9 Caf\xe9") {
  std::map<std::string, std::string> files;
  std::string p =
      "# a test catalogue\nid=Test#Catalog\nname=Test catalogue\nlicense=" + license + "\n";
  int n = 0;
  for (const FakeModel& m : models) {
    const std::string k = "#" + std::to_string(++n), dir = "test/" + m.id + "/";
    p += "id" + k + "=Test#" + m.id + "\nname" + k + "=" + m.id + "\ncategory" + k + "=" +
         m.category + "\nmodel" + k + "=/" + dir + m.id + ".obj\nwidth" + k + "=" +
         std::to_string(m.width) + "\ndepth" + k + "=" + std::to_string(m.depth) + "\nheight" + k +
         "=" + std::to_string(m.height) + "\ncreator" + k + "=Maker " + m.id + "\nelevation" + k +
         "=" + std::to_string(m.elevation) + "\n";
    files[dir + m.id + ".obj"] = m.broken ? "this is not\0 an obj" : cubeObj(m.id + ".mtl");
    files[dir + m.id + ".mtl"] = "newmtl skin\nKd 1 1 1\nmap_Kd skin.png\n";
    files[dir + "skin.png"] = pngBytes(static_cast<uint8_t>(20 * n));
  }
  files["PluginFurnitureCatalog.properties"] = p;
  writeZip(path, files);
}

// Models of every room category, of everyday sizes.
std::vector<FakeModel> everydayModels() {
  std::vector<FakeModel> m;
  const char* categories[] = {"Living room", "Bedroom", "Kitchen", "Office", "Bathroom"};
  int k = 0;
  for (const char* c : categories)
    for (int i = 0; i < 4; ++i, ++k)
      m.push_back({"m" + std::to_string(k), c, 40.0f + 25.0f * i, 35.0f + 15.0f * (i % 3),
                   50.0f + 40.0f * i});
  for (const char* c : categories)  // small pieces, for the tops of the others
    m.push_back({"s" + std::to_string(k++), c, 15, 12, 20});
  m.push_back({"door1", "Doors and windows", 87, 10, 205});
  m.push_back({"door2", "Doors and windows", 96, 17, 210});
  m.push_back({"garagedoor", "Doors and windows", 440, 30, 220});  // never in a room's opening
  m.push_back({"shelf", "Living room", 60, 20, 30, false, 150});   // hung on a wall
  m.push_back({"tower", "Living room", 50, 50, 400});              // taller than any ceiling
  return m;
}

std::string writeEverydayCatalog(const std::string& dir) {
  fs::create_directories(dir);
  writeCatalog(dir + "/test.sh3f", everydayModels());
  return dir;
}

FurnishOptions optionsFor(const std::string& dir, ModelSet set = ModelSet::All) {
  FurnishOptions o;
  o.catalogDir = dir;
  o.models = set;
  return o;
}

TEST(Properties, ParsesJavaPropertiesIntoUtf8) {
  const auto p = parseProperties(
      "# comment\n! also a comment\n  key1 = value one\nkey2:two\nkey3 three\n"
      "long=first \\\n    second\nesc=a\\tb\\u00e9\\\\\nlatin=Caf\xe9\nempty=\nsp\\ ace=x\n");
  EXPECT_EQ(p.at("key1"), "value one");
  EXPECT_EQ(p.at("key2"), "two");
  EXPECT_EQ(p.at("key3"), "three");
  EXPECT_EQ(p.at("long"), "first second");
  EXPECT_EQ(p.at("esc"), "a\tb\xc3\xa9\\");
  EXPECT_EQ(p.at("latin"), "Caf\xc3\xa9");
  EXPECT_EQ(p.at("empty"), "");
  EXPECT_EQ(p.at("sp ace"), "x");
  EXPECT_EQ(p.size(), 8u);
}

TEST(Catalog, ReadsItsModelsAndRefusesWhatIsNotOne) {
  const std::string dir = testing::scratchDir("c");
  writeCatalog(dir + "/a.sh3f", {{"chair", "Kitchen", 45, 50, 90}, {"flat", "Office", 0, 10, 10}});
  const auto models = readCatalog(dir + "/a.sh3f");
  ASSERT_EQ(models.size(), 1u);  // a model without a width is left out
  EXPECT_EQ(models[0].id, "Test#chair");
  EXPECT_EQ(models[0].category, "Kitchen");
  EXPECT_EQ(models[0].creator, "Maker chair");
  EXPECT_EQ(models[0].model, "test/chair/chair.obj");
  EXPECT_FLOAT_EQ(models[0].width, 0.45f);
  EXPECT_FLOAT_EQ(models[0].height, 0.9f);
  EXPECT_EQ(models[0].license, "CC-BY 3.0 \xc2\xa9 Caf\xc3\xa9");
  EXPECT_EQ(models[0].catalogueName, "Test catalogue");
  // Not a zip, a truncated one, a zip without the properties: errors naming the file.
  writeFileAtomic(dir + "/junk.sh3f", std::string("PK\x03\x04 garbage", 12));
  EXPECT_ERROR_CONTAINS(readCatalog(dir + "/junk.sh3f"), dir + "/junk.sh3f");
  writeZip(dir + "/none.sh3f", {{"readme.txt", "hello"}});
  EXPECT_ERROR_CONTAINS(readCatalog(dir + "/none.sh3f"),
                        "not a furniture catalogue: no PluginFurnitureCatalog.properties");
  const std::string whole = readFile(dir + "/a.sh3f");
  // Cut inside the properties (the archive's first entry).
  ASSERT_EQ(whole.find("PluginFurnitureCatalog.properties"), 30u);
  writeFileAtomic(dir + "/cut.sh3f", whole.substr(0, 120));
  EXPECT_ERROR_CONTAINS(readCatalog(dir + "/cut.sh3f"), dir + "/cut.sh3f");
  // A folder: the bad catalogues are warnings naming them, the good one is read.
  std::vector<std::string> warnings;
  EXPECT_EQ(readCatalogs(dir, &warnings).size(), 1u);
  ASSERT_EQ(warnings.size(), 3u);
  EXPECT_NE(warnings[0].find("cut.sh3f"), std::string::npos);
  EXPECT_NE(warnings[1].find("junk.sh3f"), std::string::npos);
  EXPECT_NE(warnings[2].find("none.sh3f"), std::string::npos);
  // No catalogue at all: the package to install.
  EXPECT_ERROR_CONTAINS(readCatalogs(dir + "/nothing", nullptr), "sweethome3d-furniture");
  fs::create_directories(dir + "/empty");
  EXPECT_ERROR_CONTAINS(readCatalogs(dir + "/empty", nullptr), "sweethome3d-furniture");
}

TEST(Catalog, ExtractsOnlyTheFoldersAskedForAndNothingOutsideItsTarget) {
  const std::string dir = testing::scratchDir("x");
  writeZip(dir + "/a.sh3f", {{"m/one/one.obj", "1"},
                             {"m/one/skin.png", "2"},
                             {"m/two/two.obj", "3"},
                             {"m/one/../../escape.txt", "4"},
                             {"/abs.txt", "5"}});
  extractFolders(dir + "/a.sh3f", {"m/one/"}, dir + "/out");
  EXPECT_EQ(readFile(dir + "/out/m/one/one.obj"), "1");
  EXPECT_EQ(readFile(dir + "/out/m/one/skin.png"), "2");
  EXPECT_FALSE(fs::exists(dir + "/out/m/two"));
  EXPECT_FALSE(fs::exists(dir + "/escape.txt"));
  EXPECT_FALSE(fs::exists(dir + "/out/escape.txt"));
}

TEST(ModelSplit, HoldsOutAFifthOfDebiansCatalogueDeterministically) {
  if (!fs::is_directory(kDebianFurnitureDir))
    GTEST_SKIP() << "sweethome3d-furniture is not installed (scripts/setup.sh installs it)";
  const auto models = readCatalogs(kDebianFurnitureDir, nullptr);
  size_t heldOut = 0;
  for (const auto& m : models) {
    heldOut += isHeldOut(m);
    EXPECT_NE(inSet(m, ModelSet::Train), inSet(m, ModelSet::HeldOut));
    EXPECT_TRUE(inSet(m, ModelSet::All));
  }
  EXPECT_GT(models.size(), 700u);
  const double share = static_cast<double>(heldOut) / static_cast<double>(models.size());
  EXPECT_GT(share, 0.15);
  EXPECT_LT(share, 0.25);
  EXPECT_EQ(parseModelSet("heldout"), ModelSet::HeldOut);
  EXPECT_ERROR_CONTAINS(parseModelSet("test"), "train, heldout or all, not 'test'");
}

// Every placement in `scene` against the rules: inside its room's walls, clear of the other
// footprints, the doorways and the room's free centre; and the model's triangles inside its
// footprint (so the footprints are what the geometry occupies).
void expectPlacementsKeepTheRules(const LayoutSpec& L, const FurnishedScene& scene,
                                  const FurnitureLibrary& library, size_t shellTriangles) {
  const auto doors = doorwayKeepOuts(L);
  const float t = kWallThickness / 2, eps = 1e-4f;
  const auto openings = doorOpenings(L);
  for (size_t i = 0; i < scene.placements.size(); ++i) {
    const Placement& p = scene.placements[i];
    const CatalogModel& m = library.models()[p.model];
    const RoomSpec& r = L.rooms[static_cast<size_t>(p.room)];
    if (p.door >= 0) {  // a door, filling its opening, within the floor kept free before it
      const DoorOpening& o = openings[static_cast<size_t>(p.door)];
      EXPECT_TRUE(isDoor(m));
      EXPECT_FLOAT_EQ(p.x, o.x);
      EXPECT_FLOAT_EQ(p.z, o.z);
      EXPECT_NEAR(o.alongZ ? p.z1 - p.z0 : p.x1 - p.x0, o.width, 1e-5f);
      EXPECT_LE(o.alongZ ? p.x1 - p.x0 : p.z1 - p.z0, 0.2f + 1e-6f);
      const auto& k = doors[static_cast<size_t>(p.door)];
      EXPECT_TRUE(p.x0 >= k[0] && p.x1 <= k[2] && p.z0 >= k[1] && p.z1 <= k[3]);
      continue;
    }
    EXPECT_GE(p.x0, r.x0 + t - eps);
    EXPECT_LE(p.x1, r.x1 - t + eps);
    EXPECT_GE(p.z0, r.z0 + t - eps);
    EXPECT_LE(p.z1, r.z1 - t + eps);
    // Pieces on the floor stand apart, and so do the pieces on one host.
    for (size_t j = 0; j < i; ++j) {
      const Placement& q = scene.placements[j];
      if (q.host != p.host) continue;
      EXPECT_TRUE(p.x1 <= q.x0 || q.x1 <= p.x0 || p.z1 <= q.z0 || q.z1 <= p.z0)
          << "placements " << j << " and " << i << " overlap";
    }
    if (p.host >= 0) {  // small, on its host's top, within it
      ASSERT_LT(static_cast<size_t>(p.host), i);
      const Placement& h = scene.placements[static_cast<size_t>(p.host)];
      EXPECT_TRUE(isTabletop(m));
      EXPECT_TRUE(canHold(library.models()[h.model]));
      EXPECT_EQ(h.host, -1);
      EXPECT_FLOAT_EQ(p.y, h.y + library.models()[h.model].height);
      EXPECT_TRUE(p.x0 >= h.x0 && p.x1 <= h.x1 && p.z0 >= h.z0 && p.z1 <= h.z1);
      continue;
    }
    EXPECT_FALSE(isTabletop(m)) << m.id << " stands on the floor";
    EXPECT_FLOAT_EQ(p.y, m.elevation);
    for (const auto& d : doors)
      EXPECT_TRUE(p.x1 <= d[0] || d[2] <= p.x0 || p.z1 <= d[1] || d[3] <= p.z0)
          << "placement " << i << " stands before a door";
    const float cx = 0.5f * (r.x0 + r.x1), cz = 0.5f * (r.z0 + r.z1), c = kFreeCentre / 2;
    EXPECT_TRUE(p.x1 <= cx - c || cx + c <= p.x0 || p.z1 <= cz - c || cz + c <= p.z0)
        << "placement " << i << " takes the room's free centre";
    EXPECT_LE(m.height + m.elevation, L.height);
  }
  // The furniture's vertices, in placement order after the shell's.
  size_t v = 0;
  for (size_t k = 0; k < shellTriangles; ++k)
    v = std::max<size_t>(v, static_cast<size_t>(scene.mesh.triangles[k].maxCoeff()) + 1);
  for (const Placement& p : scene.placements) {
    const Mesh& m = *library.mesh(p.model);
    for (size_t k = 0; k < m.positions.size(); ++k, ++v) {
      const Eigen::Vector3f& q = scene.mesh.positions[v];
      ASSERT_GE(q.x(), p.x0 - eps);
      ASSERT_LE(q.x(), p.x1 + eps);
      ASSERT_GE(q.z(), p.z0 - eps);
      ASSERT_LE(q.z(), p.z1 + eps);
      ASSERT_GE(q.y(), p.y - eps);
      ASSERT_LE(q.y(), p.y + (p.door >= 0 ? kDoorHeight : library.models()[p.model].height) + eps);
      ASSERT_LE(q.y(), L.height);
    }
  }
  EXPECT_EQ(v, scene.mesh.positions.size());
}

TEST(Furnish, ModelsStandInTheirRoomsApartLeavingDoorwaysAndFloorFree) {
  const std::string dir = writeEverydayCatalog(testing::scratchDir("cat"));
  FurnitureLibrary library(optionsFor(dir));
  size_t placed = 0, onTops = 0, doors = 0;
  std::set<std::string> categories;
  for (uint64_t seed : {1, 2, 3}) {
    const LayoutSpec L = randomLayout("r", seed, 4);
    LayoutSpec shellSpec = L;
    shellSpec.furnished = true;
    const size_t shellTriangles = buildLayout(shellSpec).triangles.size();
    const FurnishedScene scene = furnishLayout(L, library);
    expectPlacementsKeepTheRules(L, scene, library, shellTriangles);
    for (const Placement& p : scene.placements) {
      if (p.door >= 0) continue;
      const RoomSpec& r = L.rooms[static_cast<size_t>(p.room)];
      EXPECT_EQ(library.models()[p.model].category, roomCategory(r));
      EXPECT_NE(library.models()[p.model].id, "Test#tower");
      categories.insert(roomCategory(r));
      // Each room's furniture covers at most kMaxCover of its floor.
    }
    std::map<int, float> cover;
    for (const Placement& p : scene.placements)
      if (p.host < 0) cover[p.room] += (p.x1 - p.x0) * (p.z1 - p.z0);
    for (const Placement& p : scene.placements) onTops += p.host >= 0, doors += p.door >= 0;
    for (const auto& [room, area] : cover) {
      const RoomSpec& r = L.rooms[static_cast<size_t>(room)];
      EXPECT_LE(area, kMaxCover * (r.x1 - r.x0 - kWallThickness) * (r.z1 - r.z0 - kWallThickness) +
                          1e-4f);
    }
    placed += scene.placements.size();
  }
  EXPECT_GE(placed, 12u);
  EXPECT_GE(onTops, 3u);
  EXPECT_GE(doors, 2u);
  EXPECT_GE(categories.size(), 3u);
}

TEST(Furnish, TheSameSeedGivesTheSameBytesAndAnotherSeedOthers) {
  const std::string dir = writeEverydayCatalog(testing::scratchDir("cat"));
  const std::string out = testing::scratchDir("out");
  for (const char* name : {"a", "b", "c"}) {
    FurnitureLibrary library(optionsFor(dir));  // a fresh library each time
    const uint64_t seed = std::string(name) == "c" ? 8 : 7;
    writeFurnishedScene(furnishLayout(randomLayout("x", seed, 3), library), out + "/" + name, "x");
  }
  const auto a = testing::fileTree(out + "/a"), b = testing::fileTree(out + "/b"),
             c = testing::fileTree(out + "/c");
  EXPECT_GT(a.size(), 3u);
  EXPECT_EQ(a, b);
  EXPECT_NE(a.at("x/x.obj"), c.at("x/x.obj"));
}

TEST(Furnish, ABrokenModelIsSkippedWithAWarningNamingItsEntry) {
  const std::string dir = testing::scratchDir("cat");
  auto models = everydayModels();
  for (auto& m : models)
    if (m.category == "Kitchen") m.broken = true;
  writeCatalog(dir + "/test.sh3f", models);
  FurnitureLibrary library(optionsFor(dir));
  LayoutSpec L = randomLayout("k", 5, 3);
  for (auto& r : L.rooms) r.kind = RoomKind::Kitchen;
  L.rooms[0].kind = RoomKind::Bedroom;
  const FurnishedScene scene = furnishLayout(L, library);
  ASSERT_FALSE(library.warnings.empty());
  EXPECT_NE(library.warnings[0].find("model skipped: test.sh3f#Test#m"), std::string::npos)
      << library.warnings[0];
  EXPECT_NE(library.warnings[0].find("(m"), std::string::npos);
  EXPECT_FALSE(scene.placements.empty());  // the bedroom's
  for (const Placement& p : scene.placements) {
    if (p.door < 0) {
      EXPECT_EQ(p.room, 0);
    }
  }
}

TEST(Furnish, HeldOutScenesUseOnlyHeldOutModelsAndTrainScenesNone) {
  const std::string dir = testing::scratchDir("cat");
  std::vector<FakeModel> many;
  for (int i = 0; i < 60; ++i) many.push_back({"p" + std::to_string(i), "Living room", 60, 50, 80});
  writeCatalog(dir + "/test.sh3f", many);
  LayoutSpec L = randomLayout("h", 3, 4);
  for (auto& r : L.rooms) r.kind = RoomKind::Living;
  std::set<std::string> used[2];
  for (ModelSet set : {ModelSet::Train, ModelSet::HeldOut}) {
    FurnitureLibrary library(optionsFor(dir, set));
    const FurnishedScene scene = furnishLayout(L, library);
    EXPECT_FALSE(scene.placements.empty());
    for (const Placement& p : scene.placements) {
      EXPECT_EQ(isHeldOut(library.models()[p.model]), set == ModelSet::HeldOut);
      used[set == ModelSet::HeldOut].insert(library.models()[p.model].id);
    }
  }
  for (const auto& id : used[0]) EXPECT_FALSE(used[1].count(id)) << id;
}

std::string capture(const std::string& command, int* status) {
  std::string out;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  char buf[4096];
  while (size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
  *status = pclose(p);
  return out;
}

const std::string kMakeScenes = std::string(PAIRCAST_BINARY_DIR) + "/tools/make_scenes";

TEST(MakeScenesFurnish, AMissingPackageOrABadOptionIsOneLine) {
  const std::string dir = testing::scratchDir("m");
  int status = 0;
  std::string out = capture(
      kMakeScenes + " --random 1 --furnish --catalogues " + dir + "/none --out " + dir + "/o",
      &status);
  EXPECT_NE(status, 0);
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
  EXPECT_NE(out.find("install Debian's sweethome3d-furniture package"), std::string::npos) << out;
  EXPECT_NE(out.find(dir + "/none"), std::string::npos) << out;
  out = capture(kMakeScenes + " --random 1 --models heldout --out " + dir + "/o", &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("--models and --catalogues need --furnish"), std::string::npos) << out;
}

TEST(MakeScenesFurnish, CreditsReachThePairsAndTheReport) {
  const std::string dir = writeEverydayCatalog(testing::scratchDir("cat"));
  const std::string out = testing::scratchDir("run");
  int status = 0;
  const std::string made = capture(kMakeScenes + " --random 2 --furnish --seed 4 --catalogues " +
                                       dir + " --out " + out + "/scenes",
                                   &status);
  ASSERT_EQ(status, 0) << made;
  for (const char* s : {"random_4_0", "random_4_1"}) {
    const auto credits = nlohmann::json::parse(readFile(out + "/scenes/" + s + "/credits.json"));
    EXPECT_EQ(credits["scene"], s);
    ASSERT_FALSE(credits["models"].empty());
    for (const auto& m : credits["models"]) {
      EXPECT_EQ(m["catalogue"], "test.sh3f");
      EXPECT_EQ(m["creator"], "Maker " + m["name"].get<std::string>());
      EXPECT_EQ(m["license"], "CC-BY 3.0 \xc2\xa9 Caf\xc3\xa9");
      EXPECT_GE(m["instances"].get<int>(), 1);
    }
  }
  GenerateConfig c;
  c.scenes = {out + "/scenes"};
  c.out = out + "/pairs";
  c.pairsPerScene = 3;
  c.pair.resolution = 48;
  c.progress = false;
  const auto summary = runGenerate(c);
  EXPECT_EQ(summary["pairs"], 6);
  const auto credits = nlohmann::json::parse(readFile(out + "/pairs/credits.json"));
  EXPECT_EQ(credits["scenes"].size(), 2u);
  EXPECT_EQ(credits["scenes"]["random_4_1"],
            nlohmann::json::parse(readFile(out + "/scenes/random_4_1/credits.json")));
  const std::string report = std::string(PAIRCAST_BINARY_DIR) + "/tools/dataset_report";
  const std::string printed = capture(report + " " + out + "/pairs", &status);
  ASSERT_EQ(status, 0) << printed;
  const std::string page = readFile(out + "/pairs/report.html");
  EXPECT_NE(page.find("<h2>Credits</h2>"), std::string::npos);
  EXPECT_NE(page.find("Maker m0"), std::string::npos);
}

TEST(MakeScenesFurnish, DebiansCataloguesFurnishAHomeThatGivesPairs) {
  if (!fs::is_directory(kDebianFurnitureDir))
    GTEST_SKIP() << "sweethome3d-furniture is not installed (scripts/setup.sh installs it)";
  const std::string out = testing::scratchDir("home");
  int status = 0;
  const std::string made =
      capture(kMakeScenes + " --random 1 --rooms 2 --furnish --seed 11 --out " + out, &status);
  ASSERT_EQ(status, 0) << made;
  const std::string obj = out + "/random_11_0/random_11_0.obj";
  const Scene scene = loadScene(obj);
  EXPECT_GT(scene.mesh.textures.size(), 5u);  // the models' own textures
  const auto credits = nlohmann::json::parse(readFile(out + "/random_11_0/credits.json"));
  EXPECT_GE(credits["models"].size(), 3u);
  for (const auto& m : credits["models"]) EXPECT_FALSE(m["license"].get<std::string>().empty());
  GenerateConfig c;
  c.scenes = {obj};
  c.out = out + "/pairs";
  c.pairsPerScene = 4;
  c.pair.resolution = 64;
  c.progress = false;
  EXPECT_EQ(runGenerate(c)["pairs"], 4);
}

}  // namespace
}  // namespace paircast
