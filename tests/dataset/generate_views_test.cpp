// The generation engine: candidate screening, N-view samples, co-visibility masks, the
// journal, and the command's exit status.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "covis/covisibility.h"
#include "dataset/generate_job.h"
#include "dataset/pair_generator.h"
#include "dataset/shard.h"
#include "dataset/test_scenes.h"
#include "test_errors.h"
#include "test_files.h"
#include "test_paths.h"
#include "test_process.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

std::string writeRoom(const std::string& dir) {
  const std::string path = dir + "/room.obj";
  testing::writeBoxesObj(path, testing::roomBoxes());
  return path;
}

GenerateConfig config(const std::string& scene, const std::string& out, int pairs) {
  GenerateConfig c;
  c.scenes = {scene};
  c.out = out;
  c.pairsPerScene = pairs;
  c.pair.resolution = 64;
  c.shardSize = 1000;
  c.jobs = 2;
  c.progress = false;
  return c;
}

std::string tool() {
  return std::string(PAIRCAST_BINARY_DIR) + "/tools/generate_pairs";
}

// The two-sample Kolmogorov-Smirnov statistic: the largest gap between the empirical CDFs.
double ksStatistic(std::vector<double> a, std::vector<double> b) {
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  double d = 0;
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const double x = std::min(a[i], b[j]);
    while (i < a.size() && a[i] <= x) ++i;
    while (j < b.size() && b[j] <= x) ++j;
    d = std::max(d, std::abs(double(i) / a.size() - double(j) / b.size()));
  }
  return d;
}

// Covis of the accepted pairs 0..n-1 of one generator.
std::vector<double> acceptedCovis(const Scene& scene, const RayCaster& caster,
                                  const ViewpointSampler& sampler, const PairOptions& o, int n,
                                  size_t* screened = nullptr, size_t* falseRejections = nullptr) {
  const PairGenerator gen(scene, caster, sampler, o);
  std::vector<double> out;
  for (int i = 0; i < n; ++i) {
    GenerationCost cost;
    const auto s = gen.generate(11, i, &cost);
    if (!s) continue;
    out.push_back(s->covis[1].covis);
    if (screened) *screened += cost.screened;
    if (falseRejections) *falseRejections += cost.falseRejections;
  }
  return out;
}

// The test room with its BVH and sampler, for PairGenerator.
struct Room {
  explicit Room(const std::string& name)
      : scene(loadRoom(name)), caster(scene.mesh), sampler(scene, caster, {}) {}
  static Scene loadRoom(const std::string& name) {
    Scene s = loadScene(writeRoom(testing::scratchDir(name)), {});
    s.name = "room";
    return s;
  }
  std::vector<double> accepted(const PairOptions& o, int n, size_t* screened = nullptr,
                               size_t* falseRejections = nullptr) const {
    return acceptedCovis(scene, caster, sampler, o, n, screened, falseRejections);
  }
  Scene scene;
  RayCaster caster;
  ViewpointSampler sampler;
};

TEST(Screening, KeepsCrocosCovisDistribution) {
  const Room room("screen_ks");
  PairOptions o;
  o.resolution = 128;
  o.keepDepth = false;
  o.screenResolution = 0;
  const std::vector<double> plain = room.accepted(o, 300);
  o.screenResolution = 16;  // the default at 128: screened at 16, then at 32
  size_t screened = 0;
  const std::vector<double> fast = room.accepted(o, 300, &screened);
  ASSERT_GE(plain.size(), 280u);
  ASSERT_GE(fast.size(), 280u);
  EXPECT_GT(screened, 300u) << "screening turned almost nothing down: the test tests nothing";
  // Critical value of the two-sample test at alpha = 0.01: below it, p >= 0.01.
  const double n = plain.size(), m = fast.size();
  const double critical = 1.628 * std::sqrt((n + m) / (n * m));
  EXPECT_LT(ksStatistic(plain, fast), critical);
  // A screen that turns down everything in the band shifts the distribution: the test can fail.
  o.minCovis = 0.5;
  o.screenCovisMargin = 0;
  PairOptions biased = o;
  biased.accept = nullptr;
  biased.maxCovis = 0.6;  // accepted covis now <= 0.6: a different distribution
  const std::vector<double> shifted = room.accepted(biased, 300);
  EXPECT_GT(ksStatistic(plain, shifted), critical);
}

