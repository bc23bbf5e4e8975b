// Data-parallel training through torch's own c10d: a TCPStore rendezvous at the place that the
// engine gives (launchRole: torchrun's RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT, or
// srun's SLURM_PROCID, SLURM_NTASKS, ...), ProcessGroupGloo on CPU (ProcessGroupNCCL when built
// with it, on CUDA).
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

#include "util/launch_env.h"

namespace paircast {

// This process's place from its engine's variables (launchRole of the process's environment), for
// work outside any process group. Throws paircast::Error on a bad environment.
LaunchRole environmentRole();

class Distributed {
 public:
  // nullptr for a world of one (unless PAIRCAST_PROCESS_GROUP=1, which makes a group of one).
  // Throws paircast::Error on a bad environment.
  static std::unique_ptr<Distributed> fromEnvironment(const std::string& device);
  // The process groups this build has: Gloo (CPU) and NCCL (CUDA).
  static bool hasGloo();
  static bool hasNccl();
  ~Distributed();

  int rank() const { return rank_; }
  int worldSize() const { return world_; }
  int localRank() const { return localRank_; }
  // Averages the tensors over the ranks, in place (one flattened all-reduce).
  void allReduceMean(const std::vector<torch::Tensor>& tensors);
  // Rank 0's values to every rank, in place.
  void broadcast(const std::vector<torch::Tensor>& tensors);
  void barrier();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int rank_ = 0, world_ = 1, localRank_ = 0;
};

}  // namespace paircast
