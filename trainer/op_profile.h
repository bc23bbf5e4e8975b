// Where a training step's time goes, operator by operator: LibTorch's RecordFunction callbacks
// time every ATen operator the profiled thread runs, and each operator's self time (its own, less
// the operators it called) is summed by name, by kind (matmul, softmax, layer norm, casts, ...)
// and by stage (the user scopes the training loop opens: data, forward, backward, optimizer).
// Version-independent: RecordFunction's callback API is the same in LibTorch 1.13 and 2.x.
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

namespace paircast {

// The stages the training loop marks with RECORD_USER_SCOPE; ops outside them are "other".
inline constexpr const char* kStageData = "data";
inline constexpr const char* kStageForward = "forward";
inline constexpr const char* kStageBackward = "backward";
inline constexpr const char* kStageOptimizer = "optimizer";

// The kind an ATen operator's name falls into ("aten::addmm" -> "matmul").
std::string operatorKind(const std::string& name);

// One profile at a time per process. Install it, then resume() and pause() around the steps to
// count; the callbacks cost about a microsecond an operator while installed and counting, and
// nothing while paused but a flag read.
class OpProfile {
 public:
  OpProfile();  // installs the callback (paused); throws if another profile is installed
  ~OpProfile();
  OpProfile(const OpProfile&) = delete;
  OpProfile& operator=(const OpProfile&) = delete;

  void resume();  // counts the operators of the calling thread from now on
  void pause();

  // {"steps", "ms_per_step" (the operators' self times summed), "stages": [...], "kinds":
  // [...], "ops": the `top` slowest}, each entry with ms_per_step, share and calls_per_step.
  nlohmann::json report(int64_t steps, size_t top = 20) const;

 private:
  uint64_t handle_ = 0;
};

}  // namespace paircast
