#include "dataset/dataset_report.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>

#include "dataset/generate_job.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

PairRecord pairAt(const Eigen::Vector3d& t2, double yawRightDegrees) {
  PairRecord p;
  // Camera 1 at the origin, OpenCV axes = world axes (y down, z forward).
  const double a = yawRightDegrees * M_PI / 180;
  // Turning right about the up axis (-y): forward z goes towards +x.
  p.camera[1].R_cam2world = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix();
  p.camera[1].t_cam2world = t2;
  return p;
}

TEST(DatasetReport, RelativePoseGeometry) {
  const PairRecord p = pairAt({1.0, 0.0, 2.0}, 90);
  EXPECT_NEAR(viewDistance(p), std::sqrt(5.0), 1e-12);
  EXPECT_NEAR(viewAngleDegrees(p), 90, 1e-9);
  const FloorRelative r = floorRelative(p);
  EXPECT_NEAR(r.x, 1.0, 1e-9);         // to the right of the first camera
  EXPECT_NEAR(r.y, 2.0, 1e-9);         // ahead of it
  EXPECT_NEAR(r.headingX, 1.0, 1e-9);  // looking right
  EXPECT_NEAR(r.headingY, 0.0, 1e-9);
  // Height differences do not move the point on the floor plane.
  const FloorRelative low = floorRelative(pairAt({1.0, 0.7, 2.0}, 0));
  EXPECT_NEAR(low.x, 1.0, 1e-9);
  EXPECT_NEAR(low.y, 2.0, 1e-9);
  EXPECT_NEAR(low.headingY, 1.0, 1e-9);
}

// 24 pairs of the shipped room, in shards and in CroCo's layout.
const std::string& generated() {
  static const std::string dir = [] {
    const std::string d =
        (fs::path(::testing::TempDir()) / "paircast" / ("report_pairs." + std::to_string(getpid())))
            .string();
    fs::remove_all(d);
    GenerateConfig g;
    g.scenes = {testing::sourceDir() + "/scenes/room/room.obj"};
    g.out = d;
    g.pairsPerScene = 24;
    g.pair.resolution = 64;
    g.pair.minCovis = 0.1;
    g.croco = true;
    g.progress = false;
    runGenerate(g);
    return d;
  }();
  return dir;
}

// Every src/href of the page names a file that exists beside it.
void expectValidPage(const std::string& html, const fs::path& dir) {
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_NE(html.find("</html>"), std::string::npos);
  EXPECT_EQ(html.find("http://"), std::string::npos) << "the page must work offline";
  EXPECT_EQ(html.find("https://"), std::string::npos) << "the page must work offline";
  const std::regex ref("(src|href)='([^']+)'");
  int refs = 0;
  for (auto it = std::sregex_iterator(html.begin(), html.end(), ref); it != std::sregex_iterator();
       ++it, ++refs)
    EXPECT_TRUE(fs::exists(dir / (*it)[2].str())) << (*it)[2].str();
  EXPECT_GT(refs, 3);
}

TEST(DatasetReport, ShardsAndCrocoLayoutGiveTheSameCounts) {
  const std::string out = testing::scratchDir("report");
  ReportOptions o;
  o.dir = generated();
  o.out = out + "/shards";
  const nlohmann::json a = writeDatasetReport(o);
  EXPECT_EQ(a["pairs"], 24);
  EXPECT_EQ(a["pairs_per_scene"]["room"], 24);
  EXPECT_GT(a["sample_pairs"].get<int>(), 0);
  expectValidPage(readFile(out + "/shards/report.html"), out + "/shards");
  // The same pairs through the CroCo layout (move the shards away so that it is used).
  const std::string croco = out + "/croco_copy";
  fs::copy(generated(), croco, fs::copy_options::recursive);
  for (const auto& e : fs::directory_iterator(croco))
    if (e.path().extension() == ".tar") fs::remove(e.path());
  o.dir = croco;
  o.out = "";
  const nlohmann::json b = writeDatasetReport(o);
  EXPECT_EQ(b["pairs"], 24);
  EXPECT_NEAR(b["mean_covis"].get<double>(), a["mean_covis"].get<double>(), 1e-6);
  EXPECT_EQ(b["covis_histogram"], a["covis_histogram"]);
  // Camera poses survive the habitat quaternions: the same distances and angles.
  const auto ra = readPairRecords(generated()), rb = readPairRecords(croco);
  ASSERT_EQ(ra.size(), rb.size());
  for (size_t i = 0; i < ra.size(); ++i) {
    EXPECT_NEAR(viewDistance(ra[i]), viewDistance(rb[i]), 1e-4);
    EXPECT_NEAR(viewAngleDegrees(ra[i]), viewAngleDegrees(rb[i]), 1e-2);
  }
  expectValidPage(readFile(croco + "/report.html"), croco);
}

