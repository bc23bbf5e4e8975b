// Kernels with an AVX2 variant. The project builds for baseline x86-64 (SSE2), so that one binary
// runs everywhere; a kernel that gains from eight lanes also has a function compiled for AVX2
// (PAIRCAST_AVX2), picked at run time by cpuHasAvx2(). Both variants do the same operations in
// the same order (AVX2 does not include FMA), so they give the same results to the bit.
#pragma once

#include <atomic>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define PAIRCAST_HAVE_AVX2 1
#define PAIRCAST_AVX2 __attribute__((target("avx2")))
#include <immintrin.h>
#endif

namespace paircast {

// Tests turn the AVX2 kernels off to compare them with the scalar code.
inline std::atomic<bool>& simdKernelsEnabled() {
  static std::atomic<bool> enabled{true};
  return enabled;
}

inline bool cpuHasAvx2() {
#ifdef PAIRCAST_HAVE_AVX2
  static const bool has = __builtin_cpu_supports("avx2");
  return has && simdKernelsEnabled().load(std::memory_order_relaxed);
#else
  return false;
#endif
}

}  // namespace paircast
