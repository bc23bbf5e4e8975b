// generate_pairs --from-metadata and habitat's conventions (docs/conventions.md, "Habitat").
#include "dataset/replay.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "dataset/generate_job.h"
#include "dataset/habitat_frame.h"
#include "dataset/test_scenes.h"
#include "test_errors.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

TEST(HabitatFrame, IdentityQuaternionLooksDownMinusZWithYUp) {
  const Eigen::Matrix3d R = cameraRotationFromHabitat({1, 0, 0, 0});
  EXPECT_TRUE(R.col(2).isApprox(Eigen::Vector3d(0, 0, -1)));  // OpenCV forward
  EXPECT_TRUE(R.col(1).isApprox(Eigen::Vector3d(0, -1, 0)));  // OpenCV down
  EXPECT_TRUE(R.col(0).isApprox(Eigen::Vector3d(1, 0, 0)));
  EXPECT_ERROR_CONTAINS(cameraRotationFromHabitat({0, 0, 0, 0}),
                        "camera orientation is not a rotation quaternion");
}

TEST(HabitatFrame, ZUpStagesAreRotatedIntoHabitatsYUpWorld) {
  const Eigen::Matrix3d S = sceneFromHabitat(UpAxis::Z);
  EXPECT_TRUE((S * Eigen::Vector3d(0, 1, 0)).isApprox(Eigen::Vector3d(0, 0, 1)));   // up
  EXPECT_TRUE((S * Eigen::Vector3d(0, 0, -1)).isApprox(Eigen::Vector3d(0, 1, 0)));  // front
  EXPECT_TRUE(sceneFromHabitat(UpAxis::Y).isIdentity());
  EXPECT_DOUBLE_EQ(S.determinant(), 1.0);
}

TEST(HabitatFrame, QuaternionsRoundTripToTheSameRotation) {
  Rng rng(3);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d axis =
        Eigen::Vector3d(rng.normal(), rng.normal(), rng.normal()).normalized();
    const Eigen::Matrix3d R(Eigen::AngleAxisd(rng.uniform(-3.1, 3.1), axis));
    const HabitatQuaternion q = habitatQuaternion(R);
    EXPECT_TRUE(cameraRotationFromHabitat(q).isApprox(R, 1e-12));
    // The JSON text of a quaternion reads back to the same doubles: replay is exact.
    const auto back = nlohmann::json::parse(nlohmann::json(q).dump()).get<HabitatQuaternion>();
    ASSERT_EQ(back, q) << i;
  }
}

// CroCo metadata with one sample: habitat poses at (2.35, 0.6, 0), looking down -z (identity)
// and +z (180 degrees about y).
nlohmann::json crocoMetadata(const std::string& scene) {
  return {{"scene", scene},
          {"resolution", {64, 64}},
          {"hfov", 60},
          {"generate_depth", true},
          {"multiviews",
           {{"00000007",
             {{"positions", {{2.35, 0.6, 0.0}, {2.35, 0.6, 0.0}}},
              {"orientations", {{1, 0, 0, 0}, {0, 0, 1, 0}}}}}}}};
}

float centreDepth(const std::string& exr) {
  const ImageF d = readImageF(exr);
  return d.data[static_cast<size_t>(d.height / 2) * d.width + d.width / 2];
}

// In the room, looking down habitat -z from z = 0 meets the wall at 2.5 m; looking up +z meets
// the cabinet's face at 1.8 m. The z-up copy of the room must give the same depths.
TEST(Replay, CrocoPosesLandInTheSceneFrameForBothUpAxes) {
  for (bool zUp : {false, true}) {
    const std::string dir = testing::scratchDir(zUp ? "replay_z" : "replay_y");
    testing::writeBoxesObj(dir + "/room.obj", testing::roomBoxes(), zUp);
    makeDirs(dir + "/meta/room");
    writeFileAtomic(dir + "/meta/room/metadata.json", crocoMetadata("scenes/room.obj").dump());
    fs::create_directories(dir + "/root/scenes");
    fs::copy_file(dir + "/room.obj", dir + "/root/scenes/room.obj");
    ReplayConfig c;
    c.metadata = {dir + "/meta"};
    c.sceneRoot = dir + "/root";
    c.out = dir + "/out";
    c.load.up = zUp ? UpAxis::Z : UpAxis::Y;
    c.progress = false;
    const nlohmann::json summary = runReplay(c);
    ASSERT_EQ(summary["samples"], 1) << summary.dump();
    EXPECT_NEAR(centreDepth(dir + "/out/room/00000007_1_depth.exr"), 2.5f, 0.03f) << zUp;
    EXPECT_NEAR(centreDepth(dir + "/out/room/00000007_2_depth.exr"), 1.8f, 0.03f) << zUp;
    EXPECT_EQ(readFile(dir + "/out/pairs.txt"), "room/00000007_1.jpeg room/00000007_2.jpeg\n");
  }
}