TEST(Screening, StagesDoubleUpToAQuarterOfTheOutputWithMarginsBySide) {
  PairOptions o;  // 256: auto 16, then 32 and 64
  const std::vector<ScreenStageSpec> s = screenStages(o);
  ASSERT_EQ(s.size(), 3u);
  EXPECT_EQ(s[0].side, 16);
  EXPECT_EQ(s[1].side, 32);
  EXPECT_EQ(s[2].side, 64);
  // 32 and 64 take the two margins; 16 two and a half times the 32 one.
  EXPECT_DOUBLE_EQ(s[1].margin, o.screenCovisMargin);
  EXPECT_NEAR(s[2].margin, o.screenFineMargin, 1e-12);
  EXPECT_NEAR(s[0].margin, 2.5 * o.screenCovisMargin, 1e-12);
  o.resolution = 224;  // CroCo's: 16 and 32 (4 x 64 > 224), the last at the 32x32 margin
  ASSERT_EQ(screenStages(o).size(), 2u);
  EXPECT_DOUBLE_EQ(screenStages(o).back().margin, o.screenCovisMargin);
  o.resolution = 512;  // 32, 64, 128
  EXPECT_EQ(screenStages(o).front().side, 32);
  EXPECT_EQ(screenStages(o).back().side, 128);
  EXPECT_NEAR(screenStages(o).back().margin, o.screenFineMargin / 2, 1e-12);  // half per doubling
  o.screenResolution = 48;                                                    // at 512: 48 and 96
  EXPECT_EQ(screenStages(o).size(), 2u);
  o.resolution = 128;
  o.screenResolution = 24;
  o.screenCovisMargin = 0.0;  // a zero margin applies as given, no division by zero
  ASSERT_EQ(screenStages(o).size(), 1u);
  EXPECT_EQ(screenStages(o)[0].margin, 0.0);
  o.screenResolution = 0;
  EXPECT_TRUE(screenStages(o).empty());
  o.screenResolution = kAutoScreen;
  o.resolution = 48;  // off below 64
  EXPECT_TRUE(screenStages(o).empty());
}

TEST(Screening, MeanWorldPointIsThePerPixelMean) {
  // meanWorldPoint sums three numbers per pixel; the definition sums a back-projected point.
  Camera cam = Camera::fromHfov(37, 29, 70);
  cam.lookAt({0.3, 1.2, -0.4}, {2, 0.5, 3}, {0, 1, 0});
  ImageF depth(37, 29, 1, 0.0f);
  Rng rng(3);
  for (float& d : depth.data) d = rng.uniform(0, 1) < 0.3 ? 0.0f : rng.uniform(0.5, 9);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int n = 0;
  for (int v = 0; v < depth.height; ++v) {
    for (int u = 0; u < depth.width; ++u) {
      const float d = depth.data[static_cast<size_t>(v) * depth.width + u];
      if (d <= 0) continue;
      sum += cam.R_cam2world * (d * cam.rayCamera(u + 0.5, v + 0.5)) + cam.t_cam2world;
      ++n;
    }
  }
  EXPECT_LT((meanWorldPoint(cam, depth) - sum / n).norm(), 1e-9);
  EXPECT_THROW(meanWorldPoint(cam, ImageF(37, 29, 1, 0.0f)), std::exception);  // no valid pixel
}

