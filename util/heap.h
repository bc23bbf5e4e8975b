// Keeping freed memory for reuse. glibc's malloc serves each block over 32 MiB with fresh pages
// from mmap(2) and hands freed ones back to the kernel, so a training step on the CPU page-faults
// its large activations in anew every time: the kernel zeroes each page on first touch. naver/
// croco's CroCo-Flow step (tiny, 224 x 224, batch 8, 2 threads) took 6.3 s so and 3.3 s with the
// memory kept (docs/trainer.md, "Benchmark"). The training loop calls this on the CPU.
#pragma once

namespace paircast {

// From now on, large blocks come from the heap and freed memory stays with the process: its
// resident size stays at the peak of what it has used. Set PAIRCAST_KEEP_FREED_MEMORY=0 to keep
// glibc's defaults. Does nothing without glibc. Returns whether it took effect.
bool keepFreedMemoryForReuse();

// The minor page faults of the whole process so far, every thread (getrusage): what fresh memory
// costs, for benchmarks and tests to count.
long minorPageFaults();

}  // namespace paircast
