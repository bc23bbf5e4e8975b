#include "util/heap.h"

#include <sys/resource.h>

#include <cstdlib>
#include <cstring>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace paircast {

bool keepFreedMemoryForReuse() {
  const char* env = std::getenv("PAIRCAST_KEEP_FREED_MEMORY");
  if (env && std::strcmp(env, "0") == 0) return false;
#if defined(__GLIBC__)
  // No mmap(2) for large blocks (they come from the heap, whose freed memory is reused), and no
  // trimming of the heap's free top back to the kernel (-1: never).
  return mallopt(M_MMAP_MAX, 0) == 1 && mallopt(M_TRIM_THRESHOLD, -1) == 1;
#else
  return false;
#endif
}

long minorPageFaults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

}  // namespace paircast