TEST(Screening, AnIndexWithoutASampleStillReportsWhatItSpent) {
  // A band no pair reaches: the index ends without a sample, yet it rendered, screened and
  // sampled poses; the job adds that to its time split and screening counts.
  const Room room("no_sample_spent");
  PairOptions o;
  o.resolution = 128;
  o.minCovis = 0.999;
  o.maxAttempts = 10;
  o.maxReferences = 2;
  const PairGenerator gen(room.scene, room.caster, room.sampler, o);
  GenerationCost spent;  // run statistics, apart from the sample
  EXPECT_FALSE(gen.generate(3, 0, &spent).has_value());
  EXPECT_GT(spent.candidateCovis.size(), 0u);
  EXPECT_GT(spent.screened, 0u);
  EXPECT_GT(spent.screenSeconds, 0.0);
  EXPECT_GE(spent.totalSeconds, spent.renderSeconds + spent.screenSeconds + spent.covisSeconds);
  // With a sample, `spent` holds what making it cost, and the sample records its candidates.
  o.minCovis = 0.5;
  const PairGenerator ok(room.scene, room.caster, room.sampler, o);
  const std::optional<PairSample> sample = ok.generate(3, 0, &spent);
  ASSERT_TRUE(sample.has_value());
  EXPECT_EQ(spent.candidateCovis, sample->candidateCovis);
  EXPECT_GT(spent.renderSeconds, 0.0);
  EXPECT_GE(spent.totalSeconds, spent.renderSeconds + spent.screenSeconds + spent.covisSeconds);
}

TEST(Screening, AuditChangesNoOutputAndCountsFalseRejections) {
  const Room room("screen_audit");
  PairOptions o;
  o.resolution = 96;
  o.screenResolution = 24;
  o.screenCovisMargin = 0.0;  // no margin: some candidates in the band are turned down
  const std::vector<double> a = room.accepted(o, 60);
  o.auditScreening = true;
  size_t screened = 0, falseRejections = 0;
  const std::vector<double> b = room.accepted(o, 60, &screened, &falseRejections);
  EXPECT_EQ(a, b);
  EXPECT_GT(falseRejections, 0u) << "without a margin, the estimate must miss some";
  EXPECT_LT(falseRejections, screened);
}

TEST(Screening, FineStageTurnsDownMoreWithTheSameOutput) {
  const Room room("screen_fine");
  PairOptions o;
  o.resolution = 256;
  o.keepDepth = false;
  o.screenResolution = 32;   // then 64
  o.screenFineMargin = 1.0;  // passes everything: one stage in effect
  o.auditScreening = true;
  size_t coarse = 0, fine = 0, coarseMisses = 0, fineMisses = 0;
  const std::vector<double> a = room.accepted(o, 60, &coarse, &coarseMisses);
  o.screenFineMargin = PairOptions{}.screenFineMargin;
  const std::vector<double> b = room.accepted(o, 60, &fine, &fineMisses);
  EXPECT_GT(fine, coarse) << "the second stage turned nothing down";
  // The random stream does not depend on rendering: a second stage that turns down no view
  // that would pass leaves the same pairs.
  EXPECT_EQ(fineMisses, coarseMisses);
  EXPECT_EQ(a, b);
}

