// bench_covis: co-visibility time per pair on one core, ours (depth reprojection) against the
// kd-tree method (nanoflann, the same test CroCo's generator does with scikit-learn), and, when
// ../shared/tools/ref_covis.py and python3-sklearn are there, against that script's CroCo
// kd-tree and numpy reprojection on the same depth maps, with the agreement of the values.
//
// Depth maps: a given pair (--depth1 A.exr --cam1 A.json --depth2 B.exr --cam2 B.json), or
// pairs rendered from the procedural "room" scene with our renderer. The last line is JSON:
// {"ms_per_pair":..., "ms_kdtree":..., "speedup":..., ...}.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "covis/covisibility.h"
#include "covis/pointcloud_covis.h"
#include "covis/unproject.h"
#include "render/procedural_scene.h"
#include "render/ray_caster.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"
#include "util/random.h"
#include "util/timer.h"

using namespace paircast;
namespace fs = std::filesystem;

namespace {

struct Config {
  std::string depth1, cam1, depth2, cam2;  // a given pair; empty: rendered pairs
  int pairs = 8;                           // rendered pairs
  int size = 256;                          // rendered resolution (square), pixels
  double hfov = 60.0;                      // degrees
  uint64_t seed = 1;
  int refRepeat = 2;  // ref_covis.py times each method as the best of this many runs
  bool ref = true;
  std::string refScript;  // default: ../shared/tools/ref_covis.py beside the checkout
  CovisOptions covis;
  std::string normalize = "valid";
  std::string jsonOut;  // optional: per-pair values and the summary
  bool sweep = false;   // compare tolerances against exact visibility (rendered pairs only)
};

struct Pair {
  std::string name;
  Camera cam[2];
  ImageF depth[2];       // [H, W, 1] z-depth, metres
  std::string files[4];  // depth1, cam1, depth2, cam2 on disk (for ref_covis.py)
};

// The absolute-only tolerance of the implementation check against ref_covis.py, metres.
constexpr float kSameTestTol = 0.05f;

// Best of `rounds` timings of fn, each round repeating it until it ran at least `minSeconds`.
template <typename F>
double bestSecondsPerCall(F&& fn, int rounds, double minSeconds) {
  double best = 1e30;
  for (int r = 0; r < rounds; ++r) {
    int calls = 0;
    const auto start = SteadyClock::now();
    do {
      fn();
      ++calls;
    } while (secondsSince(start) < minSeconds);
    best = std::min(best, secondsSince(start) / calls);
  }
  return best;
}

ImageF firstChannel(const ImageF& image, const std::string& path) {
  if (image.channels == 1) return image;
  std::fprintf(stderr, "note: %s has %d channels; using the first\n", path.c_str(), image.channels);
  ImageF out(image.width, image.height, 1);
  for (size_t i = 0; i < out.data.size(); ++i) out.data[i] = image.data[i * image.channels];
  return out;
}

Pair loadPair(const Config& c) {
  Pair p;
  p.name = fs::path(c.depth1).filename().string() + " / " + fs::path(c.depth2).filename().string();
  p.files[0] = c.depth1;
  p.files[1] = c.cam1;
  p.files[2] = c.depth2;
  p.files[3] = c.cam2;
  for (int k = 0; k < 2; ++k) {
    p.cam[k] = readCameraJson(p.files[2 * k + 1]);
    p.depth[k] = firstChannel(readImageF(p.files[2 * k]), p.files[2 * k]);
    try {
      checkDepthMatches(p.cam[k], p.depth[k]);
    } catch (const Error& e) {
      throw Error(p.files[2 * k], e.what());
    }
  }
  return p;
}

// The procedural living room (Y up) and its BVH.
struct RoomScene {
  LayoutSpec layout;
  Mesh mesh;
  std::unique_ptr<RayCaster> caster;

