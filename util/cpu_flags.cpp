#include "util/cpu_flags.h"

#include <cstdlib>
#include <fstream>
#include <sstream>

namespace paircast {

CpuFlags cpuFlagsFrom(const std::string& cpuinfo) {
  std::istringstream lines(cpuinfo);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t colon = line.find(':');
    if (colon == std::string::npos || line.compare(0, 5, "flags") != 0) continue;
    std::istringstream words(line.substr(colon + 1));
    CpuFlags flags;
    for (std::string w; words >> w;) flags.insert(w);
    return flags;
  }
  return {};
}

const CpuFlags& cpuFlags() {
  static const CpuFlags flags = [] {
    const char* fake = std::getenv("PAIRCAST_CPUINFO");
    std::ifstream in(fake && *fake ? fake : "/proc/cpuinfo");
    std::ostringstream text;
    text << in.rdbuf();
    return cpuFlagsFrom(text.str());
  }();
  return flags;
}

std::string bf16UnitsFlag(const CpuFlags& flags) {
  for (const char* f : {"amx_bf16", "avx512_bf16"})
    if (flags.count(f)) return f;
  return "";
}

}  // namespace paircast