TEST(MultiView, SamplesHaveNViewsInTheBandWithView1) {
  const std::string dir = testing::scratchDir("views3");
  GenerateConfig c = config(writeRoom(dir), dir + "/out", 5);
  c.pair.views = 3;
  c.croco = true;
  c.saveDepth = true;
  const nlohmann::json summary = runGenerate(c);
  ASSERT_EQ(summary["pairs"].get<int>(), 5);
  // CroCo layout: three images per sample, the (1, k) pairs, a 3x3 visibility matrix.
  const std::string scene = dir + "/out/room/";
  for (int k = 1; k <= 3; ++k) {
    EXPECT_TRUE(fs::exists(scene + "00000004_" + std::to_string(k) + ".jpeg"));
    EXPECT_TRUE(fs::exists(scene + "00000004_" + std::to_string(k) + "_depth.exr"));
  }
  const std::string pairs = readFile(dir + "/out/pairs.txt");
  EXPECT_NE(pairs.find("room/00000000_1.jpeg room/00000000_3.jpeg\n"), std::string::npos);
  EXPECT_EQ(std::count(pairs.begin(), pairs.end(), '\n'), 10);
  const auto meta = nlohmann::json::parse(readFile(scene + "metadata.json"));
  EXPECT_EQ(meta["views_count"], 3);
  const auto& mv = meta["multiviews"]["00000002"];
  ASSERT_EQ(mv["positions"].size(), 3u);
  ASSERT_EQ(mv["pairwise_visibility_ratios"].size(), 3u);
  for (int k = 1; k < 3; ++k) EXPECT_GE(mv["covisibility_ratios"][k].get<double>(), 0.5);
  // The matrix's off-diagonal entries are v_ij, so min(v_0k, v_k0) is the covis of view k.
  const auto& m = mv["pairwise_visibility_ratios"];
  for (int k = 1; k < 3; ++k)
    EXPECT_DOUBLE_EQ(std::min(m[0][k].get<double>(), m[k][0].get<double>()),
                     mv["covisibility_ratios"][k].get<double>());
  // Shards: .1.jpg to .3.jpg, and a record of three cameras.
  size_t n = readShard(dir + "/out/pairs-000000.tar", [&](ShardSample&& s) {
    EXPECT_EQ(s.jpeg.size(), 3u);
    EXPECT_EQ(s.depthExr.size(), 3u);
    EXPECT_EQ(parseSampleRecord(s.record, s.key).camera.size(), 3u);
  });
  EXPECT_EQ(n, 5u);
}

TEST(MultiView, OneViewSamplesAreSingleValidViews) {
  const std::string dir = testing::scratchDir("views1");
  GenerateConfig c = config(writeRoom(dir), dir + "/out", 3);
  c.pair.views = 1;
  const nlohmann::json summary = runGenerate(c);
  EXPECT_EQ(summary["pairs"].get<int>(), 3);
  readShard(dir + "/out/pairs-000000.tar", [&](ShardSample&& s) {
    EXPECT_EQ(s.jpeg.size(), 1u);
    EXPECT_GE(s.record["valid_fractions"][0].get<double>(), 0.7);
  });
}

// Share of 255 over the valid pixels of `depth`.
double maskShare(const Image8& mask, const ImageF& depth) {
  size_t valid = 0, seen = 0;
  for (size_t p = 0; p < depth.data.size(); ++p) {
    if (!(depth.data[p] > 0)) continue;
    ++valid;
    seen += mask.data[p] == 255;
  }
  return valid ? double(seen) / valid : 0.0;
}

TEST(CovisMasks, ShareOf255EqualsVisibility) {
  const std::string dir = testing::scratchDir("masks");
  for (int views : {2, 3}) {
    GenerateConfig c = config(writeRoom(dir), dir + "/out" + std::to_string(views), 4);
    c.pair.views = views;
    c.pair.covisMasks = true;
    c.saveDepth = true;
    c.croco = true;
    runGenerate(c);
    const std::string stem = c.out + "/room/00000001";
    const auto meta = nlohmann::json::parse(readFile(c.out + "/room/metadata.json"));
    const auto& m = meta["multiviews"]["00000001"]["pairwise_visibility_ratios"];
    std::vector<Image8> mask;
    std::vector<ImageF> depth;
    for (int k = 1; k <= views; ++k) {
      mask.push_back(readImage8(stem + "_" + std::to_string(k) + "_covis.png", 0));
      depth.push_back(readImageF(stem + "_" + std::to_string(k) + "_depth.exr"));
      ASSERT_EQ(mask.back().channels, 1);
      for (uint8_t v : mask.back().data) ASSERT_TRUE(v == 0 || v == 255);
    }
    // View k > 1: its pixels seen by view 1, so the share is v_k1.
    for (int k = 1; k < views; ++k)
      EXPECT_NEAR(maskShare(mask[k], depth[k]), m[k][0].get<double>(), 1e-9);
    if (views == 2) {
      EXPECT_NEAR(maskShare(mask[0], depth[0]), m[0][1].get<double>(), 1e-9);
    } else {  // seen by at least one other view
      EXPECT_GE(maskShare(mask[0], depth[0]) + 1e-9,
                std::max(m[0][1].get<double>(), m[0][2].get<double>()));
    }
  }
}

