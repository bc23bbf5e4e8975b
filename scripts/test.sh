#!/usr/bin/env bash
# Set-up, build, and the whole test suite (ctest). Used by CI (.ci/run).
#
#   scripts/test.sh              Release build in build/, every test.
#   scripts/test.sh --sanitize   AddressSanitizer + UndefinedBehaviorSanitizer build in build-asan/
#                                (RelWithDebInfo), and the tests of util, render, covis and dataset.
#   scripts/test.sh --in debian13   the same inside a Debian 13 (or debian12) chroot, made with
#                                debootstrap on the first run and kept (scripts/chroot.sh); as root.
#                                Combines with --sanitize.
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
release=""
args=("$@")
for ((i = 0; i < ${#args[@]}; ++i)); do
  arg=${args[i]}
  case "$arg" in
    --sanitize) sanitize=1 ;;
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
      echo "test.sh: unknown argument '$arg' (use --sanitize, --in RELEASE or nothing)" >&2
      exit 2
      ;;
  esac
done
if [[ -n "$release" ]]; then
  inner=()
  ((sanitize)) && inner+=(--sanitize)
  exec scripts/chroot.sh "$release" scripts/test.sh "${inner[@]}"
fi

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
cd "${BUILD_DIR:-build}"
# shellcheck disable=SC2086  # CTEST_ARGS is a list of words
ctest --output-on-failure -j "$JOBS" --timeout 600 ${CTEST_ARGS:-}
