#include "trainer/distributed.h"

#include <algorithm>
#include <cstdlib>

#include "model/torch_compat.h"
#include "util/error.h"

#if defined(PAIRCAST_HAVE_GLOO) || defined(PAIRCAST_HAVE_NCCL)
#define PAIRCAST_HAVE_C10D 1
#include <torch/csrc/distributed/c10d/Backend.hpp>
#include <torch/csrc/distributed/c10d/PrefixStore.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#endif
#if defined(PAIRCAST_HAVE_GLOO)
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#endif
#if defined(PAIRCAST_HAVE_NCCL)
#include <torch/csrc/distributed/c10d/ProcessGroupNCCL.hpp>
#endif

namespace paircast {

LaunchRole environmentRole() {
  return launchRole(processEnvironment());
}

#if defined(PAIRCAST_HAVE_C10D)
struct Distributed::Impl {
  c10::intrusive_ptr<c10d::Store> store;
  c10::intrusive_ptr<torch_compat::C10dGroup> group;  // Gloo's or NCCL's
};
#else
struct Distributed::Impl {};
#endif

Distributed::~Distributed() = default;

bool Distributed::hasGloo() {
#if defined(PAIRCAST_HAVE_GLOO)
  return true;
#else
  return false;
#endif
}

bool Distributed::hasNccl() {
#if defined(PAIRCAST_HAVE_NCCL)
  return true;
#else
  return false;
#endif
}

std::unique_ptr<Distributed> Distributed::fromEnvironment(const std::string& device) {
  const Environment env = processEnvironment();
  const LaunchRole role = launchRole(env);
  const int world = role.world;
  // PAIRCAST_PROCESS_GROUP=1 makes a group even for one process, so that one GPU runs the
  // multi-GPU code path (NCCL all-reduces and broadcasts) end to end.
  if (world == 1 && env("PAIRCAST_PROCESS_GROUP") != "1") return nullptr;
#if !defined(PAIRCAST_HAVE_C10D)
  (void)device;
  throw Error(
      "more than one process, but paircast was built without c10d (install libgloo-dev and "
      "rebuild)");
#else
  auto d = std::unique_ptr<Distributed>(new Distributed());
  d->world_ = world;
  d->rank_ = role.rank;
  d->localRank_ = role.localRank;
  const std::string& host = role.masterAddr;
  c10d::TCPStoreOptions opts;
  opts.port = static_cast<uint16_t>(role.masterPort);
  opts.isServer = d->rank_ == 0 && !role.agentStore;
  opts.numWorkers = static_cast<size_t>(world);
  opts.timeout = std::chrono::seconds(environmentInteger(env, "PAIRCAST_DIST_TIMEOUT", 300));
  // Since 2.4 the store asks for its libuv backend by default, and builds without libuv (Debian
  // 13's LibTorch 2.6) then refuse to start. The classic backend is in every build.
  torch_compat::useClassicTcpStore(opts);
  d->impl_ = std::make_unique<Impl>();
  d->impl_->store = c10::make_intrusive<c10d::TCPStore>(host, opts);
  if (role.agentStore)  // as torch.distributed's _create_c10d_store: this restart's own keys
    d->impl_->store = c10::make_intrusive<c10d::PrefixStore>(
        "/worker/attempt_" + std::to_string(role.restartCount), d->impl_->store);
  if (device == "cuda") {
#if defined(PAIRCAST_HAVE_NCCL)
    d->impl_->group = c10::make_intrusive<c10d::ProcessGroupNCCL>(d->impl_->store, d->rank_, world);
    return d;
#else
    throw OptionError("device",
                      "device cuda with more than one process needs a LibTorch built with NCCL");
#endif
  }
#if !defined(PAIRCAST_HAVE_GLOO)
  throw Error("more than one process on CPU needs c10d Gloo (install libgloo-dev and rebuild)");
#else
  auto options = c10d::ProcessGroupGloo::Options::create(opts.timeout);
  const std::optional<std::string> ifname = env("GLOO_SOCKET_IFNAME");
  // Each rank binds an address of its own node: the master's loopback when the job is one machine
  // by hand, else the address this node's hostname resolves to (as torch's default device).
  const bool loopback = host == "localhost" || host.rfind("127.", 0) == 0 || host == "::1";
  if (ifname)
    options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(*ifname));
  else if (loopback)
    options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname(host));
  else
    options->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
  options->threads = 2;
  d->impl_->group =
      c10::make_intrusive<c10d::ProcessGroupGloo>(d->impl_->store, d->rank_, world, options);
  return d;
#endif  // PAIRCAST_HAVE_GLOO
#endif  // PAIRCAST_HAVE_C10D
}

void Distributed::allReduceMean(const std::vector<torch::Tensor>& tensors) {
#if defined(PAIRCAST_HAVE_C10D)
  std::vector<torch::Tensor> flat;
  for (const auto& t : tensors) flat.push_back(t.reshape({-1}));
  std::vector<torch::Tensor> bucket = {torch::cat(flat)};
  impl_->group->allreduce(bucket)->wait();
  bucket[0].div_(world_);
  int64_t offset = 0;
  for (const auto& t : tensors) {
    t.copy_(bucket[0].narrow(0, offset, t.numel()).view_as(t));
    offset += t.numel();
  }
#else
  (void)tensors;
#endif
}

void Distributed::broadcast(const std::vector<torch::Tensor>& tensors) {
#if defined(PAIRCAST_HAVE_C10D)
  std::vector<torch::Tensor> ts(tensors.begin(), tensors.end());
  for (auto& t : ts) {
    std::vector<torch::Tensor> one = {t};
    impl_->group->broadcast(one)->wait();
  }
#else
  (void)tensors;
#endif
}

void Distributed::barrier() {
#if defined(PAIRCAST_HAVE_C10D)
  impl_->group->barrier()->wait();
#endif
}

}  // namespace paircast
