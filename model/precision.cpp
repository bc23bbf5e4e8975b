#include "model/precision.h"

#include <atomic>
#include <cstdio>

#include "util/error.h"

namespace paircast {

void checkAmp(const std::string& amp) {
  if (amp != "auto" && amp != "bf16" && amp != "fp16" && amp != "none")
    throw OptionError("amp", "mixed precision must be auto, bf16, fp16 or none, not '" + amp + "'");
}

Precision resolvePrecision(const std::string& amp, at::DeviceType device, const CpuFlags& flags) {
  checkAmp(amp);
  Precision p;
  p.requested = amp;
  p.device = device;
  if (device == at::kCUDA) {
    p.ran = amp == "none" ? "float32" : amp == "fp16" ? "fp16" : "bf16";
    p.why = amp == "auto" ? "auto: a CUDA device" : "--amp " + amp;
    return p;
  }
  if (amp == "fp16")
    throw OptionError("amp", "fp16 autocast runs on CUDA only; on the CPU use auto, bf16 or none");
  const std::string units = bf16UnitsFlag(flags);
  if (amp == "none") {
    p.why = "--amp none";
  } else if (amp == "auto") {
    p.ran = units.empty() ? "float32" : "bf16";
    p.why = units.empty() ? "auto: the CPU has no bf16 units (amx_bf16, avx512_bf16)"
                          : "auto: the CPU has " + units;
  } else {
    p.ran = "bf16";
    p.slow = units.empty();
    p.why = p.slow ? "--amp bf16, on a CPU without bf16 units" : "--amp bf16";
  }
  return p;
}

Precision resolvePrecision(const std::string& amp, at::DeviceType device, const std::string& tool) {
  const Precision p = resolvePrecision(amp, device, cpuFlags());
  static std::atomic<bool> warned{false};
  if (p.slow && !warned.exchange(true))
    std::fprintf(stderr,
                 "%s: warning: --amp bf16, but the CPU has no bf16 units (amx_bf16, avx512_bf16): "
                 "bf16 runs slowly; auto runs float32 here\n",
                 tool.c_str());
  return p;
}

}  // namespace paircast
