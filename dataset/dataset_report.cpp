#include "dataset/dataset_report.h"

#include <glob.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include "dataset/shard.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/html.h"
#include "util/plot.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

std::vector<std::string> globFiles(const std::string& pattern) {
  std::vector<std::string> out;
  glob_t g{};
  if (::glob(pattern.c_str(), 0, nullptr, &g) == 0)
    for (size_t i = 0; i < g.gl_pathc; ++i) out.push_back(g.gl_pathv[i]);
  globfree(&g);
  std::sort(out.begin(), out.end());
  return out;
}

std::set<std::string> readKeys(const std::string& file) {
  std::set<std::string> keys;
  if (file.empty()) return keys;
  std::ifstream in(file);
  if (!in) throw Error(file, "cannot read the key list");
  std::string line;
  while (std::getline(in, line))
    if (!line.empty()) keys.insert(line);
  return keys;
}

int binOf(double covis, int bins) {
  return std::clamp(static_cast<int>(covis * bins), 0, bins - 1);
}

// Images of the sample grid: per bin, the pairs whose keys hash lowest, so that the samples are
// spread over the scenes and do not depend on the order of the files.
struct Samples {
  struct Sample {
    uint64_t hash;
    PairRecord record;
    std::array<std::string, 2> jpeg;
  };
  int bins, perBin;
  std::vector<std::vector<Sample>> byBin;
  static uint64_t hashOf(const std::string& key) {
    uint64_t h = 1469598103934665603ull;
    for (unsigned char c : key) h = (h ^ c) * 1099511628211ull;
    return h;
  }
  // Whether a pair with this key and covis would be kept (so its images are worth reading).
  bool wants(const std::string& key, double covis) const {
    if (perBin <= 0) return false;  // no sample grid
    const auto& v = byBin[binOf(covis, bins)];
    if (static_cast<int>(v.size()) < perBin) return true;
    return hashOf(key) < v.back().hash;
  }
  void add(const PairRecord& r, std::string a, std::string b) {
    auto& v = byBin[binOf(r.covis, bins)];
    Sample s{hashOf(r.key), r, {std::move(a), std::move(b)}};
    auto at = std::upper_bound(v.begin(), v.end(), s.hash,
                               [](uint64_t h, const Sample& x) { return h < x.hash; });
    v.insert(at, std::move(s));
    if (static_cast<int>(v.size()) > perBin) v.pop_back();
  }
};

// The pairs of tar shards (samples with two views), in file order.
std::vector<PairRecord> readShardRecords(const std::vector<std::string>& shards,
                                         const std::set<std::string>& keys, Samples* samples) {
  std::vector<PairRecord> out;
  for (const auto& shard : shards) {
    readShard(
        shard,
        [&](ShardSample&& s) {
          if (!keys.empty() && !keys.count(s.key)) return;
          if (!s.record.contains("camera2")) return;  // a one-view sample is no pair
          PairRecord r;
          r.key = s.key;
          r.scene = s.record.value("scene", std::string("?"));
          r.covis = s.record.value("covis", 0.0);
          r.camera[0] = cameraFromJson(s.record.at("camera1"), shard + ":" + s.key);
          r.camera[1] = cameraFromJson(s.record.at("camera2"), shard + ":" + s.key);
          if (samples && samples->wants(r.key, r.covis))
            samples->add(r, std::string(s.jpeg[0].begin(), s.jpeg[0].end()),
                         std::string(s.jpeg[1].begin(), s.jpeg[1].end()));
          out.push_back(std::move(r));
        },
        [&](const std::string& why) {
          std::fprintf(stderr, "dataset_report: warning: %s\n", why.c_str());
        });
  }
  return out;
}

