// Wall-clock seconds since a time point, on the steady clock.
#pragma once

#include <chrono>

namespace paircast {

using SteadyClock = std::chrono::steady_clock;

inline double secondsSince(SteadyClock::time_point t) {
  return std::chrono::duration<double>(SteadyClock::now() - t).count();
}

}  // namespace paircast