TEST(CovisMasks, MaskMatchesCountVisible) {
  // An analytic pair: two cameras facing a wall, one shifted.
  ImageF d1(32, 32, 1, 3.0f), d2(32, 32, 1, 3.0f);
  Camera c1 = Camera::fromHfov(32, 32, 60), c2 = c1;
  c2.t_cam2world = Eigen::Vector3d(0.8, 0, 0);
  for (int x = 0; x < 4; ++x) d1.data[x] = 0;  // a few misses
  const Image8 m = visibilityMask(c1, d1, c2, d2);
  const VisibleCount n = countVisible(c1, d1, c2, d2);
  EXPECT_EQ(static_cast<size_t>(std::count(m.data.begin(), m.data.end(), 255)), n.visible);
  EXPECT_GT(n.visible, 0u);
  EXPECT_LT(n.visible, n.valid);
  for (int x = 0; x < 4; ++x) EXPECT_EQ(m.data[x], 0);
}

TEST(Journal, ShardRunsLeaveFewFilesAndResumeFromATornLine) {
  const std::string dir = testing::scratchDir("journal");
  const std::string room = writeRoom(dir);
  GenerateConfig c = config(room, dir + "/a", 60);
  c.shardSize = 20;
  runGenerate(c);
  size_t others = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir + "/a"))
    if (e.is_regular_file() && e.path().extension() != ".tar") ++others;
  EXPECT_LE(others, 4u) << "journal, index.json, summary.json";
  // A killed writer's torn last line, and a lost last shard: the rerun redoes them.
  const std::string journal = dir + "/a/.paircast/journal.jsonl";
  const std::string before = readFile(journal);
  std::ofstream(journal, std::ios::app) << "{\"scene\": \"room\", \"ind";
  const auto clean = testing::fileTree(dir + "/a");
  fs::remove(dir + "/a/pairs-000002.tar");
  const nlohmann::json again = runGenerate(c);
  EXPECT_EQ(again["pairs_this_run"].get<int>(), 20);
  EXPECT_EQ(again["pairs"].get<int>(), 60);
  EXPECT_EQ(testing::fileTree(dir + "/a"), clean);
  const std::string after = readFile(journal);
  EXPECT_EQ(after.substr(0, before.size()), before);
  EXPECT_EQ(after.back(), '\n');
}

int run(const std::vector<std::string>& args) {
  return testing::waitProcess(testing::spawnProcess(args));
}

TEST(GeneratePairsCli, OptionErrorsNameTheFlagAndTheRuleOnce) {
  const std::string dir = testing::scratchDir("flagnames");
  const std::string room = writeRoom(dir);
  auto stderrOf = [&](const std::string& extra, int* status) {
    const std::string log = dir + "/stderr.txt";
    const std::string cmd =
        tool() + " --scenes " + room + " --out " + dir + "/o --quiet " + extra + " 2> " + log;
    *status = WEXITSTATUS(std::system(cmd.c_str()));
    return readFile(log);
  };
  int status = 0;
  // The library's rule (PairOptions::validate) with the command's flag in front of it.
  std::string err = stderrOf("--resolution 8", &status);
  EXPECT_EQ(status, 2);
  EXPECT_NE(err.find("generate_pairs: error: --resolution: resolution must be in 16..4096 pixels, "
                     "got 8"),
            std::string::npos)
      << err;
  err = stderrOf("--min-covis 0.9 --max-covis 0.2", &status);
  EXPECT_EQ(status, 2);
  EXPECT_NE(err.find("--min-covis: the covis band must satisfy 0 <= min_covis <= max_covis <= 1"),
            std::string::npos)
      << err;
  // The library's own message names no flag.
  PairOptions o;
  o.resolution = 8;
  EXPECT_ERROR_CONTAINS(o.validate(), "resolution must be in 16..4096 pixels, got 8");
  try {
    o.validate();
  } catch (const OptionError& e) {
    EXPECT_EQ(e.field(), "resolution");
    EXPECT_EQ(std::string(e.what()).find("--"), std::string::npos) << e.what();
  }
}