TEST(Replay, OwnMetadataReplaysToTheSameBytes) {
  const std::string dir = testing::scratchDir("replay_own");
  testing::writeBoxesObj(dir + "/room.obj", testing::roomBoxes(), true);
  GenerateConfig g;
  g.scenes = {dir + "/room.obj"};
  g.out = dir + "/gen";
  g.pairsPerScene = 4;
  g.pair.resolution = 64;
  g.pair.views = 3;
  g.load.up = UpAxis::Z;
  g.shards = false;
  g.croco = true;
  g.saveDepth = true;
  g.progress = false;
  ASSERT_EQ(runGenerate(g)["pairs"], 4);
  ReplayConfig c;
  c.metadata = {dir + "/gen/room/metadata.json"};
  c.out = dir + "/replay";
  c.progress = false;  // the up axis comes from the metadata ("up": "z")
  ASSERT_EQ(runReplay(c)["samples"], 4);
  int compared = 0;
  for (const auto& e : fs::directory_iterator(dir + "/gen/room")) {
    const std::string name = e.path().filename().string();
    if (name == "metadata.json") continue;
    ASSERT_TRUE(fs::exists(dir + "/replay/room/" + name)) << name;
    EXPECT_EQ(readFile(e.path().string()), readFile(dir + "/replay/room/" + name)) << name;
    ++compared;
  }
  EXPECT_EQ(compared, 4 * 3 * 3);  // jpeg, depth, camera of 3 views
  EXPECT_EQ(readFile(dir + "/gen/pairs.txt"), readFile(dir + "/replay/pairs.txt"));
}

TEST(Replay, ScenePathsAreRemappedAndBasisGlbFallsBackToGlb) {
  const std::string dir = testing::scratchDir("replay_paths");
  fs::create_directories(dir + "/root/hm3d/00800-abc");
  std::ofstream(dir + "/root/hm3d/00800-abc/abc.basis.glb") << "x";
  std::ofstream(dir + "/root/hm3d/00800-abc/abc.glb") << "x";
  const std::string meta = dir + "/m/metadata.json";
  EXPECT_EQ(
      resolveScenePath("/data/scene_datasets/hm3d/00800-abc/abc.basis.glb", meta, dir + "/root"),
      dir + "/root/hm3d/00800-abc/abc.glb");
  EXPECT_EQ(resolveScenePath("hm3d/00800-abc/abc.basis.glb", meta, dir + "/root"),
            dir + "/root/hm3d/00800-abc/abc.glb");
  fs::remove(dir + "/root/hm3d/00800-abc/abc.glb");
  EXPECT_EQ(resolveScenePath("hm3d/00800-abc/abc.basis.glb", meta, dir + "/root"),
            dir + "/root/hm3d/00800-abc/abc.basis.glb");
  EXPECT_FALSE(resolveScenePath("hm3d/none.glb", meta, dir + "/root").has_value());
}

TEST(Replay, BadMetadataIsSkippedWithItsFileNamedAndNothingReplayedFails) {
  const std::string dir = testing::scratchDir("replay_bad");
  testing::writeBoxesObj(dir + "/room.obj", testing::roomBoxes());
  makeDirs(dir + "/m/a");
  makeDirs(dir + "/m/b");
  makeDirs(dir + "/m/c");
  writeFileAtomic(dir + "/m/a/metadata.json", "{\"scene\": \"missing.glb\", \"multiviews\": {}}");
  writeFileAtomic(dir + "/m/b/metadata.json", "{not json");
  nlohmann::json nan = crocoMetadata(dir + "/room.obj");
  nan["multiviews"]["00000007"]["orientations"][0] = {0, 0, 0, 0};
  writeFileAtomic(dir + "/m/c/metadata.json", nan.dump());
  ReplayConfig c;
  c.metadata = {dir + "/m"};
  c.out = dir + "/out";
  c.progress = false;
  const nlohmann::json s = runReplay(c);
  ASSERT_EQ(s["skipped"].size(), 3u);
  EXPECT_NE(s["skipped"][0]["reason"].get<std::string>().find("missing.glb' was not found"),
            std::string::npos);
  EXPECT_NE(s["skipped"][1]["reason"].get<std::string>().find("m/b/metadata.json"),
            std::string::npos);
  EXPECT_NE(s["skipped"][2]["reason"].get<std::string>().find("not a rotation quaternion"),
            std::string::npos);
  const std::string tool = std::string(PAIRCAST_BINARY_DIR) + "/tools/generate_pairs";
  EXPECT_EQ(testing::waitProcess(testing::spawnProcess(
                {tool, "--from-metadata", dir + "/m", "--out", dir + "/o2", "--quiet"})),
            1);
  EXPECT_NE(testing::waitProcess(testing::spawnProcess(
                {tool, "--from-metadata", dir + "/nothing", "--out", dir + "/o3"})),
            0);
}

}  // namespace
}  // namespace paircast
