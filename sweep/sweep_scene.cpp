#include "sweep/sweep_scene.h"

#include <omp.h>

#include <cstdio>
#include <filesystem>

#include "dataset/generate_job.h"
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
  if (c.progress) std::fprintf(stderr, "[covis_sweep] %s\n", line.c_str());
}

}  // namespace paircast