TEST(GeneratePairsCli, ExitStatusSaysWhenScenesWereSkipped) {
  const std::string dir = testing::scratchDir("exit");
  const std::string room = writeRoom(dir);
  std::ofstream(dir + "/broken.obj") << "v 0 0 0\nf 1 2 3\n";
  const std::vector<std::string> common = {
      "--out", dir + "/o", "--pairs-per-scene", "2", "--resolution", "48", "--quiet"};
  auto cmd = [&](std::vector<std::string> scenes, std::vector<std::string> extra = {}) {
    std::vector<std::string> a = {tool(), "--scenes"};
    a.insert(a.end(), scenes.begin(), scenes.end());
    a.insert(a.end(), common.begin(), common.end());
    a.insert(a.end(), extra.begin(), extra.end());
    fs::remove_all(dir + "/o");
    return run(a);
  };
  EXPECT_EQ(cmd({room}), 0);
  EXPECT_EQ(cmd({dir + "/broken.obj"}), 1) << "no pair at all must fail";
  EXPECT_TRUE(fs::exists(dir + "/o/summary.json")) << "skipped scenes stay listed";
  EXPECT_EQ(cmd({room, dir + "/broken.obj"}), 4);
  EXPECT_EQ(cmd({room, dir + "/broken.obj"}, {"--allow-skipped-scenes"}), 0);
}

TEST(GeneratePairsCli, BadNewOptionsAreClearErrors) {
  const std::string dir = testing::scratchDir("badopts");
  const std::string room = writeRoom(dir);
  auto cmd = [&](std::vector<std::string> extra) {
    std::vector<std::string> a = {
        tool(), "--scenes",     room, "--out",  dir + "/o", "--pairs-per-scene",
        "1",    "--resolution", "64", "--quiet"};
    a.insert(a.end(), extra.begin(), extra.end());
    return run(a);
  };
  EXPECT_NE(cmd({"--views", "0"}), 0);
  EXPECT_NE(cmd({"--views", "100"}), 0);
  EXPECT_NE(cmd({"--screen-resolution", "-1"}), 0);
  EXPECT_NE(cmd({"--screen-resolution", "65"}), 0);
  EXPECT_EQ(cmd({"--screen-resolution", "0"}), 0);
  PairOptions o;
  o.views = 0;
  EXPECT_ERROR_CONTAINS(o.validate(), "views must be in [1, ", "got 0");
  o.views = 2;
  o.screenResolution = 300;
  EXPECT_ERROR_CONTAINS(o.validate(),
                        "the screening resolution (300) must not exceed the resolution (256)");
}

}  // namespace
}  // namespace paircast

namespace paircast {
namespace {

TEST(SceneNames, SharedStemsAreToldApartByTheirFolder) {
  EXPECT_EQ(
      uniqueSceneNames({"r/room_0/mesh.ply", "r/room_1/mesh.ply", "b/x.obj", "c/x.obj", "d/y.obj",
                        "e/room_0_mesh.obj"}),
      (std::vector<std::string>{"room_0_mesh", "room_1_mesh", "b_x", "c_x", "y", "room_0_mesh_2"}));
}

}  // namespace
}  // namespace paircast