  RoomScene() {
    const std::vector<LayoutSpec> layouts = shippedLayouts();
    layout = layouts.front();
    for (const LayoutSpec& l : layouts)
      if (l.name == "room") layout = l;
    mesh = buildLayout(layout);
    caster = std::make_unique<RayCaster>(mesh);
  }
};

// Pairs inside the room: a first view from a random eye at head height, and a second one moved
// up to 1.2 m and aimed near the mean point the first view sees, as CroCo's sampler does, so
// that the overlaps spread over [0, 1].
std::vector<Pair> renderPairs(const Config& c, const RoomScene& scene, const std::string& dir) {
  const RayCaster& caster = *scene.caster;
  const LayoutSpec& layout = scene.layout;
  const RoomSpec& room = layout.rooms.front();
  const Eigen::Vector3d up(0, 1, 0);
  Rng rng(c.seed);
  std::vector<Pair> pairs;
  for (int attempt = 0; static_cast<int>(pairs.size()) < c.pairs && attempt < 100 * c.pairs;
       ++attempt) {
    Pair p;
    const Eigen::Vector3d eye(rng.uniform(room.x0 + 0.4, room.x1 - 0.4), rng.uniform(1.2, 1.7),
                              rng.uniform(room.z0 + 0.4, room.z1 - 0.4));
    const double yaw = rng.uniform(0, 2 * M_PI), pitch = rng.uniform(-0.35, 0.2);
    const Eigen::Vector3d forward(std::cos(pitch) * std::cos(yaw), std::sin(pitch),
                                  std::cos(pitch) * std::sin(yaw));
    p.cam[0] = Camera::fromHfov(c.size, c.size, c.hfov);
    p.cam[0].lookAt(eye, eye + forward, up);
    caster.renderDepth(p.cam[0], p.depth[0]);
    const std::optional<Eigen::Vector3d> target = meanValidPoint(p.cam[0], p.depth[0]);
    if (!target) continue;
    const Eigen::Vector3d eye2 =
        eye +
        Eigen::Vector3d(rng.uniform(-1.2, 1.2), rng.uniform(-0.2, 0.2), rng.uniform(-1.2, 1.2));
    const Eigen::Vector3d target2 =
        *target + Eigen::Vector3d(rng.normal(), 0.3 * rng.normal(), rng.normal());
    if ((target2 - eye2).norm() < 0.5 || eye2.y() < 0.3 || eye2.y() > layout.height - 0.3) continue;
    p.cam[1] = Camera::fromHfov(c.size, c.size, c.hfov);
    p.cam[1].lookAt(eye2, target2, up);
    caster.renderDepth(p.cam[1], p.depth[1]);
    // Both views must see mostly geometry beyond arm's length (not the inside of furniture).
    bool ok = true;
    for (const ImageF& d : p.depth) {
      size_t far = 0;
      for (float z : d.data) far += z > 0.5f;
      ok = ok && far > d.data.size() / 2;
    }
    if (!ok) continue;
    const int k = static_cast<int>(pairs.size());
    p.name = "room pair " + std::to_string(k);
    for (int v = 0; v < 2; ++v) {
      const std::string stem = dir + "/pair" + std::to_string(k) + "_" + std::to_string(v + 1);
      p.files[2 * v] = stem + "_depth.exr";
      p.files[2 * v + 1] = stem + "_camera_params.json";
      writeExr(p.files[2 * v], p.depth[v]);
      writeCameraJson(p.files[2 * v + 1], p.cam[v]);
    }
    pairs.push_back(std::move(p));
  }
  if (static_cast<int>(pairs.size()) < c.pairs)
    throw Error("found only " + std::to_string(pairs.size()) + " usable view pairs");
  return pairs;
}

// The exact share of view i's valid pixels that view j sees: the pixel's surface point lies in
// j's frame, in front of it, and nothing is on the segment to j's centre (shadow rays).
double exactVisibleFraction(const RayCaster& caster, const Camera& ci, const ImageF& di,
                            const Camera& cj) {
  std::vector<Ray> rays;  // [valid pixels of i in j's frame]
  size_t valid = 0;
  const PixelDepthMap world = worldFromPixelDepth(ci);
  for (int v = 0; v < ci.height; ++v)
    for (int u = 0; u < ci.width; ++u) {
      const float z = di.data[static_cast<size_t>(v) * ci.width + u];
      if (!validDepth(z)) continue;
      ++valid;
      const Eigen::Vector3d p = world.apply(u, v, z).cast<double>();
      const Eigen::Vector3d q = cj.cameraFromWorld() * p;
      if (q.z() <= 0) continue;
      const Eigen::Vector2d x = cj.project(q);
      if (!(x.x() >= 0 && x.y() >= 0 && x.x() < cj.width && x.y() < cj.height)) continue;
      // t in units of the segment; 1e-3 of it (a few mm) keeps the ray off its own surface.
      rays.push_back(Ray{p.cast<float>(), (cj.t_cam2world - p).cast<float>(), 1e-3f, 1.0f - 1e-3f});
    }
  std::vector<Hit> hits(rays.size());
  caster.intersect(rays.data(), hits.data(), rays.size());
  size_t visible = 0;
  for (const Hit& h : hits) visible += h.triangle < 0;
  return valid ? static_cast<double>(visible) / valid : 0.0;
}

// How far v_ij and v_ji land from the exact visibility, over a grid of tolerances, and for the
// kd-tree test (normalised by valid pixels, so that it measures the same thing).
nlohmann::json toleranceSweep(const RoomScene& scene, const std::vector<Pair>& pairs) {
  std::vector<double> exact;  // [2 * pairs]: v_ij, v_ji
  for (const Pair& p : pairs) {
    exact.push_back(exactVisibleFraction(*scene.caster, p.cam[0], p.depth[0], p.cam[1]));
    exact.push_back(exactVisibleFraction(*scene.caster, p.cam[1], p.depth[1], p.cam[0]));
  }
  auto errors = [&](auto&& fn) {
    double sum = 0, worst = 0;
    for (size_t k = 0; k < pairs.size(); ++k) {
      const CovisResult r = fn(pairs[k]);
      for (const double e :
           {std::abs(r.v_ij - exact[2 * k]), std::abs(r.v_ji - exact[2 * k + 1])}) {
        sum += e;
        worst = std::max(worst, e);
      }
    }
    return std::make_pair(sum / exact.size(), worst);
  };
  std::printf(
      "\ntolerance sweep against exact visibility (shadow rays), %zu pairs, both directions:\n",
      pairs.size());
  std::printf("%-28s %12s %12s\n", "method", "mean |err|", "max |err|");
  nlohmann::json out = nlohmann::json::array();
  for (const float absTol : {0.0f, 0.01f, 0.03f, 0.05f, 0.1f})
    for (const float relTol : {0.0f, 0.01f, 0.03f, 0.05f, 0.1f}) {
      CovisOptions o;
      o.absTol = absTol;
      o.relTol = relTol;
      const auto [mean, worst] = errors([&](const Pair& p) {
        return computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], o);
      });
      char name[64];
      std::snprintf(name, sizeof name, "reproj %.2f m + %.2f x depth", absTol, relTol);
      std::printf("%-28s %12.4f %12.4f\n", name, mean, worst);
      out.push_back({{"abs_tol", absTol},
                     {"rel_tol", relTol},
                     {"mean_abs_err", mean},
                     {"max_abs_err", worst}});
    }
  PointCloudCovisOptions kd;
  kd.normalize = CovisOptions::Normalize::Valid;
  const auto [mean, worst] = errors([&](const Pair& p) {
    return computePointCloudCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], kd);
  });
  std::printf("%-28s %12.4f %12.4f\n", "kd-tree < 5 cm (/ valid)", mean, worst);
  out.push_back({{"method", "kdtree"}, {"mean_abs_err", mean}, {"max_abs_err", worst}});
  return out;
}

