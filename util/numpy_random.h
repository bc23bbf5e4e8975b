// NumPy's default generator, bit for bit: numpy.random.default_rng(entropy) (SeedSequence's pool
// and state, then PCG64, XSL-RR 128/64) and its Generator.integers(low, high) for ranges below
// 2^32 (Lemire's bounded draw on the buffered 32-bit output). paircast.torch draws its crops with
// NumPy; the C++ loaders draw the same ones with this, on their own threads.
#pragma once

#include <cstdint>
#include <vector>

namespace paircast {

class NumpyGenerator {
 public:
  // numpy.random.default_rng(entropy): each entry a non-negative int, split into 32-bit words.
  explicit NumpyGenerator(const std::vector<uint64_t>& entropy);
  // Generator.integers(low, high) (int64, high excluded): a value in [low, high). Needs
  // 0 < high - low <= 2^32 - 1 (the only path the loaders take); throws std::invalid_argument
  // otherwise.
  int64_t integers(int64_t low, int64_t high);
  // The next raw 64-bit output (BitGenerator.random_raw()).
  uint64_t raw();

 private:
  uint32_t next32();
  unsigned __int128 state_ = 0, inc_ = 0;
  bool hasUint32_ = false;
  uint32_t uinteger_ = 0;
};

}  // namespace paircast
