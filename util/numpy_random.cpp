#include "util/numpy_random.h"

#include <array>
#include <stdexcept>

namespace paircast {
namespace {

// SeedSequence's constants (numpy/random/bit_generator.pyx).
constexpr uint32_t kInitA = 0x43b0d7e5, kMultA = 0x931e8875, kInitB = 0x8b51f9dd,
                   kMultB = 0x58f38ded, kMixMultL = 0xca01f9dd, kMixMultR = 0x4973f715;
constexpr int kPoolSize = 4;

std::vector<uint32_t> words(const std::vector<uint64_t>& entropy) {
  std::vector<uint32_t> out;
  for (uint64_t e : entropy) {
    out.push_back(static_cast<uint32_t>(e));  // 0 is one word, [0]
    for (e >>= 32; e > 0; e >>= 32) out.push_back(static_cast<uint32_t>(e));
  }
  return out;
}

// SeedSequence.pool of `entropy`, then generate_state(4, uint64).
std::array<uint64_t, 4> seedState(const std::vector<uint64_t>& entropy) {
  const std::vector<uint32_t> in = words(entropy);
  uint32_t hashConst = kInitA;
  auto hashmix = [&](uint32_t v) {
    v ^= hashConst;
    hashConst *= kMultA;
    v *= hashConst;
    return v ^ (v >> 16);
  };
  auto mix = [](uint32_t x, uint32_t y) {
    uint32_t r = kMixMultL * x - kMixMultR * y;
    return r ^ (r >> 16);
  };
  std::array<uint32_t, kPoolSize> pool{};
  for (int i = 0; i < kPoolSize; ++i)
    pool[i] = hashmix(i < static_cast<int>(in.size()) ? in[i] : 0);
  for (int s = 0; s < kPoolSize; ++s)
    for (int d = 0; d < kPoolSize; ++d)
      if (s != d) pool[d] = mix(pool[d], hashmix(pool[s]));
  for (size_t s = kPoolSize; s < in.size(); ++s)
    for (int d = 0; d < kPoolSize; ++d) pool[d] = mix(pool[d], hashmix(in[s]));
  std::array<uint32_t, 8> state{};
  uint32_t c = kInitB;
  for (int i = 0; i < 8; ++i) {
    uint32_t v = pool[i % kPoolSize] ^ c;
    c *= kMultB;
    v *= c;
    state[i] = v ^ (v >> 16);
  }
  std::array<uint64_t, 4> out{};
  for (int i = 0; i < 4; ++i)
    out[i] = state[2 * i] | (static_cast<uint64_t>(state[2 * i + 1]) << 32);
  return out;
}

using u128 = unsigned __int128;
constexpr u128 kMultiplier =
    (static_cast<u128>(2549297995355413924ULL) << 64) | 4865540595714422341ULL;

}  // namespace

NumpyGenerator::NumpyGenerator(const std::vector<uint64_t>& entropy) {
  const auto v = seedState(entropy);
  const u128 seed = (static_cast<u128>(v[0]) << 64) | v[1];
  const u128 inc = (static_cast<u128>(v[2]) << 64) | v[3];
  inc_ = (inc << 1) | 1;  // pcg64_srandom_r
  state_ = inc_;          // 0 stepped once
  state_ += seed;
  state_ = state_ * kMultiplier + inc_;
}

uint64_t NumpyGenerator::raw() {
  state_ = state_ * kMultiplier + inc_;
  const auto hi = static_cast<uint64_t>(state_ >> 64), lo = static_cast<uint64_t>(state_);
  const uint64_t value = hi ^ lo;
  const unsigned rot = static_cast<unsigned>(hi >> 58);
  return (value >> rot) | (value << ((64 - rot) & 63));
}

uint32_t NumpyGenerator::next32() {
  if (hasUint32_) {
    hasUint32_ = false;
    return uinteger_;
  }
  const uint64_t next = raw();
  hasUint32_ = true;
  uinteger_ = static_cast<uint32_t>(next >> 32);
  return static_cast<uint32_t>(next);
}

int64_t NumpyGenerator::integers(int64_t low, int64_t high) {
  if (!(high > low) || static_cast<uint64_t>(high - low) > 0xffffffffULL)
    throw std::invalid_argument("NumpyGenerator::integers needs 0 < high - low < 2^32");
  const auto range = static_cast<uint32_t>(high - 1 - low);  // numpy's inclusive range
  if (range == 0) return low;
  const uint64_t excl = static_cast<uint64_t>(range) + 1;
  uint64_t m = static_cast<uint64_t>(next32()) * excl;
  auto leftover = static_cast<uint32_t>(m);
  if (leftover < excl) {
    const auto threshold = static_cast<uint32_t>((0xffffffffULL - range) % excl);
    while (leftover < threshold) {
      m = static_cast<uint64_t>(next32()) * excl;
      leftover = static_cast<uint32_t>(m);
    }
  }
  return low + static_cast<int64_t>(m >> 32);
}

}  // namespace paircast
