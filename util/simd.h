// Kernels with wider SIMD variants. The project builds for baseline x86-64 (SSE2), so that one
// binary runs everywhere. Two ways to go wider, each picked at run time:
// - PAIRCAST_AVX2 marks a function written for AVX2 with intrinsics; the caller checks
//   cpuHasAvx2(). Both variants do the same operations in the same order (AVX2 does not include
//   FMA), so they give the same results to the bit (the renderer's shading).
// - PAIRCAST_CLONES compiles one function for AVX-512, AVX2 and the baseline, and the loader
//   picks the clone the CPU runs (the co-visibility kernel, vectorised by the compiler).
//   -DPAIRCAST_CLONES= turns the clones off.
#pragma once

#include <atomic>
#include <cstdint>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define PAIRCAST_HAVE_AVX2 1
#define PAIRCAST_AVX2 __attribute__((target("avx2")))
#include <immintrin.h>
#endif

#ifndef PAIRCAST_CLONES
#if defined(__x86_64__) && defined(__has_attribute)
#if __has_attribute(target_clones)
#define PAIRCAST_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#endif
#endif
#endif
#ifndef PAIRCAST_CLONES
#define PAIRCAST_CLONES
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

#ifdef PAIRCAST_HAVE_AVX2
namespace avx2 {

// All bits set in the lanes i whose bit i is set in `bits`.
PAIRCAST_AVX2 inline __m256i laneMask(uint32_t bits) {
  const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  return _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(static_cast<int>(bits)), bit), bit);
}

}  // namespace avx2
#endif

}  // namespace paircast
