// The training loop's memory reuse (util/heap.h): a large block freed and asked for again is not
// page-faulted in again. Here, not in util's tests: the sanitizers' allocators, under which
// util's tests also run, ignore glibc's settings. Each test runs in its own process (ctest), so
// glibc's defaults hold at the start of each.
#include "util/heap.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>

namespace paircast {
namespace {

constexpr size_t kBytes = size_t{96} << 20;  // over glibc's largest mmap threshold (32 MiB)

// The minor page faults of writing a fresh kBytes block and freeing it.
long faultsOfOneRound() {
  const long before = minorPageFaults();
  char* p = static_cast<char*>(std::malloc(kBytes));
  EXPECT_NE(p, nullptr);
  std::memset(p, 1, kBytes);
  asm volatile("" : : "r"(p) : "memory");  // the writes happen
  std::free(p);
  return minorPageFaults() - before;
}

TEST(KeepFreedMemory, ALargeBlockAskedForAgainIsNotFaultedInAgain) {
  faultsOfOneRound();
  const long fresh = faultsOfOneRound();  // glibc's default: new pages each time
  // 96 MiB of new pages: 24,576 faults of 4 KiB, or 48 where huge pages back them.
  EXPECT_GE(fresh, 48);
  ASSERT_TRUE(keepFreedMemoryForReuse());
  faultsOfOneRound();
  const long reused = faultsOfOneRound();
  EXPECT_LE(reused * 8, fresh) << "fresh " << fresh << ", reused " << reused;
}

TEST(KeepFreedMemory, TheEnvironmentCanTurnItOff) {
  ::setenv("PAIRCAST_KEEP_FREED_MEMORY", "0", 1);
  EXPECT_FALSE(keepFreedMemoryForReuse());
  faultsOfOneRound();
  EXPECT_GE(faultsOfOneRound(), 48);
  ::unsetenv("PAIRCAST_KEEP_FREED_MEMORY");
}

}  // namespace
}  // namespace paircast
