// Which kernels OpenBLAS runs. It picks them at load time from CPUID and can fall back to an
// older core than the CPU has (Prescott's for an AVX-512 Xeon on some VMs): float32 matmuls
// then run up to 3x slower and nothing says so. The start-up check (runTool)
// compares its core with the CPU's flags and, where it is older, executes the command again with
// OPENBLAS_CORETYPE set, which OpenBLAS reads only when it loads.
//
// Environment: PAIRCAST_OPENBLAS_CHECK=0 turns the check off; an OPENBLAS_CORETYPE the user set
// is kept and recorded, without a warning (machines set an older core on purpose where newer
// kernels misbehave on their CPU); PAIRCAST_FAKE_BLAS_CORE makes the loaded core read as that
// name until the re-execution (tests).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "util/cpu_flags.h"

namespace paircast {

struct BlasCore {
  std::string name;      // openblas_get_corename(), e.g. "Haswell"; "" without OpenBLAS
  std::string expected;  // the newest core the CPU's flags allow, e.g. "Cooperlake"; "" unknown
  // "none" (nothing to fix), "re-executed" (with OPENBLAS_CORETYPE=expected), "warned" (older,
  // and not fixed), "kept OPENBLAS_CORETYPE=<core>" (the user's), "off"
  // (PAIRCAST_OPENBLAS_CHECK=0) or "no OpenBLAS".
  std::string action;
  nlohmann::json toJson() const {
    return {{"name", name}, {"expected", expected}, {"action", action}};
  }
};

// The OpenBLAS core whose kernels the flags allow: Cooperlake (avx512_bf16 or amx_bf16 with
// AVX-512), SkylakeX (avx512f, bw, vl, dq), Haswell (avx2 and fma), Sandybridge (avx), Prescott
// (sse3); "" for none of them.
std::string expectedBlasCore(const CpuFlags& flags);

// Whether core `found` is older (runs narrower kernels) than `expected`; false when either is
// not a core this knows.
bool olderBlasCore(const std::string& found, const std::string& expected);

// The core the loaded OpenBLAS runs, "" when none is loaded.
std::string loadedBlasCore();

// The start-up check of a command (`tool` names it in warnings): may replace the process by
// itself, run again with `argv` and OPENBLAS_CORETYPE set. Warns once where the core stays older.
void checkBlasCore(const char* tool, char** argv);

// What checkBlasCore found, or, where no command ran it (tests, Python), the core as it is.
BlasCore blasCore();

}  // namespace paircast
