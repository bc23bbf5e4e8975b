#include "dataset/replay.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <set>

#include "dataset/croco_layout.h"
#include "dataset/generate_job.h"
#include "dataset/habitat_frame.h"
#include "dataset/pair_generator.h"
#include "dataset/shard.h"
#include "render/ray_caster.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/timer.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

std::vector<std::string> metadataFiles(const std::vector<std::string>& args) {
  std::vector<std::string> files;
  for (const auto& arg : args) {
    std::error_code ec;
    if (fs::is_directory(arg, ec)) {
      const std::vector<std::string> found =
          sortedFilesUnder(arg, [](const fs::path& p) { return p.filename() == "metadata.json"; });
      if (found.empty()) throw Error(arg, "holds no metadata.json");
      files.insert(files.end(), found.begin(), found.end());
    } else if (fs::is_regular_file(arg, ec)) {
      files.push_back(arg);
    } else {
      throw Error(arg, "no such metadata file or folder");
    }
  }
  return files;
}

// A ".basis.glb" prefers the plain ".glb" beside it.
std::optional<std::string> existingScene(const fs::path& p) {
  std::error_code ec;
  const std::string s = p.string();
  const std::string basis = ".basis.glb";
  if (s.size() > basis.size() && s.compare(s.size() - basis.size(), basis.size(), basis) == 0) {
    const std::string plain = s.substr(0, s.size() - basis.size()) + ".glb";
    if (fs::is_regular_file(plain, ec)) return plain;
  }
  if (fs::is_regular_file(p, ec)) return s;
  return std::nullopt;
}

// The image size of a metadata file: CroCo writes "resolution": [H, W] (or one number).
std::pair<int, int> widthHeight(const nlohmann::json& meta, const std::string& source) {
  const auto& r = meta.at("resolution");
  int w = 0, h = 0;
  if (r.is_number_integer()) {
    w = h = r.get<int>();
  } else if (r.is_array() && r.size() == 2 && r[0].is_number_integer() &&
             r[1].is_number_integer()) {
    h = r[0].get<int>();
    w = r[1].get<int>();
  }
  if (w < 16 || h < 16 || w > 4096 || h > 4096)
    throw Error(source, "'resolution' must be a size (or [H, W]) in 16..4096, got " + r.dump());
  return {w, h};
}

struct ReplayFile {
  std::string path, name, scene;
  nlohmann::json meta;
};

class Replayer {
 public:
  explicit Replayer(const ReplayConfig& cfg) : cfg_(cfg) {}
  // Renders the file's samples; returns its pairs.txt lines.
  std::string replay(ReplayFile& file);
  size_t samples = 0, views = 0;

 private:
  UpAxis upOf(const nlohmann::json& meta) const;
  Camera camera(const nlohmann::json& pose, int k, const Camera& intrinsics,
                const Eigen::Matrix3d& sceneFromMeta, const std::string& source) const;
  const ReplayConfig& cfg_;
};

UpAxis Replayer::upOf(const nlohmann::json& meta) const {
  if (!cfg_.upGiven && meta.contains("up") && meta["up"].is_string())
    return parseUpAxis(meta["up"].get<std::string>());
  return cfg_.load.up;
}

Camera Replayer::camera(const nlohmann::json& entry, int k, const Camera& intrinsics,
                        const Eigen::Matrix3d& sceneFromMeta, const std::string& source) const {
  const auto& p = entry.at("positions").at(k);
  const auto& q = entry.at("orientations").at(k);
  const HabitatQuaternion wxyz = {q.at(0).get<double>(), q.at(1).get<double>(),
                                  q.at(2).get<double>(), q.at(3).get<double>()};
  Camera c = intrinsics;
  const Eigen::Vector3d position(p.at(0).get<double>(), p.at(1).get<double>(),
                                 p.at(2).get<double>());
  if (!position.allFinite()) throw Error(source, "a position is not finite");
  c.t_cam2world = sceneFromMeta * position;
  c.R_cam2world = sceneFromMeta * cameraRotationFromHabitat(wxyz);
  return c;
}

