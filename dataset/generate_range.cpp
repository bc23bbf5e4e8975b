#include "dataset/generate_range.h"

#include <omp.h>

namespace paircast {

std::vector<std::optional<PairSample>> generateRange(const GeneratorOf& generatorOf, uint64_t seed,
                                                     uint64_t first, int count, int threads) {
  std::vector<std::optional<PairSample>> out(count > 0 ? count : 0);
  if (threads <= 0) threads = omp_get_max_threads();
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int i = 0; i < count; ++i) {
    const uint64_t index = first + static_cast<uint64_t>(i);
    out[i] = generatorOf(index).generate(seed, index);
  }
  return out;
}

}  // namespace paircast
