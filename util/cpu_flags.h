// The CPU's feature flags as the kernel reports them: the "flags" line of /proc/cpuinfo, which
// lists only what the OS has enabled (AVX-512 state, AMX tiles), unlike CPUID alone.
#pragma once

#include <set>
#include <string>

namespace paircast {

using CpuFlags = std::set<std::string>;  // e.g. {"avx2", "avx512f", "avx512_bf16", ...}

// The first processor's flags in a /proc/cpuinfo text; empty when it has none (not x86).
CpuFlags cpuFlagsFrom(const std::string& cpuinfo);

// This machine's flags, read once: from /proc/cpuinfo, or from the file that PAIRCAST_CPUINFO
// names (tests fake a CPU so).
const CpuFlags& cpuFlags();

// The flag of the CPU's bf16 matmul units ("amx_bf16", else "avx512_bf16"), "" when it has none.
std::string bf16UnitsFlag(const CpuFlags& flags);

}  // namespace paircast
