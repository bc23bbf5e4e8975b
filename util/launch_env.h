// What the workload manager that started this process says about its place in the job: the part
// of a generation job (a Slurm array task, a Kubernetes Indexed Job's pod) and the rank of a
// training process (torchrun, srun). Pure functions of an environment lookup, so that every
// engine's variables are tested without setting the process's own (docs/scale.md).
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace paircast {

// A variable's value, or nullopt when it is unset or empty.
using Environment = std::function<std::optional<std::string>(const std::string& name)>;

// The process's own environment (getenv).
Environment processEnvironment();

// The integer value of `name`, or `fallback` when unset. Throws paircast::Error naming the variable
// when it is not a whole decimal integer.
long environmentInteger(const Environment& env, const std::string& name, long fallback);

// Every host of a Slurm host list, in Slurm's order: "gpu[01-04,07],cpu3" gives gpu01 ... gpu04,
// gpu07, cpu3; several bracket groups multiply out ("n[1-2]-r[3-4]": n1-r3, n1-r4, n2-r3, n2-r4);
// a range keeps the zero padding of its first bound. Hosts are separated by commas or spaces.
// Throws paircast::Error on an unbalanced bracket, an empty or reversed range, or a list of
// more than a million hosts.
std::vector<std::string> expandSlurmHostList(const std::string& list);

// The first host of a Slurm host list (what MASTER_ADDR is under srun).
std::string firstSlurmHost(const std::string& list);

// This machine's part of a generation job: parts index of count, and where they came from.
struct JobPart {
  int index = 0, count = 1;
  std::string source;  // "" (one machine), "flags", "Slurm array", "Kubernetes Indexed Job"
  std::string detail;  // the flags or variables it came from
  // One line for the log ("part 1 of 3, from the Slurm array (SLURM_ARRAY_TASK_ID=2 ...)"), or
  // "" for a job of one part that nothing split.
  std::string describe() const;
};

// The part from the flags when --shard-index was given (with --num-shards, or 1 part); else
// from a Slurm array (SLURM_ARRAY_TASK_ID less SLURM_ARRAY_TASK_MIN, of SLURM_ARRAY_TASK_COUNT;
// with
// --num-shards given, the task ids are the part indices themselves); else from a Kubernetes
// Indexed Job (JOB_COMPLETION_INDEX, of --num-shards, which is then required); else one part,
// or parts of --num-shards with part 0 here. Throws paircast::Error, naming the variables, on a
// stepped array or one with gaps (without --num-shards), a non-integer, or an index out of range.
JobPart jobPart(const Environment& env, std::optional<int> shardIndexFlag,
                std::optional<int> numShardsFlag);

// A training process's place: rank of world, its local rank on the node, and the rendezvous.
struct LaunchRole {
  int rank = 0, world = 1, localRank = 0;
  std::string masterAddr = "127.0.0.1";
  int masterPort = 29500;
  // torchrun's static rendezvous (TORCHELASTIC_USE_AGENT_STORE=True): its agent already serves
  // the store at MASTER_PORT, so every rank joins it as a client, under the keys of this restart.
  bool agentStore = false;
  int restartCount = 0;  // TORCHELASTIC_RESTART_COUNT
  std::string
      engine;  // "" (none), "torchrun", "RANK/WORLD_SIZE" (set by hand or another tool), "srun"
  std::string detail;  // where the values came from
  // One line for the log ("rank 1 of 2 (local rank 1) from srun: ..."), or "" when no engine
  // said anything.
  std::string describe() const;
};

// torchrun's variables when WORLD_SIZE is set (RANK, LOCAL_RANK, MASTER_ADDR, MASTER_PORT);
// else, inside an srun step (SLURM_STEP_ID set), SLURM_PROCID of SLURM_NTASKS, local rank
// SLURM_LOCALID, MASTER_ADDR the first host of SLURM_STEP_NODELIST (or SLURM_JOB_NODELIST) and
// MASTER_PORT from SLURM_JOB_ID (slurmMasterPort), each unless given; else one process. A batch
// script's own SLURM_PROCID=0 (no step) is one process. Throws paircast::Error naming the
// variable on a non-integer, a rank outside [0, world) or a bad host list.
LaunchRole launchRole(const Environment& env);

// The rendezvous port of a Slurm job, in [kSlurmPortBase, kSlurmPortBase + kSlurmPortCount):
// unprivileged and below Linux's ephemeral range (32768 and up).
constexpr int kSlurmPortBase = 20000, kSlurmPortCount = 10000;
int slurmMasterPort(long jobId);

}  // namespace paircast
