// bench_resume: what a no-op rerun of a finished generate_pairs job costs at CroCo's scale.
// It fakes a finished shards job cheaply, without rendering: dummy scene files (never loaded,
// since nothing is left to make), the journal's notes written directly in generate_pairs'
// format, and shards of one small encoded sample (16x16 views, a full record) under every key.
// Then it runs the real generate_pairs on it again, as a child process, and prints the journal's
// bytes per pair, the rerun's seconds and peak RSS, against its targets (under 300 bytes, 30 s
// and 1 GiB; docs/dataset.md, "Determinism and resuming", has a run).
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "dataset/shard.h"
#include "util/camera.h"

using namespace paircast;
namespace fs = std::filesystem;

namespace {

struct Args {
  uint64_t pairs = 1800000;
  int scenes = 200;
  int shardSize = 1000;
  std::string out = "/tmp/bench_resume";
  std::string tool;
};

std::string sceneName(int s) {
  char name[32];
  std::snprintf(name, sizeof name, "scene_%05d", s);
  return name;
}

// A record as generate_pairs writes it to shards: the schema's fields, 16 candidates' covis,
// screened and up.
EncodedPair fakeEncoded() {
  PairSample s;
  s.seed = 5;
  s.visibility.assign(2, std::vector<double>(2, 1.0));
  for (int k = 0; k < 2; ++k) {
    s.camera.push_back(Camera::fromHfov(16, 16, 60));
    s.camera[k].t_cam2world = Eigen::Vector3d(k + 0.123456789, 1.5, -2.987654321);
    s.rgb.push_back(Image8(16, 16, 3, static_cast<uint8_t>(40 * k)));
    s.depth.push_back(ImageF());
    CovisResult c;
    c.covis = c.v_ij = k ? 0.4321987654 : 1.0;
    c.v_ji = k ? 0.5123456789 : 1.0;
    c.valid_i = c.valid_j = 0.987654321;
    s.covis.push_back(c);
  }
  for (int c = 0; c < 16; ++c) s.candidateCovis.push_back(0.05f * c + 0.0123f);
  EncodedPair enc = encodePair(s, false, 90);
  enc.record["candidate_covis"] = s.candidateCovis;
  enc.record["screened"] = 12;
  enc.record["up"] = "y";
  return enc;
}

// The journal note generate_pairs keeps of an accepted sample.
std::string journalLine(const std::string& scene, uint64_t k) {
  return nlohmann::json({{"scene", scene},
                         {"index", k},
                         {"candidates", "ABCDEFGHIJKLMNOP"},
                         {"up", "y"},
                         {"covis", 0.4321987654}})
             .dump() +
         "\n";
}

void fakeJob(const Args& a, uint64_t perScene) {
  fs::remove_all(a.out);
  fs::create_directories(a.out + "/scenes");
  fs::create_directories(a.out + "/out/.paircast");
  std::ofstream journal(a.out + "/out/.paircast/journal.jsonl");
  EncodedPair enc = fakeEncoded();
  std::unique_ptr<ShardWriter> shard;
  size_t shards = 0;
  for (int s = 0; s < a.scenes; ++s) {
    const std::string name = sceneName(s);
    std::ofstream(a.out + "/scenes/" + name + ".obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    for (uint64_t k = 0; k < perScene; ++k) {
      journal << journalLine(name, k);
      if (!shard) {
        char file[64];
        std::snprintf(file, sizeof file, "/out/pairs-%06zu.tar", shards++);
        shard = std::make_unique<ShardWriter>(a.out + file);
      }
      enc.key = sampleKey(name, k);
      enc.record["scene"] = name;
      enc.record["index"] = k;
      shard->add(enc);
      if (static_cast<int>(shard->samples()) >= a.shardSize) shard->close(), shard.reset();
    }
  }
  if (shard) shard->close();
}

struct Rerun {
  int status = -1;
  double seconds = 0;
  double peakMiB = 0;
};

Rerun rerun(const Args& a, uint64_t perScene) {
  const std::string pps = std::to_string(perScene), size = std::to_string(a.shardSize);
  const std::string scenes = a.out + "/scenes", out = a.out + "/out";
  const auto t0 = std::chrono::steady_clock::now();
  std::fflush(stdout);
  const pid_t pid = ::fork();
  if (pid == 0) {
    std::freopen("/dev/null", "w", stdout);  // its summary
    ::execl(a.tool.c_str(), a.tool.c_str(), "--scenes", scenes.c_str(), "--out", out.c_str(),
            "--pairs-per-scene", pps.c_str(), "--shard-size", size.c_str(), "--format", "shards",
            "--resolution", "16", "--quiet", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  Rerun r;
  struct rusage ru {};
  ::wait4(pid, &r.status, 0, &ru);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.peakMiB = ru.ru_maxrss / 1024.0;  // KiB on Linux
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  a.tool =
      (fs::canonical("/proc/self/exe").parent_path().parent_path() / "tools" / "generate_pairs")
          .string();
  CLI::App app{"bench_resume: a no-op rerun of a finished generate_pairs job, faked"};
  app.add_option("--pairs", a.pairs, "pairs of the faked job (CroCo: 1.8 M)");
  app.add_option("--scenes", a.scenes, "scenes they are spread over");
  app.add_option("--shard-size", a.shardSize, "pairs per shard");
  app.add_option("--out", a.out, "scratch folder (removed first)");
  app.add_option("--tool", a.tool, "the generate_pairs binary");
  CLI11_PARSE(app, argc, argv);
  const uint64_t perScene = (a.pairs + a.scenes - 1) / a.scenes;
  const uint64_t pairs = perScene * a.scenes;
  const auto t0 = std::chrono::steady_clock::now();
  fakeJob(a, perScene);
  std::printf("faked %llu pairs over %d scenes in %.1f s\n", static_cast<unsigned long long>(pairs),
              a.scenes,
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  const double journalBytes = fs::file_size(a.out + "/out/.paircast/journal.jsonl");
  const Rerun r = rerun(a, perScene);
  const auto summary = nlohmann::json::parse(std::ifstream(a.out + "/out/summary.json"));
  const bool noop = WIFEXITED(r.status) && WEXITSTATUS(r.status) == 0 &&
                    summary.value("pairs_this_run", -1) == 0 &&
                    summary.value("pairs", uint64_t(0)) == pairs;
  std::printf("journal       %8.1f bytes/pair   (target < 300)\n", journalBytes / pairs);
  std::printf("no-op rerun   %8.2f s            (target < 30)\n", r.seconds);
  std::printf("peak RSS      %8.1f MiB          (target < 1024)\n", r.peakMiB);
  std::printf("rerun %s: exit %d, pairs %llu, pairs this run %d\n",
              noop ? "made nothing" : "FAILED", WIFEXITED(r.status) ? WEXITSTATUS(r.status) : -1,
              static_cast<unsigned long long>(summary.value("pairs", uint64_t(0))),
              summary.value("pairs_this_run", -1));
  const bool met = noop && journalBytes / pairs < 300 && r.seconds < 30 && r.peakMiB < 1024;
  std::printf("targets %s\n", met ? "met" : "NOT met");
  return noop ? 0 : 1;
}