std::string shellQuote(const std::string& s) {
  std::string out = "'";
  for (char ch : s) out += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return out + "'";
}

bool haveReference(const std::string& script) {
  return fs::exists(script) &&
         std::system("/usr/bin/python3 -c 'import sklearn, numpy' >/dev/null 2>&1") == 0;
}

// Runs ref_covis.py on one pair, on one thread, and parses its line
// "SUMMARY ref_covis official: v12=.. v21=.. covis=.. ms=.. | reproj: v12=.. ..." into
// {"official": {...}, "reproj": {...}} (the parts its --method asked for).
nlohmann::json runReference(const std::string& script, const Pair& p, const std::string& method,
                            float absTol, float relTol, int repeat) {
  std::ostringstream cmd;
  cmd << "OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 /usr/bin/python3 "
      << shellQuote(script) << " --depth1 " << shellQuote(p.files[0]) << " --cam1 "
      << shellQuote(p.files[1]) << " --depth2 " << shellQuote(p.files[2]) << " --cam2 "
      << shellQuote(p.files[3]) << " --method " << method << " --abs-tol " << absTol
      << " --rel-tol " << relTol << " --repeat " << repeat << " 2>&1";
  std::string output, summary;
  if (FILE* f = popen(cmd.str().c_str(), "r")) {
    char buf[4096];
    while (fgets(buf, sizeof buf, f)) output += buf;
    pclose(f);
  }
  std::istringstream lines(output);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("SUMMARY ref_covis", 0) == 0) summary = line.substr(17);
  nlohmann::json out = nlohmann::json::object();
  std::istringstream parts(summary);
  for (std::string part; std::getline(parts, part, '|');) {
    std::istringstream is(part);
    std::string name, tok;
    is >> name;  // "official:" or "reproj:"
    if (name.empty() || name.back() != ':') continue;
    nlohmann::json j;
    while (is >> tok) {
      const size_t eq = tok.find('=');
      if (eq != std::string::npos) j[tok.substr(0, eq)] = std::stod(tok.substr(eq + 1));
    }
    if (j.contains("covis")) out[name.substr(0, name.size() - 1)] = j;
  }
  if (out.empty())
    std::fprintf(stderr, "ref_covis.py gave no usable SUMMARY:\n%s\n", output.c_str());
  return out;
}

