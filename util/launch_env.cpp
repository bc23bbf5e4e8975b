#include "util/launch_env.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>

#include "util/error.h"

namespace paircast {

namespace {

constexpr size_t kMaxHosts = 1000000;

std::string assignment(const std::string& name, const std::string& value) {
  return name + "=" + value;
}

// ---- Slurm host lists ----

// The hosts of one bracket group's body ("01-04,07"), each padded to its range's first bound.
std::vector<std::string> expandGroup(const std::string& body, const std::string& list) {
  auto bad = [&](const std::string& why) {
    return Error("Slurm host list '" + list + "': " + why);
  };
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= body.size()) {
    const size_t comma = std::min(body.find(',', start), body.size());
    const std::string range = body.substr(start, comma - start);
    const size_t dash = range.find('-');
    const std::string lo = range.substr(0, dash);
    const std::string hi = dash == std::string::npos ? lo : range.substr(dash + 1);
    auto number = [&](const std::string& s) {
      unsigned long long v = 0;
      const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
      if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size())
        throw bad("'[" + body + "]' holds '" + range + "', not a number or a range of numbers");
      return v;
    };
    const unsigned long long a = number(lo), b = number(hi);
    if (b < a) throw bad("the range " + range + " runs backwards");
    if (b - a >= kMaxHosts) throw bad("the range " + range + " is over a million hosts");
    for (unsigned long long v = a; v <= b; ++v) {
      char digits[32];
      std::snprintf(digits, sizeof digits, "%0*llu", static_cast<int>(lo.size()), v);
      out.push_back(digits);
    }
    start = comma + 1;
  }
  return out;
}

// The hosts of one item of the list ("n[1-2]-r[3-4]"): its pieces multiplied out, left first.
std::vector<std::string> expandItem(const std::string& item, const std::string& list) {
  std::vector<std::string> hosts = {""};
  size_t i = 0;
  while (i < item.size()) {
    std::vector<std::string> piece;
    if (item[i] == '[') {
      const size_t close = item.find(']', i);
      if (close == std::string::npos) throw Error("Slurm host list '" + list + "': '[' not closed");
      const std::string body = item.substr(i + 1, close - i - 1);
      if (body.find('[') != std::string::npos)
        throw Error("Slurm host list '" + list + "': '[' inside brackets");
      piece = expandGroup(body, list);
      i = close + 1;
    } else {
      const size_t next = std::min(item.find_first_of("[]", i), item.size());
      if (next < item.size() && item[next] == ']')
        throw Error("Slurm host list '" + list + "': ']' without '['");
      piece = {item.substr(i, next - i)};
      i = next;
    }
    if (hosts.size() * piece.size() > kMaxHosts)
      throw Error("Slurm host list '" + list + "': over a million hosts");
    std::vector<std::string> grown;
    for (const auto& h : hosts)
      for (const auto& p : piece) grown.push_back(h + p);
    hosts = std::move(grown);
  }
  return hosts;
}

// The list split at commas and spaces outside brackets.
std::vector<std::string> hostListItems(const std::string& list) {
  std::vector<std::string> items;
  std::string current;
  int depth = 0;
  for (char c : list) {
    if (c == '[') ++depth;
    if (c == ']') --depth;
    const bool separator = c == ',' || c == ' ' || c == '\t' || c == '\n';
    if (separator && depth == 0) {
      if (!current.empty()) items.push_back(current);
      current.clear();
    } else if (separator && c != ',') {
      throw Error("Slurm host list '" + list + "': a space inside brackets");
    } else {
      current += c;
    }
  }
  if (!current.empty()) items.push_back(current);
  return items;
}

// ---- generation parts ----

std::string partsOf(int index, int count) {
  return "part " + std::to_string(index) + " of " + std::to_string(count);
}

int toInt(long v, const std::string& name) {
  if (v < 0 || v > 1000000000) throw Error(name + "=" + std::to_string(v) + " is out of range");
  return static_cast<int>(v);
}

