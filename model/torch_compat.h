// The one place that knows which LibTorch paircast is built with: Debian 12's 1.13 (CPU), Debian
// 13's 2.6 (CPU) or pip's 2.x (CUDA). Everything else includes this header and calls what it
// names, version-free.
//
// What changed between them:
//   2.0: at::scaled_dot_product_attention (a fused kernel: flash or memory-efficient attention on
//        CUDA, a flash kernel on CPU); an optimizer's state is keyed by the parameter's
//        TensorImpl pointer (a string of it before); c10d's Gloo and NCCL groups are
//        c10d::Backends (c10d::ProcessGroups before).
//   2.1: at::_fused_adamw_, AdamW's multi-tensor CUDA kernel (float lr overload).
//   2.4: autocast is switched per device type (set_autocast_enabled(kCUDA, on),
//        set_autocast_dtype(kCPU, bf16)); before, by set_enabled / set_cpu_enabled and
//        set_autocast_gpu_dtype / set_autocast_cpu_dtype (deprecated, with a warning, since).
//        c10d::TCPStoreOptions asks for the libuv backend by default, which builds without libuv
//        (Debian 13's) refuse to start.
#pragma once

#include <ATen/autocast_mode.h>
#include <torch/torch.h>
#include <torch/version.h>

#include <cmath>
#include <string>
#include <vector>

#include "util/error.h"

#ifndef TORCH_VERSION_MAJOR
#error "torch/version.h defines no TORCH_VERSION_MAJOR: this LibTorch is not one paircast knows"
#endif
#define PAIRCAST_TORCH_AT_LEAST(major, minor) \
  (TORCH_VERSION_MAJOR > (major) ||           \
   (TORCH_VERSION_MAJOR == (major) && TORCH_VERSION_MINOR >= (minor)))

// Declared for torch_compat::C10dGroup; c10d's headers, included where a group is made, define it.
namespace c10d {
#if PAIRCAST_TORCH_AT_LEAST(2, 0)
class Backend;
#else
class ProcessGroup;
#endif
}  // namespace c10d

namespace paircast::torch_compat {

// ---- attention ----

// softmax(q k^T / sqrt(Dh)) v over [B, H, Nq, Dh] x [B, H, Nk, Dh] -> [B, H, Nq, Dh].
inline torch::Tensor scaledDotProductAttention(const torch::Tensor& q, const torch::Tensor& k,
                                               const torch::Tensor& v) {
#if PAIRCAST_TORCH_AT_LEAST(2, 0)
  return at::scaled_dot_product_attention(q, k, v);
#else
  // The scale is applied to q [Nq, Dh], not to the scores [Nq, Nk]: matmul copies the strided
  // q into a contiguous one anyway, so the multiplication takes that copy's place.
  const double scale = 1.0 / std::sqrt(static_cast<double>(q.size(-1)));
  return torch::softmax(torch::matmul(q * scale, k.transpose(-2, -1)), -1).matmul(v);
#endif
}

// ---- mixed precision ----

// Whether autocast is on for `device` (kCPU or kCUDA), for this thread.
inline bool isAutocast(at::DeviceType device) {
#if PAIRCAST_TORCH_AT_LEAST(2, 4)
  return at::autocast::is_autocast_enabled(device);
#else
  return device == at::kCPU ? at::autocast::is_cpu_enabled() : at::autocast::is_enabled();
#endif
}

// The type autocast casts to on `device` (kCPU or kCUDA).
inline at::ScalarType autocastDtype(at::DeviceType device) {
#if PAIRCAST_TORCH_AT_LEAST(2, 4)
  return at::autocast::get_autocast_dtype(device);
#else
  return device == at::kCPU ? at::autocast::get_autocast_cpu_dtype()
                            : at::autocast::get_autocast_gpu_dtype();
#endif
}

// Autocast on `device` (kCPU or kCUDA) on or off from now on, for this thread, casting to
// `dtype` (bf16, or fp16 on CUDA). Its cache of cast weights is the caller's to clear.
inline void setAutocast(at::DeviceType device, bool enabled, at::ScalarType dtype) {
#if PAIRCAST_TORCH_AT_LEAST(2, 4)
  at::autocast::set_autocast_enabled(device, enabled);
  at::autocast::set_autocast_dtype(device, dtype);
#else
  if (device == at::kCPU) {
    at::autocast::set_cpu_enabled(enabled);
    at::autocast::set_autocast_cpu_dtype(dtype);
  } else {
    at::autocast::set_enabled(enabled);
    at::autocast::set_autocast_gpu_dtype(dtype);
  }
#endif
}

// ---- optimizers ----

// The key of parameter p's entry in an optimizer's state() map.
#if PAIRCAST_TORCH_AT_LEAST(2, 0)
inline void* optimizerStateKey(const torch::Tensor& p) {
  return p.unsafeGetTensorImpl();
}
#else
inline std::string optimizerStateKey(const torch::Tensor& p) {
  return c10::guts::to_string(p.unsafeGetTensorImpl());
}
#endif

// Whether fusedAdamW can run: at::_fused_adamw_ exists from 2.1 on.
constexpr bool kHasFusedAdamW = PAIRCAST_TORCH_AT_LEAST(2, 1);

// One AdamW step (no amsgrad, not maximising) of every tensor of params, on one CUDA device, by
// at::_fused_adamw_. steps [P]: each parameter's step count as a 0-d float tensor, already
// incremented for this step (the kernel reads it so, as Python's AdamW(fused=True) passes it).
// Throws paircast::Error without kHasFusedAdamW.
inline void fusedAdamW(const std::vector<torch::Tensor>& params,
                       const std::vector<torch::Tensor>& grads,
                       const std::vector<torch::Tensor>& expAvg,
                       const std::vector<torch::Tensor>& expAvgSq,
                       const std::vector<torch::Tensor>& steps, double lr, double beta1,
                       double beta2, double weightDecay, double eps) {
#if PAIRCAST_TORCH_AT_LEAST(2, 1)
  at::_fused_adamw_(params, grads, expAvg, expAvgSq, /*max_exp_avg_sqs=*/{}, steps, lr, beta1,
                    beta2, weightDecay, eps, /*amsgrad=*/false, /*maximize=*/false);
#else
  (void)params, (void)grads, (void)expAvg, (void)expAvgSq, (void)steps;
  (void)lr, (void)beta1, (void)beta2, (void)weightDecay, (void)eps;
  throw Error("fused AdamW needs LibTorch 2.1 or later");
#endif
}

// ---- c10d ----

// The type of c10d's Gloo and NCCL process groups, and so of the group a Distributed holds.
#if PAIRCAST_TORCH_AT_LEAST(2, 0)
using C10dGroup = c10d::Backend;
#else
using C10dGroup = c10d::ProcessGroup;
#endif

// Makes a c10d::TCPStoreOptions start the store's classic backend, which every build has.
template <typename TcpStoreOptions>
void useClassicTcpStore(TcpStoreOptions& options) {
#if PAIRCAST_TORCH_AT_LEAST(2, 4)
  options.useLibUV = false;
#else
  (void)options;  // the classic backend is the only one
#endif
}

}  // namespace paircast::torch_compat

#undef PAIRCAST_TORCH_AT_LEAST  // the versions are this header's alone
