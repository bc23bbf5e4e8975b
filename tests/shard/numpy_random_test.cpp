// NumpyGenerator against NumPy itself: the values below were printed by NumPy 1.24
// (numpy.random.default_rng(entropy).integers(...) and bit_generator.random_raw()), and
// tests/python/test_loader.py checks the same draws against the installed NumPy.
#include "util/numpy_random.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace paircast {
namespace {

struct Expected {
  std::vector<uint64_t> entropy;
  std::vector<int64_t> crops;          // integers(0, 33) five times
  int64_t view, zero, thousand, wide;  // integers(1, 3), (0, 1), (0, 1000), (0, 2^32 - 1)
};

TEST(NumpyGenerator, DrawsWhatNumpyDraws) {
  const std::vector<Expected> cases = {
      {{0, 0, 123, 5}, {22, 10, 24, 23, 28}, 2, 0, 357, 1767832273},
      {{7, 1, 4000000000, 99}, {30, 17, 10, 19, 24}, 2, 0, 757, 2546663863},
      {{(uint64_t{1} << 40) + 3, 2, 3, 4}, {22, 1, 26, 7, 29}, 2, 0, 491, 1795266731},  // 2 words
      {{1}, {15, 16, 24, 31, 1}, 1, 0, 822, 4074418349},
      {{0}, {28, 21, 16, 8, 10}, 1, 0, 75, 70985653},
  };
  for (const Expected& e : cases) {
    NumpyGenerator g(e.entropy);
    for (int64_t want : e.crops) EXPECT_EQ(g.integers(0, 33), want);
    EXPECT_EQ(g.integers(1, 3), e.view);
    EXPECT_EQ(g.integers(0, 1), e.zero);  // one value: no draw
    EXPECT_EQ(g.integers(0, 1000), e.thousand);
    EXPECT_EQ(g.integers(0, (int64_t{1} << 32) - 1), e.wide);
  }
  NumpyGenerator raw({3, 1, 4});
  EXPECT_EQ(raw.raw(), 13307217498242072740ULL);
  EXPECT_EQ(raw.raw(), 16898218703215279083ULL);
  EXPECT_EQ(raw.raw(), 1238292493740382943ULL);
}

TEST(NumpyGenerator, RefusesRangesItDoesNotDraw) {
  NumpyGenerator g({1});
  EXPECT_THROW(g.integers(3, 3), std::invalid_argument);
  EXPECT_THROW(g.integers(0, int64_t{1} << 33), std::invalid_argument);
}

}  // namespace
}  // namespace paircast
