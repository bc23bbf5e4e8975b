#include "model/reconstruct.h"

#include <gtest/gtest.h>

#include <fstream>

#include "model/checkpoint.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace {

struct Fixture {
  std::string dir, ckpt, a, b;
};

Fixture makeFixture(const std::string& name) {
  Fixture f;
  f.dir = testing::scratchDir(name);
  CroCoConfig c = presetConfig("tiny");
  c.img_size = 64;
  CroCoNet net(c);
  f.ckpt = f.dir + "/tiny.pth";
  saveCheckpoint(f.ckpt, net, 0);
  Image8 img(80, 80, 3);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<uint8_t>(i * 7);
  f.a = f.dir + "/a.jpg";  // JPEG: the trainer-only build reads no other format
  f.b = f.dir + "/b.jpg";
  writeImage(f.a, img);
  writeImage(f.b, img);
  return f;
}

TEST(Reconstruct, GridPredictionAndMaskFile) {
  const Fixture f = makeFixture("grid");
  std::ofstream mask(f.dir + "/mask.txt");
  for (int i = 0; i < 16; ++i) mask << (i % 2) << (i % 4 == 3 ? "\n" : " ");
  mask.close();
  ReconstructOptions o;
  o.checkpoint = f.ckpt;
  o.image1 = f.a;
  o.image2 = f.b;
  o.maskFile = f.dir + "/mask.txt";
  const Reconstruction r = reconstruct(o);
  EXPECT_EQ(r.grid.width, 4 * 64 + 3 * 4);
  EXPECT_EQ(r.grid.height, 64);
  EXPECT_EQ(r.prediction.sizes(), (std::vector<int64_t>{16, 768}));
  // The visible patches of the reconstruction are the input's: patch (0, 0) is visible.
  const int S = 64, gap = 4;
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(r.grid.pixel(2 * (S + gap) + 3, 3)[c], r.grid.pixel(3 * (S + gap) + 3, 3)[c], 1);
  writeNpy(f.dir + "/p.npy", r.prediction);
  const std::string npy = readFile(f.dir + "/p.npy");
  EXPECT_EQ(npy.substr(1, 5), "NUMPY");
  EXPECT_NE(npy.find("'shape': (16,768)"), std::string::npos);
  EXPECT_EQ(npy.size() % 16, (128 + 16 * 768 * 4) % 16);
}

TEST(Reconstruct, BadInputNamesTheFile) {
  const Fixture f = makeFixture("bad");
  ReconstructOptions o;
  o.checkpoint = f.ckpt;
  o.image1 = f.a;
  o.image2 = f.dir + "/missing.png";
  EXPECT_ERROR_CONTAINS(reconstruct(o), f.dir + "/missing.png: no such file");
  o.image2 = f.b;
  std::ofstream(f.dir + "/short.txt") << "1 0 1";
  o.maskFile = f.dir + "/short.txt";
  try {
    reconstruct(o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("short.txt"), std::string::npos);
  }
  // Flags that contradict the checkpoint's shapes are refused.
  o.maskFile.clear();
  CroCoConfig wrong = presetConfig("small");
  wrong.img_size = 64;
  o.config = wrong;
  try {
    reconstruct(o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("patch_embed.proj.weight"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace paircast
