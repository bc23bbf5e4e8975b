#!/usr/bin/env bash
# Set-up, build, and the whole test suite (ctest). Used by CI (.ci/run).
#
#   scripts/test.sh              Release build in build/, every test.
#   scripts/test.sh --sanitize   AddressSanitizer + UndefinedBehaviorSanitizer build in build-asan/
#                                (RelWithDebInfo), and the tests of util, render, covis and dataset.
#   scripts/test.sh --in debian13   the same inside a Debian 13 (or debian12) chroot, made with
#                                debootstrap on the first run and kept (scripts/chroot.sh); as root.
#                                Combines with --sanitize and --require-all.
#   scripts/test.sh --require-all   fails on any skipped test, the allowed ones below included.
#
# Before the build, scripts/check_history.sh fails on comments, help text or docs that narrate
# history (it belongs in git log). After ctest, scripts/skip_policy.py reads each skipped test's
# reason (ctest's JUnit file, and pytest's for the Python tests) and fails on any skip that is not
# allowed on CI's machines. It prints the skips it allowed and why. The allowed skips:
#   - CUDA without a GPU: the Cuda.* tests and Pretrain.CudaStep, "no CUDA device".
#   - torchrun on Debian 13's torch (no libuv): the Torchrun.* test, on Debian 13 only.
#   - the pthread-OpenBLAS warning where only the OpenMP OpenBLAS is installed (setup.sh's choice):
#     Pretrain.WarnsOnThePthreadOpenBlas.
# Every other skip fails the run: a missing package, ../shared/scenes absent, Slurm unable to run
# (tests/launch/slurm_cluster.sh check exits 3). The policy applies to the tests that ran, so it
# follows CTEST_ARGS. docs/releases.md, "Skips", has the list and the reasons.
#
# Then scripts/test_inventory.py compares the tests the build registered with
# tests/registered_tests.txt, and fails naming the tests and modules a missing dependency left out
# (no pybind11: no Python test; no GoogleTest: none at all). A CTEST_ARGS filter that matches no
# test fails too.
#
# Why --sanitize leaves out model/, trainer/ and sweep/: the prebuilt LibTorch is not instrumented,
# so ASan checks none of its code, and its tests (CroCo forward/backward passes, training runs)
# become too slow for the 600 s ctest limit on a small machine. Our own code that reads untrusted
# checkpoints (model/checkpoint.cpp) is instead run under ASan+UBSan by the fuzz_checkpoint target
# (scripts/fuzz.sh). See docs/reliability.md, "Fuzzing and sanitizers", for the measured times.
#
# Environment: BUILD_DIR (default build, or build-asan with --sanitize), JOBS (parallel compile
# jobs and tests, default nproc), CTEST_ARGS (extra ctest arguments, e.g. "-R Shard").
set -euo pipefail
cd "$(dirname "$0")/.."

sanitize=0
require_all=0
release=""
args=("$@")
for ((i = 0; i < ${#args[@]}; ++i)); do
  arg=${args[i]}
  case "$arg" in
    --sanitize) sanitize=1 ;;
    --require-all) require_all=1 ;;
    --in)
      release=${args[i + 1]:-}
      if [[ -z "$release" ]]; then
        echo "test.sh: --in needs a release (debian12 or debian13)" >&2
        exit 2
      fi
      ((++i))
      ;;
    -h | --help)
      sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
      exit 0
      ;;
    *)
      echo "test.sh: unknown argument '$arg' (use --sanitize, --require-all, --in RELEASE or" \
        "nothing)" >&2
      exit 2
      ;;
  esac
done
if [[ -n "$release" ]]; then
  inner=()
  ((sanitize)) && inner+=(--sanitize)
  ((require_all)) && inner+=(--require-all)
  exec scripts/chroot.sh "$release" scripts/test.sh "${inner[@]}"
fi

scripts/check_history.sh

JOBS=${JOBS:-$(nproc)}
export JOBS
scripts/setup.sh
if ((sanitize)); then
  export BUILD_DIR=${BUILD_DIR:-build-asan}
  # Exported before the build too: gtest_discover_tests runs each test binary at build time.
  source scripts/sanitizers/env.sh
  scripts/build.sh "${PAIRCAST_ASAN_CMAKE_ARGS[@]}"
else
  scripts/build.sh
fi
policy=$PWD/scripts/skip_policy.py inventory=$PWD/scripts/test_inventory.py
cd "${BUILD_DIR:-build}"
# Where each test's output, skip messages included, is kept whole for the skip policy; the
# python test writes pytest's (tests/CMakeLists.txt). Removed first: only this run's tests count.
junit=$PWD/Testing/ctest-junit.xml pytest_junit=$PWD/Testing/pytest-junit.xml
rm -f "$junit" "$pytest_junit"
status=0
# shellcheck disable=SC2086  # CTEST_ARGS is a list of words
ctest --output-on-failure -j "$JOBS" --timeout 600 --output-junit "$junit" --no-tests=error \
  --test-output-size-passed 1000000 ${CTEST_ARGS:-} || status=$?
python3 "$inventory" check . "$junit" || ((status)) || status=1
policy_args=("$junit" "$pytest_junit")
((require_all)) && policy_args=(--require-all "${policy_args[@]}")
python3 "$policy" "${policy_args[@]}" || ((status)) || status=1
exit "$status"
