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
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
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
#include "util/error.h"
#include "util/image_io.h"
#include "util/random.h"

using namespace paircast;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

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
};

struct Pair {
  std::string name;
  Camera cam[2];
  ImageF depth[2];       // [H, W, 1] z-depth, metres
  std::string files[4];  // depth1, cam1, depth2, cam2 on disk (for ref_covis.py)
};

double seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

// Best of `rounds` timings of fn, each round repeating it until it ran at least `minSeconds`.
template <typename F>
double bestSecondsPerCall(F&& fn, int rounds, double minSeconds) {
  double best = 1e30;
  for (int r = 0; r < rounds; ++r) {
    int calls = 0;
    const auto start = Clock::now();
    do {
      fn();
      ++calls;
    } while (seconds(start) < minSeconds);
    best = std::min(best, seconds(start) / calls);
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

// Pairs inside the procedural living room (Y up): a first view from a random eye at head
// height, and a second one moved up to 1.2 m and aimed near the mean point the first view
// sees, as CroCo's sampler does, so that the overlaps spread over [0, 1].
std::vector<Pair> renderPairs(const Config& c, const std::string& dir) {
  const LayoutSpec layout = shippedLayouts().front();
  const Mesh mesh = buildLayout(layout);
  const RayCaster caster(mesh);
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
// "SUMMARY ref_covis official: v12=.. v21=.. covis=.. ms=.. | reproj: v12=.. ...".
nlohmann::json runReference(const Config& c, const std::string& script, const Pair& p) {
  std::ostringstream cmd;
  cmd << "OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 /usr/bin/python3 "
      << shellQuote(script) << " --depth1 " << shellQuote(p.files[0]) << " --cam1 "
      << shellQuote(p.files[1]) << " --depth2 " << shellQuote(p.files[2]) << " --cam2 "
      << shellQuote(p.files[3]) << " --abs-tol " << c.covis.absTol << " --rel-tol "
      << c.covis.relTol << " --repeat " << c.refRepeat << " 2>&1";
  std::string output, summary;
  if (FILE* f = popen(cmd.str().c_str(), "r")) {
    char buf[4096];
    while (fgets(buf, sizeof buf, f)) output += buf;
    pclose(f);
  }
  std::istringstream lines(output);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("SUMMARY ref_covis", 0) == 0) summary = line;
  nlohmann::json out;
  const size_t bar = summary.find('|');
  if (bar == std::string::npos) {
    std::fprintf(stderr, "ref_covis.py gave no SUMMARY line:\n%s\n", output.c_str());
    return out;
  }
  auto parse = [](const std::string& part) {
    nlohmann::json j;
    std::istringstream is(part);
    for (std::string tok; is >> tok;) {
      const size_t eq = tok.find('=');
      if (eq != std::string::npos) j[tok.substr(0, eq)] = std::stod(tok.substr(eq + 1));
    }
    return j;
  };
  out["official"] = parse(summary.substr(0, bar));
  out["reproj"] = parse(summary.substr(bar + 1));
  return out;
}

double maxAbsDiff(const CovisResult& r, const nlohmann::json& ref) {
  return std::max({std::abs(r.v_ij - ref["v12"].get<double>()),
                   std::abs(r.v_ji - ref["v21"].get<double>()),
                   std::abs(r.covis - ref["covis"].get<double>())});
}

int run(const Config& c) {
  const std::string tmp =
      (fs::temp_directory_path() / ("bench_covis_" + std::to_string(::getpid()))).string();
  fs::create_directories(tmp);
  std::vector<Pair> pairs;
  if (!c.depth1.empty()) {
    pairs.push_back(loadPair(c));
  } else {
    std::printf("rendering %d pairs of the procedural room at %dx%d, hfov %.0f...\n", c.pairs,
                c.size, c.size, c.hfov);
    pairs = renderPairs(c, tmp);
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

  double sumOurs = 0, sumKd = 0, sumRefKd = 0, sumRefReproj = 0;
  double worstReproj = 0, worstKd = 0;
  int refCount = 0;
  nlohmann::json perPair = nlohmann::json::array();
  for (const Pair& p : pairs) {
    const CovisResult r = computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], c.covis);
    const CovisResult kd =
        computePointCloudCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1]);
    double sink = 0;
    const double ours =
        1e3 *
        bestSecondsPerCall(
            [&] {
              sink +=
                  computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], c.covis).covis;
            },
            5, 0.2);
    const double kdMs =
        1e3 *
        bestSecondsPerCall(
            [&] {
              sink +=
                  computePointCloudCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1]).covis;
            },
            3, 0.0);
    if (!(sink >= 0)) std::printf("(impossible)\n");  // keeps the timed calls alive
    sumOurs += ours;
    sumKd += kdMs;
    char valid[32];
    std::snprintf(valid, sizeof valid, "%.2f/%.2f", r.valid_i, r.valid_j);
    std::printf("%-24s %9s %8.4f %8.4f %8.4f %8.3f | %9.4f %8.2f %7.0fx\n", p.name.c_str(), valid,
                r.v_ij, r.v_ji, r.covis, ours, kd.covis, kdMs, kdMs / ours);
    nlohmann::json row = {{"pair", p.name},   {"v12", r.v_ij},       {"v21", r.v_ji},
                          {"covis", r.covis}, {"ms", ours},          {"kd_covis", kd.covis},
                          {"kd_ms", kdMs},    {"valid1", r.valid_i}, {"valid2", r.valid_j}};
    if (ref) {
      const nlohmann::json rr = runReference(c, script, p);
      if (rr.contains("reproj") && rr["reproj"].contains("covis")) {
        // Ours normalised by valid pixels against the script's reprojection (which is), and our
        // kd-tree (by all pixels) against its CroCo kd-tree.
        CovisOptions byValid = c.covis;
        byValid.normalize = CovisOptions::Normalize::Valid;
        const CovisResult rv =
            computeCovisibility(p.cam[0], p.depth[0], p.cam[1], p.depth[1], byValid);
        const double dReproj = maxAbsDiff(rv, rr["reproj"]), dKd = maxAbsDiff(kd, rr["official"]);
        worstReproj = std::max(worstReproj, dReproj);
        worstKd = std::max(worstKd, dKd);
        sumRefKd += rr["official"]["ms"].get<double>();
        sumRefReproj += rr["reproj"]["ms"].get<double>();
        ++refCount;
        std::printf(
            "  ref_covis.py: reproj v12 %.4f v21 %.4f covis %.4f in %.1f ms (|diff| %.4f); "
            "CroCo kd-tree covis %.4f in %.1f ms (|diff| vs our kd-tree %.4f)\n",
            rr["reproj"]["v12"].get<double>(), rr["reproj"]["v21"].get<double>(),
            rr["reproj"]["covis"].get<double>(), rr["reproj"]["ms"].get<double>(), dReproj,
            rr["official"]["covis"].get<double>(), rr["official"]["ms"].get<double>(), dKd);
        row["ref"] = rr;
      }
    }
    perPair.push_back(row);
  }
  const double n = static_cast<double>(pairs.size());
  const double msOurs = sumOurs / n, msKd = sumKd / n;
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
  if (refCount > 0) {
    const double refKd = sumRefKd / refCount, refReproj = sumRefReproj / refCount;
    std::printf(
        "ref_covis.py over %d pairs (best of %d, one thread): CroCo kd-tree %.1f ms (ours "
        "%.0fx faster), numpy reprojection %.1f ms (ours %.0fx faster)\n",
        refCount, c.refRepeat, refKd, refKd / msOurs, refReproj, refReproj / msOurs);
    std::printf(
        "agreement: max |difference| of v12, v21, covis: ours vs its reprojection %.4f; "
        "our kd-tree vs its CroCo kd-tree %.4f\n",
        worstReproj, worstKd);
    last["ms_ref_kdtree"] = refKd;
    last["ms_ref_reproj"] = refReproj;
    last["speedup_vs_ref_kdtree"] = refKd / msOurs;
    last["max_diff_ref_reproj"] = worstReproj;
    last["max_diff_ref_kdtree"] = worstKd;
  } else {
    std::printf("ref_covis.py comparison skipped (%s)\n",
                c.ref ? "needs ../shared/tools/ref_covis.py and python3-sklearn" : "--no-ref");
  }
  if (!c.jsonOut.empty()) {
    std::FILE* f = std::fopen(c.jsonOut.c_str(), "w");
    if (!f) throw Error(c.jsonOut, "cannot write");
    std::fprintf(f, "%s\n", nlohmann::json{{"summary", last}, {"pairs", perPair}}.dump(1).c_str());
    std::fclose(f);
  }
  fs::remove_all(tmp);
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
