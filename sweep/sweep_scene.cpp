#include "sweep/sweep_scene.h"

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "dataset/generate_job.h"
#include "trainer/trainer.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace fs = std::filesystem;

std::vector<std::unique_ptr<SweepScene>> loadSweepScenes(const std::vector<std::string>& files,
                                                         const LoadOptions& load,
                                                         const SamplerOptions& so,
                                                         const char* role) {
  std::vector<std::unique_ptr<SweepScene>> out;
  const std::vector<std::string> names = uniqueSceneNames(files);
  for (size_t i = 0; i < files.size(); ++i) {
    auto s = std::make_unique<SweepScene>();
    s->path = files[i];
    s->name = names[i];
    try {
      s->scene = std::make_unique<Scene>(loadScene(files[i], load));
      s->scene->name = s->name;
      s->caster = std::make_unique<RayCaster>(s->scene->mesh);
      s->sampler = std::make_unique<ViewpointSampler>(*s->scene, *s->caster, so);
    } catch (const Error& e) {
      std::fprintf(stderr, "covis_sweep: warning: %s scene skipped: %s\n", role, e.what());
      continue;
    }
    out.push_back(std::move(s));
  }
  if (out.empty()) throw Error(std::string("no usable ") + role + " scene");
  return out;
}

nlohmann::json readSweepState(const std::string& path) {
  if (!fs::exists(path)) return nullptr;
  try {
    return nlohmann::json::parse(readFile(path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(path,
                std::string("unreadable state file (delete it to redo this stage): ") + e.what());
  }
}

int sweepThreads(const SweepConfig& c) {
  return c.jobs > 0 ? c.jobs : omp_get_num_procs();
}

void sweepSay(const SweepConfig& c, const std::string& line) {
  if (!c.progress) return;
  if (c.worker > 0)
    std::fprintf(stderr, "[covis_sweep] worker %d: %s\n", c.worker, line.c_str());
  else
    std::fprintf(stderr, "[covis_sweep] %s\n", line.c_str());
}

void setSweepSchedule(TrainConfig& t, int64_t steps, int64_t pairs, int batch, int world) {
  const int64_t perEpoch = std::max<int64_t>(1, pairs / (static_cast<int64_t>(batch) * world));
  t.batchSize = batch;
  t.epochs = static_cast<int>((steps + perEpoch - 1) / perEpoch);
  t.warmupEpochs = std::max(0.1 * t.epochs, 1.0 / perEpoch);
  t.maxSteps = steps;
  t.saveEvery = std::max<int64_t>(25, steps / 4);
  t.resume = true;
}

}  // namespace paircast