JobPart slurmArrayPart(const Environment& env, std::optional<int> numShards) {
  const std::string id = *env("SLURM_ARRAY_TASK_ID");
  const long task = environmentInteger(env, "SLURM_ARRAY_TASK_ID", 0);
  JobPart part{0, 1, "Slurm array", ""};
  if (numShards) {
    // The task ids are the part indices: a resubmission of some parts (--array=3,7) works.
    part.index = toInt(task, "SLURM_ARRAY_TASK_ID");
    part.count = *numShards;
    part.detail =
        assignment("SLURM_ARRAY_TASK_ID", id) + ", of --num-shards " + std::to_string(*numShards);
    if (part.index >= part.count)
      throw Error("SLURM_ARRAY_TASK_ID=" + id + " is not a part of --num-shards " +
                  std::to_string(part.count) + ": with --num-shards, the array's task ids are " +
                  "the part indices, 0 to " + std::to_string(part.count - 1));
    return part;
  }
  for (const char* name : {"SLURM_ARRAY_TASK_MIN", "SLURM_ARRAY_TASK_COUNT"})
    if (!env(name)) throw Error(std::string("SLURM_ARRAY_TASK_ID is set but ") + name + " is not");
  const long min = environmentInteger(env, "SLURM_ARRAY_TASK_MIN", 0);
  const long count = environmentInteger(env, "SLURM_ARRAY_TASK_COUNT", 1);
  const long step = environmentInteger(env, "SLURM_ARRAY_TASK_STEP", 1);
  const long max = environmentInteger(env, "SLURM_ARRAY_TASK_MAX", min + count - 1);
  if (step != 1 || max - min + 1 != count)
    throw Error("a Slurm array with a step or gaps (SLURM_ARRAY_TASK_MIN=" + std::to_string(min) +
                ", MAX=" + std::to_string(max) + ", STEP=" + std::to_string(step) + ", COUNT=" +
                std::to_string(count) + ") does not say which part a task is: submit a " +
                "contiguous array (--array=0-" + std::to_string(count - 1) +
                "), or give --num-shards N to make the task ids the part indices");
  part.index = toInt(task - min, "SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN");
  part.count = toInt(count, "SLURM_ARRAY_TASK_COUNT");
  if (part.count < 1 || part.index >= part.count)
    throw Error("SLURM_ARRAY_TASK_ID=" + id + " is outside the array " + std::to_string(min) + "-" +
                std::to_string(max));
  part.detail = assignment("SLURM_ARRAY_TASK_ID", id) +
                " - SLURM_ARRAY_TASK_MIN=" + std::to_string(min) +
                ", of SLURM_ARRAY_TASK_COUNT=" + std::to_string(count);
  return part;
}

JobPart kubernetesPart(const Environment& env, std::optional<int> numShards) {
  const std::string id = *env("JOB_COMPLETION_INDEX");
  if (!numShards)
    throw Error("JOB_COMPLETION_INDEX=" + id +
                " (a Kubernetes Indexed Job) gives this pod's part but not their number: give "
                "--num-shards with the Job's completions");
  JobPart part{
      toInt(environmentInteger(env, "JOB_COMPLETION_INDEX", 0), "JOB_COMPLETION_INDEX"), *numShards,
      "Kubernetes Indexed Job",
      assignment("JOB_COMPLETION_INDEX", id) + ", of --num-shards " + std::to_string(*numShards)};
  if (part.index >= part.count)
    throw Error("JOB_COMPLETION_INDEX=" + id + " is not a part of --num-shards " +
                std::to_string(part.count) + " (set --num-shards to the Job's completions)");
  return part;
}

// ---- training ranks ----

int intVariable(const Environment& env, const std::string& name, int fallback) {
  const long v = environmentInteger(env, name, fallback);
  if (v < -1000000000 || v > 1000000000)
    throw Error(name + "=" + std::to_string(v) + " is out of range");
  return static_cast<int>(v);
}

int portValue(const Environment& env, const std::string& name, long fallback) {
  const long port = environmentInteger(env, name, fallback);
  if (port < 1 || port > 65535)
    throw Error(name + "=" + std::to_string(port) + " is not a TCP port (1 to 65535)");
  return static_cast<int>(port);
}

void checkRank(const LaunchRole& r, const std::string& rankName, const std::string& worldName) {
  if (r.world < 1) throw Error(worldName + "=" + std::to_string(r.world) + " must be at least 1");
  if (r.rank < 0 || r.rank >= r.world)
    throw Error(rankName + "=" + std::to_string(r.rank) + " must be in [0, " + worldName + "=" +
                std::to_string(r.world) + ")");
  if (r.localRank < 0) throw Error("the local rank must be >= 0");
}

LaunchRole torchrunRole(const Environment& env) {
  LaunchRole r;
  r.world = intVariable(env, "WORLD_SIZE", 1);
  if (r.world > 1 && !env("RANK")) throw Error("WORLD_SIZE is set but RANK is not");
  r.rank = intVariable(env, "RANK", 0);
  r.localRank = intVariable(env, "LOCAL_RANK", 0);
  checkRank(r, "RANK", "WORLD_SIZE");
  r.masterAddr = env("MASTER_ADDR").value_or("127.0.0.1");
  r.masterPort = portValue(env, "MASTER_PORT", 29500);
  r.agentStore = env("TORCHELASTIC_USE_AGENT_STORE") == "True";
  r.restartCount = intVariable(env, "TORCHELASTIC_RESTART_COUNT", 0);
  r.engine = env("TORCHELASTIC_RUN_ID") ? "torchrun" : "RANK/WORLD_SIZE";
  r.detail = "RANK, WORLD_SIZE, LOCAL_RANK";
  return r;
}

// MASTER_ADDR, or the first host of the step's (else the job's) nodes.
std::string slurmMasterAddr(const Environment& env, std::string& detail) {
  if (auto given = env("MASTER_ADDR")) {
    detail += ", MASTER_ADDR";
    return *given;
  }
  for (const char* name : {"SLURM_STEP_NODELIST", "SLURM_JOB_NODELIST", "SLURM_NODELIST"})
    if (auto list = env(name)) {
      detail += std::string(", MASTER_ADDR the first host of ") + name;
      return firstSlurmHost(*list);
    }
  throw Error(
      "srun set SLURM_PROCID but no SLURM_STEP_NODELIST or SLURM_JOB_NODELIST: set "
      "MASTER_ADDR to rank 0's host");
}

