#!/usr/bin/env bash
# Configures and builds paircast in build/ (Release, Ninja when present). Extra arguments go to
# CMake, e.g. scripts/build.sh -DPAIRCAST_SANITIZE=address,undefined
# Environment: BUILD_DIR (default build), JOBS (parallel compile jobs, default nproc), TARGETS
# (space-separated targets to build, e.g. "generate_pairs pretrain"; default: everything).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
JOBS=${JOBS:-$(nproc)}
generator=()
if command -v ninja >/dev/null; then generator=(-G Ninja); fi
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]]; then
  cmake -S . -B "$BUILD_DIR" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release "$@"
elif (($#)); then
  cmake -S . -B "$BUILD_DIR" "$@"
fi
# shellcheck disable=SC2086  # TARGETS is a list of words
cmake --build "$BUILD_DIR" -j "$JOBS" ${TARGETS:+--target $TARGETS}