// Pair `index` of a CroCo metadata.json's multiviews entry `v`. Throws paircast::Error naming
// the scene's metadata.json when a field is missing.
PairRecord crocoRecord(const std::string& dir, const std::string& scene, const std::string& index,
                       const nlohmann::json& v) {
  PairRecord r;
  r.scene = scene;
  r.key = scene + "/" + index;
  try {
    r.covis = v.at("covisibility_ratios").at(1).get<double>();
    for (int k = 0; k < 2; ++k) {
      const auto& p = v.at("positions").at(k);
      const auto& q = v.at("orientations").at(k);
      const Eigen::Quaterniond h(q.at(0).get<double>(), q.at(1).get<double>(),
                                 q.at(2).get<double>(), q.at(3).get<double>());
      // Habitat's camera axes (x right, y up, z back) back to OpenCV's.
      r.camera[k].R_cam2world =
          h.normalized().toRotationMatrix() * Eigen::Vector3d(1, -1, -1).asDiagonal();
      r.camera[k].t_cam2world = {p.at(0).get<double>(), p.at(1).get<double>(),
                                 p.at(2).get<double>()};
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error((fs::path(dir) / scene / "metadata.json").string(),
                "pair " + index + ": " + e.what());
  }
  return r;
}

// The pairs of CroCo's folder layout: pairs.txt, and each scene's metadata.json.
std::vector<PairRecord> readCrocoRecords(const std::string& dir, const std::set<std::string>& keys,
                                         Samples* samples) {
  std::vector<PairRecord> out;
  const std::string pairsTxt = (fs::path(dir) / "pairs.txt").string();
  if (!fs::exists(pairsTxt))
    throw Error(dir, "holds neither *.tar shards nor a CroCo layout (pairs.txt)");
  std::map<std::string, nlohmann::json> meta;  // scene -> metadata.json
  std::ifstream in(pairsTxt);
  std::string a, b;
  while (in >> a >> b) {
    const fs::path pa(a);
    const std::string scene = pa.parent_path().string();
    const std::string stem = pa.filename().string();
    const std::string index = stem.substr(0, stem.find('_'));
    if (!meta.count(scene)) {
      const std::string m = (fs::path(dir) / scene / "metadata.json").string();
      try {
        meta[scene] = nlohmann::json::parse(readFile(m));
      } catch (const nlohmann::json::exception& e) {
        throw Error(m, std::string("bad metadata: ") + e.what());
      }
      if (!meta[scene].is_object()) throw Error(m, "bad metadata: not a JSON object");
    }
    const auto& mv = meta[scene].value("multiviews", nlohmann::json::object());
    if (!mv.contains(index)) continue;
    PairRecord r = crocoRecord(dir, scene, index, mv[index]);
    if (!keys.empty() && !keys.count(r.key)) continue;
    if (samples && samples->wants(r.key, r.covis))
      samples->add(r, readFile((fs::path(dir) / a).string()),
                   readFile((fs::path(dir) / b).string()));
    out.push_back(std::move(r));
  }
  return out;
}

// Shards when the folder has any, else CroCo's layout.
std::vector<PairRecord> readRecords(const std::string& dir, const std::string& keysFile,
                                    Samples* samples) {
  const std::set<std::string> keys = readKeys(keysFile);
  const auto shards = globFiles((fs::path(dir) / "*.tar").string());
  if (!shards.empty()) return readShardRecords(shards, keys, samples);
  return readCrocoRecords(dir, keys, samples);
}

std::string fmt(double v, const char* f = "%.3f") {
  return html::number(v, f);
}

// Pairs and the sum of their covis, per scene (in name order).
using PerScene = std::map<std::string, std::pair<int64_t, double>>;

PerScene countPerScene(const std::vector<PairRecord>& pairs) {
  PerScene perScene;
  for (const auto& p : pairs) perScene[p.scene].first++, perScene[p.scene].second += p.covis;
  return perScene;
}

// The covis histogram (20 bins), as files/covis_histogram.svg; returns the counts.
std::vector<double> writeCovisHistogram(const std::vector<PairRecord>& pairs,
                                        const fs::path& files) {
  std::vector<double> edges, counts(20, 0.0);
  for (int i = 0; i <= 20; ++i) edges.push_back(i / 20.0);
  for (const auto& p : pairs) counts[binOf(p.covis, 20)] += 1;
  writeFileAtomic((files / "covis_histogram.svg").string(),
                  plot::histogram(edges, counts, {"Co-visibility", "covis", "pairs"}));
  return counts;
}

// The joint distribution of distance and angle between the views, as files/distance_angle.svg.
void writeDistanceAngle(const std::vector<PairRecord>& pairs, const fs::path& files) {
  double maxDist = 0.5;
  for (const auto& p : pairs) maxDist = std::max(maxDist, viewDistance(p));
  maxDist = std::ceil(maxDist * 2) / 2;
  const int nx = 24, ny = 18;
  std::vector<double> xe, ye;
  for (int i = 0; i <= nx; ++i) xe.push_back(maxDist * i / nx);
  for (int i = 0; i <= ny; ++i) ye.push_back(180.0 * i / ny);
  std::vector<std::vector<double>> joint(ny, std::vector<double>(nx, 0.0));
  for (const auto& p : pairs) {
    const int cx = std::clamp(static_cast<int>(viewDistance(p) / maxDist * nx), 0, nx - 1);
    const int cy = std::clamp(static_cast<int>(viewAngleDegrees(p) / 180.0 * ny), 0, ny - 1);
    joint[cy][cx] += 1;
  }
  writeFileAtomic((files / "distance_angle.svg").string(),
                  plot::heatmap(xe, ye, joint,
                                {"Distribution of viewpoint pairs", "distance between views (m)",
                                 "angle between optical axes (deg)"}));
}

// The second views relative to the first on the floor plane, as files/relative_positions.svg.
void writeRelativePositions(const std::vector<PairRecord>& pairs, const fs::path& files) {
  std::vector<plot::Arrow> arrows;
  const size_t step = std::max<size_t>(1, pairs.size() / 2000);  // at most ~2000 marks
  for (size_t i = 0; i < pairs.size(); i += step) {
    const FloorRelative r = floorRelative(pairs[i]);
    arrows.push_back({r.x, r.y, r.headingX, r.headingY, pairs[i].covis});
  }
  writeFileAtomic((files / "relative_positions.svg").string(),
                  plot::cameraPlot(arrows, {"Second view relative to the first (floor plane)",
                                            "right (m)", "forward (m)", 460, 460}));
}

// The page's styles beyond the shared ones: the sample grid and the figures.
constexpr const char* kReportStyle =
    ".grid td{text-align:center;vertical-align:top}.grid "
    "img{width:96px;height:auto;display:inline-block;margin:1px}figure{display:inline-block;"
    "margin:6px}";

// Marks the page once every image has loaded (data-images="ok/total"), for automated checks.
constexpr const char* kImagesLoadedScript =
    "<script>\n// Marks the page once every image has loaded, for automated "
    "checks.\nwindow.addEventListener('load', function () {\n  var imgs = "
    "document.images, ok = 0;\n  for (var i = 0; i < imgs.length; i++) if (imgs[i].complete && "
    "imgs[i].naturalWidth > 0) ok++;\n  document.body.setAttribute('data-images', ok + '/' + "
    "imgs.length);\n});\n</script>\n";

// The three figures written by the functions above.
std::string figures() {
  return "<figure>" + html::image("report_files/covis_histogram.svg", "covis histogram") +
         "</figure>\n<figure>" +
         html::image("report_files/distance_angle.svg", "distance and angle") +
         "</figure>\n<figure>" +
         html::image("report_files/relative_positions.svg", "relative positions") +
         "<figcaption>Red: the first view, looking up. Dots: second views, with their heading, "
         "coloured by covis (dark low, yellow high).</figcaption></figure>\n";
}

std::string perSceneTable(const PerScene& perScene) {
  std::string s =
      html::heading(2, "Pairs per scene") + html::tableStart({"scene", "pairs", "mean covis"});
  for (const auto& [scene, v] : perScene)
    s += html::labelledRow(plot::escape(scene), {std::to_string(v.first), fmt(v.second / v.first)});
  return s + html::tableEnd();
}

// The models that furnished scenes used, from the credits*.json files generate_pairs wrote:
// (catalogue, id) -> their row, and the scenes that have credits. A file that cannot be read is
// left out; the table says so.
struct Credits {
  std::map<std::pair<std::string, std::string>, std::vector<std::string>> models;
  std::set<std::string> scenes;
  std::vector<std::string> unreadable;
};

Credits readCredits(const std::string& dir) {
  Credits c;
  for (const std::string& file : globFiles((fs::path(dir) / "credits*.json").string())) {
    try {
      const auto j = nlohmann::json::parse(readFile(file));
      for (const auto& [scene, credits] : j.at("scenes").items()) {
        c.scenes.insert(scene);
        for (const auto& m : credits.value("models", nlohmann::json::array()))
          c.models[{m.value("catalogue", ""), m.value("id", "")}] = {
              m.value("name", ""), m.value("creator", ""), m.value("catalogue_name", ""),
              m.value("license", "")};
      }
    } catch (const std::exception&) {
      c.unreadable.push_back(file);
    }
  }
  return c;
}

std::string creditsTable(const Credits& c) {
  if (c.models.empty() && c.unreadable.empty()) return "";
  std::string s = html::heading(2, "Credits") +
                  html::paragraph(std::to_string(c.models.size()) + " models in " +
                                  std::to_string(c.scenes.size()) +
                                  " furnished scene(s), from Sweet Home 3D's catalogues.");
  for (const std::string& f : c.unreadable)
    s += html::paragraph("Unreadable: <code>" + plot::escape(f) + "</code>");
  s += html::tableStart({"model", "creator", "catalogue", "licence"});
  for (const auto& [key, row] : c.models)
    s += html::labelledRow(plot::escape(row[0]),
                           {plot::escape(row[1]), plot::escape(row[2]), plot::escape(row[3])});
  return s + html::tableEnd();
}

// The sample grid: a row per covis bin, a cell per sample pair with its two views, whose JPEGs
// it writes into `files` (sample_<i>_<view>.jpg). Counts the pairs shown in `images`.
std::string sampleGrid(const Samples& samples, const fs::path& files, int* images) {
  std::string s = html::heading(2, "Sample pairs by co-visibility") + "<table class='grid'>\n";
  int& image = *images;
  for (int b = 0; b < samples.bins; ++b) {
    s += "<tr><th>" + fmt(double(b) / samples.bins, "%.2f") + "&ndash;" +
         fmt(double(b + 1) / samples.bins, "%.2f") + "</th>";
    if (samples.byBin[b].empty()) s += "<td>(none)</td>";
    for (const auto& sample : samples.byBin[b]) {
      s += "<td>";
      for (int k = 0; k < 2; ++k) {
        const std::string name =
            "sample_" + std::to_string(image) + "_" + std::to_string(k + 1) + ".jpg";
        writeFileAtomic((files / name).string(), sample.jpeg[k], Durability::NoSync);
        s += html::image("report_files/" + name, "view " + std::to_string(k + 1));
      }
      ++image;
      s += "<br>covis " + fmt(sample.record.covis) + "<br><small>" +
           plot::escape(sample.record.key) + "</small></td>";
    }
    s += "</tr>\n";
  }
  return s + html::tableEnd();
}

}  // namespace