double maxAbsDiff(const CovisResult& r, const nlohmann::json& ref) {
  return std::max({std::abs(r.v_ij - ref["v12"].get<double>()),
                   std::abs(r.v_ji - ref["v21"].get<double>()),
                   std::abs(r.covis - ref["covis"].get<double>())});
}

// A scratch folder for the rendered pairs, removed on every way out.
struct ScratchDir {
  std::string path =
      (fs::temp_directory_path() / ("bench_covis_" + std::to_string(::getpid()))).string();
  ScratchDir() { fs::create_directories(path); }
  ~ScratchDir() {
    std::error_code ignored;
    fs::remove_all(path, ignored);
  }
};

// Sums and worst agreements over the pairs.
struct Totals {
  double ours = 0, kd = 0, refKd = 0, refReproj = 0;  // ms
  double worstReproj = 0, worstCovis = 0, worstSame = 0, worstKd = 0;
  int refCount = 0;
};

// Ours and the kd-tree's co-visibility of `p`, each timed at its best, printed as a table row.
nlohmann::json measurePair(const Config& c, const Pair& p, CovisResult& kd, Totals& t) {
  const CovisResult r = computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], c.covis);
  kd = computePointCloudCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1]);
  double sink = 0;
  const double ours =
      1e3 *
      bestSecondsPerCall(
          [&] {
            sink += computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], c.covis).covis;
          },
          5, 0.2);
  const double kdMs =
      1e3 *
      bestSecondsPerCall(
          [&] {
            sink += computePointCloudCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1]).covis;
          },
          3, 0.0);
  if (!(sink >= 0)) std::printf("(impossible)\n");  // keeps the timed calls alive
  t.ours += ours;
  t.kd += kdMs;
  char valid[32];
  std::snprintf(valid, sizeof valid, "%.2f/%.2f", r.valid_i, r.valid_j);
  std::printf("%-24s %9s %8.4f %8.4f %8.4f %8.3f | %9.4f %8.2f %7.0fx\n", p.name.c_str(), valid,
              r.v_ij, r.v_ji, r.covis, ours, kd.covis, kdMs, kdMs / ours);
  return {{"pair", p.name},   {"v12", r.v_ij},       {"v21", r.v_ji},
          {"covis", r.covis}, {"ms", ours},          {"kd_covis", kd.covis},
          {"kd_ms", kdMs},    {"valid1", r.valid_i}, {"valid2", r.valid_j}};
}