int slurmPort(const Environment& env, std::string& detail) {
  if (env("MASTER_PORT")) {
    detail += ", MASTER_PORT";
    return portValue(env, "MASTER_PORT", 29500);
  }
  if (!env("SLURM_JOB_ID"))
    throw Error("srun set SLURM_PROCID but no SLURM_JOB_ID: set MASTER_PORT");
  detail += ", MASTER_PORT from SLURM_JOB_ID";
  return slurmMasterPort(environmentInteger(env, "SLURM_JOB_ID", 0));
}

LaunchRole srunRole(const Environment& env) {
  LaunchRole r;
  r.engine = "srun";
  const char* tasks = env("SLURM_NTASKS") ? "SLURM_NTASKS" : "SLURM_STEP_NUM_TASKS";
  if (!env(tasks)) throw Error("srun set SLURM_PROCID but not SLURM_NTASKS");
  r.world = intVariable(env, tasks, 1);
  r.rank = intVariable(env, "SLURM_PROCID", 0);
  r.localRank = intVariable(env, "SLURM_LOCALID", 0);
  checkRank(r, "SLURM_PROCID", tasks);
  r.detail = std::string("SLURM_PROCID, ") + tasks + ", SLURM_LOCALID";
  if (r.world > 1) {
    r.masterAddr = slurmMasterAddr(env, r.detail);
    r.masterPort = slurmPort(env, r.detail);
  }
  return r;
}

}  // namespace

Environment processEnvironment() {
  return [](const std::string& name) -> std::optional<std::string> {
    const char* v = std::getenv(name.c_str());
    if (!v || !*v) return std::nullopt;
    return std::string(v);
  };
}

long environmentInteger(const Environment& env, const std::string& name, long fallback) {
  const std::optional<std::string> v = env(name);
  if (!v) return fallback;
  long out = 0;
  const auto r = std::from_chars(v->data(), v->data() + v->size(), out);
  if (r.ec != std::errc() || r.ptr != v->data() + v->size())
    throw Error("environment variable " + name + "='" + *v + "' is not an integer");
  return out;
}

std::vector<std::string> expandSlurmHostList(const std::string& list) {
  std::vector<std::string> hosts;
  for (const std::string& item : hostListItems(list)) {
    for (std::string& h : expandItem(item, list)) hosts.push_back(std::move(h));
    if (hosts.size() > kMaxHosts)
      throw Error("Slurm host list '" + list + "': over a million hosts");
  }
  if (hosts.empty()) throw Error("Slurm host list '" + list + "' names no host");
  return hosts;
}

std::string firstSlurmHost(const std::string& list) {
  return expandSlurmHostList(list).front();
}

std::string JobPart::describe() const {
  if (source.empty()) return count > 1 ? partsOf(index, count) : "";
  return partsOf(index, count) + ", from the " + source + " (" + detail + ")";
}

JobPart jobPart(const Environment& env, std::optional<int> shardIndexFlag,
                std::optional<int> numShardsFlag) {
  if (shardIndexFlag) {
    const int count = numShardsFlag.value_or(1);
    return {*shardIndexFlag, count, "flags",
            "--shard-index " + std::to_string(*shardIndexFlag) + " --num-shards " +
                std::to_string(count)};
  }
  if (env("SLURM_ARRAY_TASK_ID")) return slurmArrayPart(env, numShardsFlag);
  if (env("JOB_COMPLETION_INDEX")) return kubernetesPart(env, numShardsFlag);
  return {0, numShardsFlag.value_or(1), "", ""};
}

std::string LaunchRole::describe() const {
  if (engine.empty()) return "";
  std::string line = "rank " + std::to_string(rank) + " of " + std::to_string(world) +
                     " (local rank " + std::to_string(localRank) + ") from " + engine + " (" +
                     detail + ")";
  if (world > 1) line += ", rendezvous at " + masterAddr + ":" + std::to_string(masterPort);
  return line;
}

LaunchRole launchRole(const Environment& env) {
  if (env("WORLD_SIZE")) return torchrunRole(env);
  if (env("SLURM_STEP_ID") && env("SLURM_PROCID")) return srunRole(env);
  LaunchRole one;
  // A batch script has SLURM_PROCID=0 and the job's SLURM_NTASKS, but only srun starts the ranks.
  const int tasks = intVariable(env, "SLURM_NTASKS", 1);
  if (env("SLURM_JOB_ID") && tasks > 1) {
    one.engine = "a Slurm batch script";
    one.detail = "SLURM_NTASKS=" + std::to_string(tasks) +
                 " but no srun step: one process; start it with srun to run " +
                 std::to_string(tasks) + " ranks";
  }
  return one;
}

int slurmMasterPort(long jobId) {
  if (jobId < 0) throw Error("SLURM_JOB_ID=" + std::to_string(jobId) + " is negative");
  return kSlurmPortBase + static_cast<int>(jobId % kSlurmPortCount);
}

}  // namespace paircast