double viewDistance(const PairRecord& p) {
  return (p.camera[1].t_cam2world - p.camera[0].t_cam2world).norm();
}

double viewAngleDegrees(const PairRecord& p) {
  const double c = p.camera[0].R_cam2world.col(2).dot(p.camera[1].R_cam2world.col(2));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI;
}

FloorRelative floorRelative(const PairRecord& p) {
  Eigen::Vector3d up = -(p.camera[0].R_cam2world.col(1) + p.camera[1].R_cam2world.col(1));
  if (up.norm() < 1e-9) up = -p.camera[0].R_cam2world.col(1);
  up.normalize();
  auto horizontal = [&](const Eigen::Vector3d& v) {
    Eigen::Vector3d h = v - v.dot(up) * up;
    return h.norm() < 1e-12 ? h : h.normalized();
  };
  const Eigen::Vector3d fwd = horizontal(p.camera[0].R_cam2world.col(2));
  const Eigen::Vector3d right = fwd.cross(up);  // OpenCV: x = y x z, with y = -up
  const Eigen::Vector3d d = p.camera[1].t_cam2world - p.camera[0].t_cam2world;
  const Eigen::Vector3d f2 = horizontal(p.camera[1].R_cam2world.col(2));
  return {d.dot(right), d.dot(fwd), f2.dot(right), f2.dot(fwd)};
}

