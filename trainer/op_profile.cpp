#include "trainer/op_profile.h"

#include <ATen/record_function.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "util/error.h"

namespace paircast {
namespace {

using Clock = std::chrono::steady_clock;

struct Totals {
  double seconds = 0;
  int64_t calls = 0;
};

// An operator running on the profiled thread: its start, the time of the operators it called,
// and the stage it runs in.
struct Frame {
  uint64_t handle;
  Clock::time_point start;
  double children = 0;
  std::string name, stage;
  bool userScope;
};

struct State {
  std::mutex mutex;  // guards the maps (report() may run on another thread)
  std::map<std::string, Totals> byOp, byStage, byKind;
  std::map<std::string, std::string> kindOf;
  std::atomic<bool> counting{false};
  std::thread::id thread;
  bool installed = false;
};

State& state() {
  static State s;
  return s;
}

thread_local std::vector<Frame> frames;

std::unique_ptr<at::ObserverContext> onStart(const at::RecordFunction& fn) {
  State& s = state();
  if (!s.counting.load(std::memory_order_relaxed) || std::this_thread::get_id() != s.thread)
    return nullptr;
  const bool user = fn.scope() == at::RecordScope::USER_SCOPE;
  std::string stage = frames.empty() ? "other" : frames.back().stage;
  if (user && (frames.empty() || stage == "other")) stage = fn.name();
  frames.push_back({fn.handle(), Clock::now(), 0, fn.name(), std::move(stage), user});
  return nullptr;
}

void onEnd(const at::RecordFunction& fn, at::ObserverContext*) {
  if (frames.empty() || frames.back().handle != fn.handle()) return;
  const Frame f = std::move(frames.back());
  frames.pop_back();
  const double total = std::chrono::duration<double>(Clock::now() - f.start).count();
  if (!frames.empty()) frames.back().children += total;
  if (f.userScope) return;  // a stage's own time is its operators'
  const double self = std::max(0.0, total - f.children);
  State& s = state();
  const std::lock_guard<std::mutex> lock(s.mutex);
  auto kind = s.kindOf.find(f.name);
  if (kind == s.kindOf.end()) kind = s.kindOf.emplace(f.name, operatorKind(f.name)).first;
  for (Totals* t : {&s.byOp[f.name], &s.byStage[f.stage],
                    &s.byKind[f.stage == kStageOptimizer ? "optimizer" : kind->second]}) {
    t->seconds += self;
    ++t->calls;
  }
}

bool has(const std::string& name, const char* part) {
  return name.find(part) != std::string::npos;
}

nlohmann::json rows(const std::map<std::string, Totals>& totals, int64_t steps, double sum,
                    size_t top, const char* key) {
  std::vector<std::pair<std::string, Totals>> sorted(totals.begin(), totals.end());
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.second.seconds > b.second.seconds; });
  if (sorted.size() > top) sorted.resize(top);
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [name, t] : sorted)
    out.push_back({{key, name},
                   {"ms_per_step", 1e3 * t.seconds / steps},
                   {"share", sum > 0 ? t.seconds / sum : 0.0},
                   {"calls_per_step", static_cast<double>(t.calls) / steps}});
  return out;
}

}  // namespace

std::string operatorKind(const std::string& name) {
  if (!has(name, "::")) return "autograd nodes";  // MmBackward0 and the like: the engine's own
  if (has(name, "mm") || has(name, "matmul") || has(name, "linear")) return "matmul";
  if (has(name, "conv")) return "convolution";
  if (has(name, "softmax") || has(name, "scaled_dot_product") || has(name, "attention"))
    return "softmax and attention";
  if (has(name, "layer_norm")) return "layer norm";
  if (has(name, "gelu")) return "gelu";
  if (has(name, "::to") || has(name, "copy") || has(name, "clone") || has(name, "contiguous"))
    return "casts and copies";
  if (has(name, "empty") || has(name, "zero") || has(name, "fill")) return "allocation and fill";
  if (has(name, "view") || has(name, "reshape") || has(name, "permute") || has(name, "transpose") ||
      has(name, "select") || has(name, "slice") || has(name, "expand") || has(name, "narrow") ||
      has(name, "chunk") || has(name, "split") || has(name, "unsqueeze") || has(name, "squeeze") ||
      has(name, "as_strided") || has(name, "detach") || name == "aten::t")
    return "views";
  return "elementwise and other";
}

OpProfile::OpProfile() {
  State& s = state();
  if (s.installed) throw Error("one operator profile at a time");
  s.installed = true;
  s.byOp.clear(), s.byStage.clear(), s.byKind.clear();
  handle_ = at::addGlobalCallback(at::RecordFunctionCallback(onStart, onEnd).needsIds(true));
}

OpProfile::~OpProfile() {
  pause();
  at::removeCallback(handle_);
  state().installed = false;
}

void OpProfile::resume() {
  State& s = state();
  s.thread = std::this_thread::get_id();
  frames.clear();
  s.counting = true;
}

void OpProfile::pause() {
  state().counting = false;
}

nlohmann::json OpProfile::report(int64_t steps, size_t top) const {
  State& s = state();
  const std::lock_guard<std::mutex> lock(s.mutex);
  steps = std::max<int64_t>(steps, 1);
  double sum = 0;
  for (const auto& [stage, t] : s.byStage) sum += t.seconds;
  nlohmann::json ops = rows(s.byOp, steps, sum, top, "op");
  for (auto& row : ops) row["kind"] = s.kindOf[row["op"].get<std::string>()];
  return {{"steps", steps},
          {"ms_per_step", 1e3 * sum / steps},
          {"stages", rows(s.byStage, steps, sum, s.byStage.size(), "stage")},
          {"kinds", rows(s.byKind, steps, sum, s.byKind.size(), "kind")},
          {"ops", ops}};
}

}  // namespace paircast
