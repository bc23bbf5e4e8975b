#!/usr/bin/env bash
# Configures and builds paircast in build/ (Release, Ninja when present). Extra arguments go to
# CMake, e.g. scripts/build.sh -DPAIRCAST_SANITIZE=address,undefined
# Environment: BUILD_DIR (default build), JOBS (parallel compile jobs, default nproc), TARGETS
# (space-separated targets to build, e.g. "generate_pairs pretrain"; default: everything).
# ccache, when installed (setup.sh installs it), caches compiles across build folders, git
# worktrees and runs: CCACHE_BASEDIR is the checkout's parent unless set, so that the same file in
# another worktree hits the cache. PAIRCAST_CCACHE=0 turns it off.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
JOBS=${JOBS:-$(nproc)}
generator=()
if command -v ninja >/dev/null; then generator=(-G Ninja); fi
launcher=()
if [[ "${PAIRCAST_CCACHE:-1}" == 1 ]] && command -v ccache >/dev/null; then
  launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(dirname "$PWD")}
  export CCACHE_MAXSIZE=${CCACHE_MAXSIZE:-8G}
fi
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]]; then
  cmake -S . -B "$BUILD_DIR" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" "$@"
elif (($#)); then
  cmake -S . -B "$BUILD_DIR" "$@"
fi
# shellcheck disable=SC2086  # TARGETS is a list of words
cmake --build "$BUILD_DIR" -j "$JOBS" ${TARGETS:+--target $TARGETS}
