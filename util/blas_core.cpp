#include "util/blas_core.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <optional>

namespace paircast {

namespace {

// Set before the re-execution, to the core it asked for: the new process checks, never again.
constexpr const char* kReexecMarker = "PAIRCAST_OPENBLAS_REEXEC";

// The width of a core's kernels: 1 SSE, 2 AVX, 3 AVX2, 4 AVX-512, 5 AVX-512 with bf16. The names
// are those of OpenBLAS's dynamic-arch table (driver/others/dynamic.c).
int blasCoreLevel(std::string name) {
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  static const std::map<std::string, int> levels = {
      {"katmai", 1},       {"coppermine", 1},    {"northwood", 1},  {"prescott", 1},
      {"banias", 1},       {"atom", 1},          {"core2", 1},      {"penryn", 1},
      {"dunnington", 1},   {"nehalem", 1},       {"athlon", 1},     {"opteron", 1},
      {"opteron_sse3", 1}, {"barcelona", 1},     {"nano", 1},       {"bobcat", 1},
      {"sandybridge", 2},  {"bulldozer", 2},     {"piledriver", 2}, {"steamroller", 2},
      {"excavator", 2},    {"haswell", 3},       {"zen", 3},        {"skylakex", 4},
      {"cooperlake", 5},   {"sapphirerapids", 5}};
  const auto it = levels.find(name);
  return it == levels.end() ? -1 : it->second;
}

std::string env(const char* name) {
  const char* v = std::getenv(name);
  return v ? v : "";
}

std::optional<BlasCore>& checked() {
  static std::optional<BlasCore> result;
  return result;
}

// The core as loaded, with the tests' fake before the re-execution.
BlasCore observe(const CpuFlags& flags) {
  BlasCore b;
  b.name = loadedBlasCore();
  if (const std::string fake = env("PAIRCAST_FAKE_BLAS_CORE");
      !fake.empty() && !b.name.empty() && env(kReexecMarker).empty())
    b.name = fake;
  b.expected = expectedBlasCore(flags);
  b.action = b.name.empty() ? "no OpenBLAS" : "none";
  return b;
}

}  // namespace

std::string expectedBlasCore(const CpuFlags& f) {
  const bool avx512 =
      f.count("avx512f") && f.count("avx512bw") && f.count("avx512vl") && f.count("avx512dq");
  if (avx512 && !bf16UnitsFlag(f).empty()) return "Cooperlake";
  if (avx512) return "SkylakeX";
  if (f.count("avx2") && f.count("fma")) return "Haswell";
  if (f.count("avx")) return "Sandybridge";
  if (f.count("pni")) return "Prescott";  // the kernel calls SSE3 "pni"
  return "";
}

bool olderBlasCore(const std::string& found, const std::string& expected) {
  const int a = blasCoreLevel(found), b = blasCoreLevel(expected);
  return a > 0 && b > 0 && a < b;
}

std::string loadedBlasCore() {
  using CoreName = char* (*)();
  const auto fn = reinterpret_cast<CoreName>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  const char* name = fn ? fn() : nullptr;
  return name ? name : "";
}

void checkBlasCore(const char* tool, char** argv) {
  BlasCore b = observe(cpuFlags());
  const std::string userCore = env("OPENBLAS_CORETYPE"), asked = env(kReexecMarker);
  if (env("PAIRCAST_OPENBLAS_CHECK") == "0") {
    b.action = "off";
  } else if (!userCore.empty() && asked.empty()) {
    // Set on purpose: some machines name an older core because the newer kernels of their
    // OpenBLAS misbehave on that CPU. Kept, and recorded, without a word.
    b.action = "kept OPENBLAS_CORETYPE=" + userCore;
    checked() = b;
    return;
  } else if (!asked.empty() && asked == userCore) {
    b.action = "re-executed";  // (an older core still, after it, is warned of below)
  }
  if (b.action != "off" && olderBlasCore(b.name, b.expected)) {
    if (asked.empty()) {
      setenv("OPENBLAS_CORETYPE", b.expected.c_str(), 1);
      setenv(kReexecMarker, b.expected.c_str(), 1);
      std::fflush(nullptr);
      execv("/proc/self/exe", argv);  // returns only when it failed
    }
    const std::string fix = !asked.empty() ? "this OpenBLAS did not take OPENBLAS_CORETYPE=" + asked
                                           : "set OPENBLAS_CORETYPE=" + b.expected;
    std::fprintf(stderr,
                 "%s: warning: OpenBLAS runs its %s kernels on a CPU that has %s's: float32 "
                 "matmuls run slower (%s)\n",
                 tool, b.name.c_str(), b.expected.c_str(), fix.c_str());
    b.action = "warned";
  }
  checked() = b;
}

BlasCore blasCore() {
  return checked() ? *checked() : observe(cpuFlags());
}

}  // namespace paircast