// ref_covis.py on `p`: its timings, and its values' agreement with ours and with our kd-tree's
// `kd`, printed and added to `row` and `t`.
void compareWithReference(const Config& c, const std::string& script, const Pair& p,
                          const CovisResult& kd, nlohmann::json& row, Totals& t) {
  // 1. The script with our tolerance values. Its test is max(abs, rel * z), ours abs + rel * d,
  //    so grazing pixels may differ: this is the agreement of the two definitions.
  const nlohmann::json rr =
      runReference(script, p, "both", c.covis.absTol, c.covis.relTol, c.refRepeat);
  // 2. An absolute tolerance only, where both tests are |z - d| <= abs: the agreement of the
  //    implementations.
  const nlohmann::json ra = runReference(script, p, "reproj", kSameTestTol, 0.0f, 1);
  if (!rr.contains("reproj") || !rr.contains("official") || !ra.contains("reproj")) return;
  // Ours normalised by valid pixels, as the script's reprojection is; our kd-tree (by all
  // pixels) against its CroCo kd-tree.
  CovisOptions byValid = c.covis;
  byValid.normalize = CovisOptions::Normalize::Valid;
  const CovisResult rv = computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], byValid);
  byValid.absTol = kSameTestTol;
  byValid.relTol = 0.0f;
  const CovisResult rs = computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], byValid);
  const double dReproj = maxAbsDiff(rv, rr["reproj"]), dKd = maxAbsDiff(kd, rr["official"]);
  const double dSame = maxAbsDiff(rs, ra["reproj"]);
  const double dCovis = std::abs(rv.covis - rr["reproj"]["covis"].get<double>());
  t.worstReproj = std::max(t.worstReproj, dReproj);
  t.worstCovis = std::max(t.worstCovis, dCovis);
  t.worstSame = std::max(t.worstSame, dSame);
  t.worstKd = std::max(t.worstKd, dKd);
  t.refKd += rr["official"]["ms"].get<double>();
  t.refReproj += rr["reproj"]["ms"].get<double>();
  ++t.refCount;
  std::printf(
      "  ref_covis.py reproj: v12 %.4f v21 %.4f covis %.4f, %.1f ms; |diff| covis %.4f, "
      "any %.4f; with |dz| <= %.2f m alone %.5f\n"
      "  ref_covis.py CroCo kd-tree: covis %.4f, %.1f ms; |diff| with our kd-tree %.5f\n",
      rr["reproj"]["v12"].get<double>(), rr["reproj"]["v21"].get<double>(),
      rr["reproj"]["covis"].get<double>(), rr["reproj"]["ms"].get<double>(), dCovis, dReproj,
      kSameTestTol, dSame, rr["official"]["covis"].get<double>(),
      rr["official"]["ms"].get<double>(), dKd);
  row["ref"] = rr;
  row["ref_abs_only"] = ra;
}

// Prints the means over the pairs and the reference's agreement; returns the summary line.
nlohmann::json summarise(const Config& c, const std::vector<Pair>& pairs, const Totals& t) {
  const double n = static_cast<double>(pairs.size());
  const double msOurs = t.ours / n, msKd = t.kd / n;
  std::printf(
      "\nmean over %zu pairs, one thread: ours %.3f ms per pair, kd-tree (nanoflann) %.2f "
      "ms: %.0fx\n",
      pairs.size(), msOurs, msKd, msKd / msOurs);
  nlohmann::json last = {{"ms_per_pair", msOurs},
                         {"ms_kdtree", msKd},
                         {"speedup", msKd / msOurs},
                         {"pairs", pairs.size()},
                         {"width", pairs.front().cam[0].width},
                         {"height", pairs.front().cam[0].height}};
  if (t.refCount == 0) {
    std::printf("ref_covis.py comparison skipped (%s)\n",
                c.ref ? "needs ../shared/tools/ref_covis.py and python3-sklearn" : "--no-ref");
    return last;
  }
  const double refKd = t.refKd / t.refCount, refReproj = t.refReproj / t.refCount;
  std::printf(
      "ref_covis.py over %d pairs (best of %d, one thread): CroCo kd-tree %.1f ms (ours "
      "%.0fx faster), numpy reprojection %.1f ms (ours %.0fx faster)\n",
      t.refCount, c.refRepeat, refKd, refKd / msOurs, refReproj, refReproj / msOurs);
  std::printf(
      "agreement, max |difference| over the pairs: ours vs its reprojection: covis %.4f, any "
      "of v12/v21/covis %.4f (same numbers, abs + rel vs max(abs, rel)); with the same test "
      "(|dz| <= %.2f m) %.5f. Our kd-tree vs its CroCo kd-tree: %.5f\n",
      t.worstCovis, t.worstReproj, kSameTestTol, t.worstSame, t.worstKd);
  last["ms_ref_kdtree"] = refKd;
  last["ms_ref_reproj"] = refReproj;
  last["speedup_vs_ref_kdtree"] = refKd / msOurs;
  last["max_diff_ref_reproj_covis"] = t.worstCovis;
  last["max_diff_ref_reproj"] = t.worstReproj;
  last["max_diff_ref_reproj_same_test"] = t.worstSame;
  last["max_diff_ref_kdtree"] = t.worstKd;
  return last;
}