std::string Replayer::replay(ReplayFile& file) {
  const nlohmann::json& meta = file.meta;
  const auto [W, H] = widthHeight(meta, file.path);
  const double hfov = meta.at("hfov").get<double>();
  if (!(hfov > 0 && hfov < 180)) throw Error(file.path, "'hfov' must be in (0, 180) degrees");
  const bool depth = meta.value("generate_depth", false);
  LoadOptions lo = cfg_.load;
  lo.up = upOf(meta);
  // paircast's own metadata is in the scene file's frame; CroCo's in habitat's world.
  const bool own = meta.value("generator", std::string()) == "paircast";
  Scene scene = loadScene(file.scene, lo);  // resolves --up auto
  const Eigen::Matrix3d sceneFromMeta =
      own ? Eigen::Matrix3d::Identity() : sceneFromHabitat(scene.up);
  const RayCaster caster(scene.mesh);
  const Camera intrinsics = Camera::fromHfov(W, H, hfov);
  const fs::path dir = fs::path(cfg_.out) / file.name;
  makeDirs(dir.string());
  std::string pairs;
  RenderOptions ro = cfg_.render;
  ro.rgb = true;
  ro.normals = false;
  ro.ids = false;
  Frame frame;
  for (const auto& [label, entry] : meta.at("multiviews").items()) {
    if (sanitizeName(label) != label)
      throw Error(file.path, "sample label '" + label + "' is not a plain name");
    const std::string source = file.path + ": sample " + label;
    const int V = static_cast<int>(entry.at("positions").size());
    if (V < 1 || V > kMaxViews || entry.at("orientations").size() != entry.at("positions").size())
      throw Error(source, "needs 1 to " + std::to_string(kMaxViews) +
                              " positions and as many orientations");
    PairSample s;
    s.scene = file.name;
    s.covis.assign(V, CovisResult{});
    s.visibility.assign(V, std::vector<double>(V, 0.0));
    for (int k = 0; k < V; ++k) {
      s.camera.push_back(camera(entry, k, intrinsics, sceneFromMeta, source));
      caster.render(s.camera[k], ro, frame);
      s.rgb.push_back(frame.rgb);
      s.depth.push_back(frame.depth);
    }
    const EncodedPair enc = encodePair(s, depth, cfg_.jpegQuality);
    writeCrocoSample((dir / label).string(), enc, s.camera);
    pairs += crocoPairLines(file.name, label, V);
    ++samples;
    views += V;
  }
  nlohmann::json out = meta;
  out["scene"] = file.scene;
  out["replayed_from"] = file.path;
  writeFileAtomic((dir / "metadata.json").string(), out.dump() + "\n");
  writeFileAtomic((dir / "pairs.txt").string(), pairs);
  return pairs;
}

}  // namespace

std::optional<std::string> resolveScenePath(const std::string& scene,
                                            const std::string& metadataFile,
                                            const std::string& sceneRoot) {
  const fs::path p(scene);
  std::vector<fs::path> tries;
  if (!sceneRoot.empty()) {
    if (p.is_relative()) tries.push_back(fs::path(sceneRoot) / p);
    // Drop leading folders one at a time: "/data/hm3d/x/y.glb" -> "hm3d/x/y.glb" -> ...
    std::vector<fs::path> parts(p.begin(), p.end());
    for (size_t first = 1; first < parts.size(); ++first) {
      fs::path tail;
      for (size_t i = first; i < parts.size(); ++i) tail /= parts[i];
      tries.push_back(fs::path(sceneRoot) / tail);
    }
  }
  tries.push_back(p.is_relative() ? fs::path(metadataFile).parent_path() / p : p);
  if (p.is_relative()) tries.push_back(p);
  for (const auto& t : tries)
    if (auto found = existingScene(t)) return found;
  return std::nullopt;
}

nlohmann::json runReplay(const ReplayConfig& cfg) {
  const auto start = SteadyClock::now();
  if (cfg.out.empty()) throw OptionError("out", "an output folder is required");
  std::vector<ReplayFile> files;
  std::set<std::string> taken;
  for (const auto& path : metadataFiles(cfg.metadata)) {
    ReplayFile f;
    f.path = path;
    const std::string base = sanitizeName(fs::path(path).parent_path().filename().string());
    f.name = base;
    for (int k = 2; taken.count(f.name); ++k) f.name = base + "_" + std::to_string(k);
    taken.insert(f.name);
    files.push_back(std::move(f));
  }
  makeDirs(cfg.out);
  Replayer replayer(cfg);
  nlohmann::json skipped = nlohmann::json::array(), done = nlohmann::json::array();
  std::string pairs;
  auto skip = [&](const ReplayFile& f, const std::string& why) {
    std::fprintf(stderr, "generate_pairs: warning: skipping %s: %s\n", f.path.c_str(), why.c_str());
    skipped.push_back({{"metadata", f.path}, {"reason", why}});
  };
  for (auto& f : files) {
    try {
      f.meta = nlohmann::json::parse(readFile(f.path));
      if (!f.meta.is_object() || !f.meta.contains("scene") || !f.meta["scene"].is_string() ||
          !f.meta.contains("multiviews") || !f.meta["multiviews"].is_object())
        throw Error(f.path, "is not a CroCo metadata file (needs \"scene\" and \"multiviews\")");
      const auto scene = resolveScenePath(f.meta["scene"], f.path, cfg.sceneRoot);
      if (!scene)
        throw Error(f.path, "its scene '" + f.meta["scene"].get<std::string>() +
                                "' was not found (give the dataset folder with --scene-root)");
      f.scene = *scene;
      pairs += replayer.replay(f);
      done.push_back({{"metadata", f.path}, {"scene", f.scene}, {"out", f.name}});
      if (cfg.progress)
        std::fprintf(stderr, "[generate_pairs] replayed %s (%s)\n", f.path.c_str(),
                     f.scene.c_str());
    } catch (const nlohmann::json::exception& e) {
      skip(f, f.path + ": malformed metadata: " + e.what());
    } catch (const Error& e) {
      skip(f, e.what());
    }
  }
  writeFileAtomic((fs::path(cfg.out) / "pairs.txt").string(), pairs);
  const nlohmann::json summary = {{"replayed", done},
                                  {"skipped", skipped},
                                  {"samples", replayer.samples},
                                  {"views", replayer.views},
                                  {"seconds", secondsSince(start)}};
  writeFileAtomic((fs::path(cfg.out) / "summary.json").string(), summary.dump(1) + "\n");
  return summary;
}

}  // namespace paircast
