#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/) with clang in build-fuzz/ and runs each for SECONDS
# (default 60), starting from a copy of its seed corpus (fuzz/corpus/<target>/):
#
#   scripts/fuzz.sh [SECONDS]
#
# Prints the executions per target (libFuzzer's stat::number_of_executed_units), its coverage of
# our code (libFuzzer's last "cov:", in edges) and what each
# run left in build-fuzz/fuzz-work/<target>/artifacts/ (crash-*, leak-*, timeout-*, oom-*).
# A finding is fixed in our code and its input kept as a regression test under
# tests/regressions/<target>/ (tests/<module>/regression_inputs_test.cpp replays them).
# Exits non-zero when any target found something.
#
# Environment: BUILD_DIR (default build-fuzz), JOBS (compile jobs, default nproc), TARGETS (a
# subset, e.g. "fuzz_shard fuzz_camera_json"), FUZZ_ARGS (extra libFuzzer flags).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
BUILD_DIR=${BUILD_DIR:-build-fuzz}
JOBS=${JOBS:-$(nproc)}
ALL_TARGETS="fuzz_scene_obj fuzz_scene_ply fuzz_scene_glb fuzz_camera_json fuzz_shard
  fuzz_shard_index fuzz_sample_json fuzz_checkpoint fuzz_flo fuzz_exr fuzz_finetune_checkpoint"
TARGETS=${TARGETS:-$ALL_TARGETS}

scripts/setup.sh clang libclang-rt-14-dev  # libFuzzer and the sanitizer runtimes
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]]; then
  CC=clang CXX=clang++ cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DPAIRCAST_FUZZ=ON -DPAIRCAST_BUILD_TESTS=OFF -DPAIRCAST_BUILD_BENCH=OFF
fi
# shellcheck disable=SC2086  # TARGETS is a list of words
cmake --build "$BUILD_DIR" -j "$JOBS" --target $TARGETS

# Leaks inside assimp, LibTorch and OpenImageIO on their error paths are suppressed (see the file).
export ASAN_OPTIONS="halt_on_error=1:detect_leaks=1:allocator_may_return_null=0"
export LSAN_OPTIONS="suppressions=$PWD/scripts/sanitizers/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
export OMP_NUM_THREADS=1
status=0
summary=()
for target in $TARGETS; do
  work="$BUILD_DIR/fuzz-work/$target"
  mkdir -p "$work/corpus" "$work/artifacts"
  cp -n fuzz/corpus/"$target"/* "$work/corpus/" 2>/dev/null || true
  log="$work/fuzz.log"
  echo "fuzz.sh: $target for ${seconds}s (log: $log)"
  before=$(find "$work/artifacts" -type f | wc -l)
  rc=0
  # OpenImageIO's leak (embedded textures) is allocated inside libstdc++, which has no frame
  # pointers: only full unwinding reaches the frame its suppression names. That costs about 4x in
  # speed, so only the target that decodes embedded textures pays it.
  unwind=""
  if [[ $target == fuzz_scene_glb ]]; then unwind=":fast_unwind_on_malloc=0"; fi
  # shellcheck disable=SC2086  # FUZZ_ARGS is a list of words
  ASAN_OPTIONS="$ASAN_OPTIONS$unwind" "$BUILD_DIR/fuzz/$target" "$work/corpus" \
    -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
    -artifact_prefix="$work/artifacts/" ${FUZZ_ARGS:-} </dev/null >"$log" 2>&1 || rc=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  corpus=$(find "$work/corpus" -type f | wc -l)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | tr -dc '0-9')
  found=$(($(find "$work/artifacts" -type f | wc -l) - before))
  line=$(printf '%-18s %10s execs %7s/s  corpus %5d  cov %5s  exit %3d  new findings %d' \
    "$target" "${execs:-?}" "${rate:-?}" "$corpus" "${cov:-?}" "$rc" "$found")
  summary+=("$line")
  if ((rc != 0 || found > 0)); then
    status=1
    grep -m1 -E "ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer)|runtime error|terminate called|Test unit written" \
      "$log" | sed 's/^/  /' || true
  fi
done
echo
echo "fuzz.sh: ${seconds}s per target"
printf '%s\n' "${summary[@]}"
exit "$status"