TEST(DatasetReport, NoSampleGridWithZeroSamplesPerBin) {
  ReportOptions o;
  o.dir = generated();
  o.out = testing::scratchDir("report_no_grid");
  o.samplesPerBin = 0;
  const nlohmann::json r = writeDatasetReport(o);
  EXPECT_EQ(r["pairs"], 24);
  EXPECT_EQ(r["sample_pairs"], 0);
  EXPECT_NE(readFile(o.out + "/report.html").find("</html>"), std::string::npos);
}

TEST(DatasetReport, KeysSelectPairsAndBadInputIsRefused) {
  const std::string out = testing::scratchDir("keys");
  const auto records = readPairRecords(generated());
  writeFileAtomic(out + "/keys.txt", records[0].key + "\n" + records[3].key + "\n");
  ReportOptions o;
  o.dir = generated();
  o.keysFile = out + "/keys.txt";
  o.out = out;
  EXPECT_EQ(writeDatasetReport(o)["pairs"], 2);
  o.keysFile = out + "/missing.txt";
  EXPECT_ERROR_CONTAINS(writeDatasetReport(o), out + "/missing.txt: cannot read the key list");
  ReportOptions none;
  none.dir = out + "/nonexistent";
  EXPECT_ERROR_CONTAINS(writeDatasetReport(none), none.dir + ": no such folder");
  ReportOptions empty;
  empty.dir = testing::scratchDir("empty");
  try {
    writeDatasetReport(empty);
    ADD_FAILURE() << "an empty folder was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(empty.dir), std::string::npos) << e.what();
  }
}

std::string capture(const std::string& command) {
  std::string out;
  FILE* p = popen(command.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  pclose(p);
  return out;
}

TEST(DatasetReport, LoadsInHeadlessChromiumWithItsImagesAndNoConsoleErrors) {
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium not installed (scripts/setup.sh installs it)";
  const std::string out = testing::scratchDir("chromium");
  ReportOptions o;
  o.dir = generated();
  o.out = out;
  const nlohmann::json r = writeDatasetReport(o);
  const std::string url = "file://" + fs::absolute(out + "/report.html").string();
  const std::string flags =
      "timeout 120 chromium --headless=new --no-sandbox --disable-gpu --no-first-run "
      "--user-data-dir=" +
      out + "/profile ";
  // The page's own script counts the images that loaded, once the page has loaded.
  const std::string dom = capture(flags + "--dump-dom '" + url + "' 2>/dev/null");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(dom, m, std::regex("data-images=\"(\\d+)/(\\d+)\"")))
      << "the page did not finish loading";
  EXPECT_EQ(m[1].str(), m[2].str()) << "some images did not load";
  EXPECT_EQ(std::stoi(m[2].str()), 3 + 2 * r["sample_pairs"].get<int>());
  // Console messages go to the log; none may be an error.
  const std::string log = capture(flags + "--enable-logging=stderr --v=0 --screenshot=" + out +
                                  "/shot.png --window-size=1200,1600 '" + url + "' 2>&1");
  for (const std::regex& bad :
       {std::regex("CONSOLE.*(Error|error|Uncaught)"), std::regex("Not allowed to load"),
        std::regex("ERR_FILE_NOT_FOUND")})
    EXPECT_FALSE(std::regex_search(log, bad)) << log;
  EXPECT_TRUE(fs::exists(out + "/shot.png"));
}

}  // namespace
}  // namespace paircast