std::vector<PairRecord> readPairRecords(const std::string& dir, const std::string& keysFile) {
  return readRecords(dir, keysFile, nullptr);
}

nlohmann::json writeDatasetReport(const ReportOptions& o) {
  if (!fs::is_directory(o.dir)) throw Error(o.dir, "no such folder");
  const int bins = std::clamp(o.bins, 1, 100);
  Samples samples{bins, std::max(0, o.samplesPerBin), {}};
  samples.byBin.resize(bins);
  const std::vector<PairRecord> pairs = readRecords(o.dir, o.keysFile, &samples);
  if (pairs.empty()) throw Error(o.dir, "holds no pair to report on");
  const std::string out = o.out.empty() ? o.dir : o.out;
  const fs::path files = fs::path(out) / "report_files";
  makeDirs(files.string());
  const std::string title =
      o.title.empty() ? fs::absolute(o.dir).lexically_normal().filename().string() : o.title;

  const std::vector<double> counts = writeCovisHistogram(pairs, files);
  writeDistanceAngle(pairs, files);
  writeRelativePositions(pairs, files);
  const PerScene perScene = countPerScene(pairs);
  double covisSum = 0;
  for (const auto& p : pairs) covisSum += p.covis;

  // The page (a line break before the styles, as it always had).
  std::string page =
      html::pageStart(plot::escape(title) + " - paircast dataset report",
                      "\n" + html::style(1200, kReportStyle)) +
      html::heading(1, plot::escape(title)) +
      html::paragraph(
          std::to_string(pairs.size()) + " pairs from " + std::to_string(perScene.size()) +
          " scene(s); mean co-visibility " + fmt(covisSum / pairs.size()) + ". Source: <code>" +
          plot::escape(o.dir) + "</code>" +
          (o.keysFile.empty() ? "" : " (keys from <code>" + plot::escape(o.keysFile) + "</code>)") +
          ".");
  const Credits credits = readCredits(o.dir);
  page += figures() + perSceneTable(perScene) + creditsTable(credits);
  int image = 0;
  page += sampleGrid(samples, files, &image) + kImagesLoadedScript + html::pageEnd();
  writeFileAtomic((fs::path(out) / "report.html").string(), page);

  nlohmann::json scenes = nlohmann::json::object();
  for (const auto& [scene, v] : perScene) scenes[scene] = v.first;
  return {{"report", (fs::path(out) / "report.html").string()},
          {"pairs", pairs.size()},
          {"mean_covis", covisSum / pairs.size()},
          {"covis_histogram", counts},
          {"pairs_per_scene", scenes},
          {"sample_pairs", image},
          {"credited_models", credits.models.size()}};
}

}  // namespace paircast
