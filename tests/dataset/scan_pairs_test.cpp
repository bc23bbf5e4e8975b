// Pairs from scans in the scan datasets' own formats (make_scenes --scan), through the real
// generate_pairs command, checked against CroCo's rules: cameras 1.2-1.8 m above the floor and
// at least 70 % of pixels with depth.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "render/scan_scene.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"
#include "util/image_io.h"

namespace paircast {
namespace {
namespace fs = std::filesystem;

TEST(ScanPairs, EveryScanKindGivesPairsWithCrocosHeightsAndValidPixels) {
  const std::string dir = testing::scratchDir("scan_pairs");
  std::vector<std::string> args = {std::string(PAIRCAST_BINARY_DIR) + "/tools/generate_pairs",
                                   "--scenes"};
  for (ScanKind kind : {ScanKind::ScanNet, ScanKind::Replica, ScanKind::Matterport}) {
    ScanSpec spec;
    spec.kind = kind;
    spec.triangles = 80'000;
    args.push_back(writeScan(spec, dir + "/scans"));
  }
  const std::vector<std::string> rest = {"--up",
                                         "z",
                                         "--out",
                                         dir + "/out",
                                         "--pairs-per-scene",
                                         "3",
                                         "--resolution",
                                         "64",
                                         "--format",
                                         "croco",
                                         "--save-depth",
                                         "--jobs",
                                         "2",
                                         "--seed",
                                         "1"};
  args.insert(args.end(), rest.begin(), rest.end());
  ASSERT_EQ(testing::runProcess(args), 0);
  int scenes = 0;
  for (const auto& entry : fs::directory_iterator(dir + "/out")) {
    // One folder per scene (Replica's is named after its file, "mesh"), beside .paircast/.
    if (!entry.is_directory() || entry.path().filename().string()[0] == '.') continue;
    ++scenes;
    for (int pair = 0; pair < 3; ++pair) {
      for (int view = 1; view <= 2; ++view) {
        char stem[32];
        std::snprintf(stem, sizeof stem, "%08d_%d", pair, view);
        const std::string base = (entry.path() / stem).string();
        const auto camera = nlohmann::json::parse(readFile(base + "_camera_params.json"));
        // The scans' floors are at z = 0 (within millimetres of noise), and no floor is raised.
        const double height = camera["t_cam2world"][2].get<double>();
        EXPECT_GE(height, 1.2 - 0.02) << base;
        EXPECT_LE(height, 1.8 + 0.02) << base;
        const ImageF depth = readImageF(base + "_depth.exr");
        size_t valid = 0;
        for (float d : depth.data) valid += d > 0.0f;
        EXPECT_GE(valid, depth.data.size() * 7 / 10) << base;
      }
    }
  }
  EXPECT_EQ(scenes, 3);
}

}  // namespace
}  // namespace paircast
