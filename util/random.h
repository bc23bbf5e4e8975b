// A seeded random source whose draws are the same on every platform and standard library:
// std::mt19937_64 is specified exactly, but std::*_distribution are not, so the few
// distributions we need are written here.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <string_view>

namespace paircast {

class Rng {
 public:
  explicit Rng(uint64_t seed) : engine_(seed) {}
  uint64_t next() { return engine_(); }
  // Uniform in [0, 1), 53 bits.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [0, n).
  uint64_t below(uint64_t n) { return n == 0 ? 0 : next() % n; }
  // Standard normal (Box-Muller, one value per call).
  double normal() {
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }

 private:
  std::mt19937_64 engine_;
};

// Mixes a run seed, a name and an index into one seed (splitmix64 over FNV-1a), so that the
// stream of item `index` of `name` does not depend on how work is split between threads.
inline uint64_t mixSeed(uint64_t seed, std::string_view name, uint64_t index) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : name) h = (h ^ c) * 1099511628211ull;
  auto splitmix = [](uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
  };
  return splitmix(splitmix(seed ^ splitmix(h)) ^ index);
}

}  // namespace paircast
