// The render_view command: its interface (kept stable for users) and its errors.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "util/camera.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/image_io.h"

namespace paircast {
namespace {

struct CliRun {
  int code;
  std::string stderrText;
};

CliRun renderView(const std::string& args, const std::string& dir) {
  const std::string err = dir + "/stderr.txt";
  const std::string cmd =
      std::string(PAIRCAST_BINARY_DIR) + "/tools/render_view " + args + " > /dev/null 2> " + err;
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, readFile(err)};
}

const std::string room() {
  return testing::sourceDir() + "/scenes/room/room.obj";
}

TEST(RenderViewCli, RendersOneViewFromACameraFile) {
  const std::string dir = testing::scratchDir("one");
  Camera cam = Camera::fromHfov(40, 30, 70);
  cam.lookAt({1, 1.5, 1}, {4, 1.2, 3}, {0, 1, 0});
  writeCameraJson(dir + "/cam.json", cam);
  const CliRun r = renderView("--scene " + room() + " --camera " + dir + "/cam.json --rgb " + dir +
                                  "/v.png --depth " + dir + "/v.exr --normals " + dir + "/n.exr",
                              dir);
  ASSERT_EQ(r.code, 0) << r.stderrText;
  const Image8 rgb = readImage8(dir + "/v.png");
  EXPECT_EQ(rgb.width, 40);
  EXPECT_EQ(rgb.height, 30);
  const ImageF depth = readImageF(dir + "/v.exr");
  EXPECT_EQ(depth.channels, 1);
  for (float d : depth.data) EXPECT_GT(d, 0.0f);  // inside a closed room every pixel hits
  EXPECT_EQ(readImageF(dir + "/n.exr").channels, 3);
}

TEST(RenderViewCli, RandomViewsComeWithTheirCameras) {
  const std::string dir = testing::scratchDir("random");
  const CliRun r =
      renderView("--scene " + room() + " --random 2 --resolution 32 --out " + dir + "/o", dir);
  ASSERT_EQ(r.code, 0) << r.stderrText;
  for (const char* f : {"000000.png", "000000_depth.exr", "000000.json", "000001.png"})
    EXPECT_TRUE(std::filesystem::exists(dir + "/o/" + f)) << f;
  const Camera c = readCameraJson(dir + "/o/000001.json");
  EXPECT_EQ(c.width, 32);
}

TEST(RenderViewCli, BadInputGivesOneLineNamingTheFile) {
  const std::string dir = testing::scratchDir("bad");
  std::ofstream(dir + "/cam.json") << "{\"camera_intrinsics\": 3}";
  struct Case {
    std::string args, fragment;
  };
  const Case cases[] = {
      {"--scene " + dir + "/missing.glb --camera " + dir + "/cam.json --rgb " + dir + "/x.png",
       "missing.glb"},
      {"--scene " + room() + " --camera " + dir + "/cam.json --rgb " + dir + "/x.png", "cam.json"},
      {"--scene " + room() + " --camera " + dir + "/nocam.json --rgb " + dir + "/x.png",
       "nocam.json"},
      {"--scene " + room() + " --rgb " + dir + "/x.png", "--camera"},
  };
  for (const auto& c : cases) {
    const CliRun r = renderView(c.args, dir);
    EXPECT_EQ(r.code, 1) << c.args;
    EXPECT_NE(r.stderrText.find(c.fragment), std::string::npos) << r.stderrText;
    EXPECT_EQ(std::count(r.stderrText.begin(), r.stderrText.end(), '\n'), 1) << r.stderrText;
  }
  EXPECT_NE(renderView("--scene " + room() + " --up q --random 1 --out " + dir, dir).code, 0);
}

}  // namespace
}  // namespace paircast