int run(const Config& c) {
  const ScratchDir scratch;
  std::vector<Pair> pairs;
  std::unique_ptr<RoomScene> scene;
  if (!c.depth1.empty()) {
    pairs.push_back(loadPair(c));
  } else {
    std::printf("rendering %d pairs of the procedural room at %dx%d, hfov %.0f...\n", c.pairs,
                c.size, c.size, c.hfov);
    scene = std::make_unique<RoomScene>();
    pairs = renderPairs(c, *scene, scratch.path);
  }
  const std::string script =
      c.refScript.empty()
          ? (fs::path(PAIRCAST_SOURCE_DIR).parent_path() / "shared/tools/ref_covis.py").string()
          : c.refScript;
  const bool ref = c.ref && haveReference(script);
  std::printf(
      "ours: depth reprojection, tolerance %.3g m + %.3g x depth, nearest pixel, normalise by "
      "%s pixels, stride %d; kd-tree: nanoflann, < 5 cm, by all pixels. One thread.\n",
      c.covis.absTol, c.covis.relTol, toString(c.covis.normalize), c.covis.stride);
  std::printf("%-24s %9s %8s %8s %8s %8s | %9s %8s %8s\n", "pair", "valid1/2", "v12", "v21",
              "covis", "ms", "kd covis", "kd ms", "speedup");
  Totals totals;
  nlohmann::json perPair = nlohmann::json::array();
  for (const Pair& p : pairs) {
    CovisResult kd;
    nlohmann::json row = measurePair(c, p, kd, totals);
    if (ref) compareWithReference(c, script, p, kd, row, totals);
    perPair.push_back(row);
  }
  const nlohmann::json last = summarise(c, pairs, totals);
  nlohmann::json sweep;
  if (c.sweep) {
    if (!scene) throw Error("--tolerance-sweep needs rendered pairs (it casts shadow rays)");
    sweep = toleranceSweep(*scene, pairs);
  }
  if (!c.jsonOut.empty())
    writeFileAtomic(
        c.jsonOut,
        nlohmann::json{{"summary", last}, {"pairs", perPair}, {"tolerance_sweep", sweep}}.dump(1) +
            "\n");
  std::printf("%s\n", last.dump().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Config c;
  CLI::App app{"Co-visibility per pair on one core: ours against the kd-tree method"};
  app.add_option("--depth1", c.depth1, "Depth of view 1 (EXR, z-depth in metres, 0 = miss)");
  app.add_option("--cam1", c.cam1, "Camera JSON of view 1 (camera_intrinsics, R/t_cam2world)");
  app.add_option("--depth2", c.depth2, "Depth of view 2");
  app.add_option("--cam2", c.cam2, "Camera JSON of view 2");
  app.add_option("--pairs", c.pairs, "Rendered pairs when no files are given")
      ->check(CLI::Range(1, 10000));
  app.add_option("--size", c.size, "Rendered resolution (square)")->check(CLI::Range(8, 8192));
  app.add_option("--hfov", c.hfov, "Rendered horizontal field of view, degrees");
  app.add_option("--seed", c.seed, "Seed of the rendered poses");
  app.add_option("--abs-tol", c.covis.absTol, "Depth tolerance, metres");
  app.add_option("--rel-tol", c.covis.relTol, "Depth tolerance, fraction of depth");
  app.add_option("--covis-normalize", c.normalize, "valid (the paper) or all (CroCo's generator)")
      ->check(CLI::IsMember({"valid", "all"}));
  app.add_option("--stride", c.covis.stride, "Sub-sampling stride of the projected view")
      ->check(CLI::Range(1, 64));
  app.add_option("--ref-script", c.refScript, "ref_covis.py (default ../shared/tools/)");
  app.add_option("--ref-repeat", c.refRepeat, "ref_covis.py: best of N runs per method")
      ->check(CLI::Range(1, 100));
  app.add_flag("!--no-ref", c.ref, "Skip ref_covis.py");
  app.add_flag("--tolerance-sweep", c.sweep,
               "Rendered pairs: error of several tolerances against exact visibility");
  app.add_option("--json", c.jsonOut, "Also write per-pair values and the summary here");
  CLI11_PARSE(app, argc, argv);
  try {
    const int given = !c.depth1.empty() + !c.cam1.empty() + !c.depth2.empty() + !c.cam2.empty();
    if (given != 0 && given != 4)
      throw Error("give all of --depth1 --cam1 --depth2 --cam2, or none");
    c.covis.normalize = parseCovisNormalize(c.normalize);
    return run(c);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_covis: %s\n", e.what());
    return 1;
  }
}
