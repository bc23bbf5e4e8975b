# Sourced by scripts/test.sh --sanitize and scripts/soak.sh: the AddressSanitizer +
# UndefinedBehaviorSanitizer build (build-asan/) and the options its programs run with.
# shellcheck shell=bash
# -O1 -g1: half the compile time of -O2 -g on 2 cores (4 min against 8 for the whole suite), and
# still line numbers in every report.
PAIRCAST_ASAN_CMAKE_ARGS=(-DPAIRCAST_SANITIZE=address,undefined -DCMAKE_BUILD_TYPE=RelWithDebInfo
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
  -DPAIRCAST_WITH_TORCH=OFF -DPAIRCAST_BUILD_BENCH=OFF)
_supp="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# Full unwinding on malloc, so that a leak's stack reaches the library the suppressions name.
export ASAN_OPTIONS="halt_on_error=1:detect_leaks=1:check_initialization_order=1:strict_init_order=1:fast_unwind_on_malloc=0"
export LSAN_OPTIONS="suppressions=$_supp/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:suppressions=$_supp/ubsan.supp"
unset _supp
