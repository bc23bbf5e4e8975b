// Which precision a run computes in, from --amp and the device: `auto` (the default) is bf16
// autocast on CUDA and on a CPU with bf16 matmul units (AMX-BF16 or AVX512-BF16, which oneDNN
// uses), float32 on other CPUs; `bf16` and `none` force it; `fp16` (with a loss scale) is
// CUDA's alone. Weights, optimizer state and checkpoints are float32 whatever it is.
#pragma once

#include <c10/core/DeviceType.h>
#include <c10/core/ScalarType.h>

#include <nlohmann/json.hpp>
#include <string>

#include "util/cpu_flags.h"

namespace paircast {

struct Precision {
  std::string requested = "none";  // --amp: auto, bf16, fp16 or none
  std::string ran = "float32";     // bf16, fp16 or float32
  std::string why;                 // one line, e.g. "auto: the CPU has avx512_bf16"
  at::DeviceType device = at::kCPU;
  bool slow = false;  // bf16 on a CPU without bf16 units: emulated, several times slower

  bool autocast() const { return ran != "float32"; }
  at::ScalarType dtype() const { return ran == "fp16" ? at::kHalf : at::kBFloat16; }
  nlohmann::json toJson() const { return {{"requested", requested}, {"ran", ran}, {"why", why}}; }
};

// Throws OptionError("amp") unless `amp` is auto, bf16, fp16 or none.
void checkAmp(const std::string& amp);

// The precision of --amp `amp` on `device` (kCPU or kCUDA) of a CPU with `flags`. Throws
// OptionError("amp") for an unknown value and for fp16 on the CPU.
Precision resolvePrecision(const std::string& amp, at::DeviceType device, const CpuFlags& flags);

// The same on this machine's CPU; says once per process, on stderr, when bf16 will be slow.
Precision resolvePrecision(const std::string& amp, at::DeviceType device, const std::string& tool);

}  // namespace paircast
