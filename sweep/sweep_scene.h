// What the stages of covis_sweep share: a scene loaded with its ray caster and viewpoint
// sampler, the sweep's state files, and its progress lines.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "dataset/viewpoint_sampler.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "sweep/covis_sweep.h"

namespace paircast {

struct TrainConfig;

// A training or held-out scene, loaded once.
struct SweepScene {
  std::string path, name;
  std::unique_ptr<Scene> scene;
  std::unique_ptr<RayCaster> caster;
  std::unique_ptr<ViewpointSampler> sampler;
};

// Loads every file (names made unique); one that fails is skipped with a warning. Throws
// paircast::Error when none loads. `role` names them in messages ("training", "held-out").
std::vector<std::unique_ptr<SweepScene>> loadSweepScenes(const std::vector<std::string>& files,
                                                         const LoadOptions& load,
                                                         const SamplerOptions& sampler,
                                                         const char* role);

// A state file's JSON, or null when there is none; throws paircast::Error naming an unreadable
// one.
nlohmann::json readSweepState(const std::string& path);

// The render threads --jobs asks for: all cores at 0.
int sweepThreads(const SweepConfig& config);

// The schedule every run and fine-tune of a sweep trains with: `steps` of `batch` pairs per
// process on `world` processes over `pairs` pairs (epochs count the global batch), a tenth of the
// epochs (at least one step) of warm-up, a checkpoint every quarter (at least 25 steps), resumed.
void setSweepSchedule(TrainConfig& t, int64_t steps, int64_t pairs, int batch, int world);

// A progress line on stderr, unless the config turns progress off.
void sweepSay(const SweepConfig& config, const std::string& line);

}  // namespace paircast
