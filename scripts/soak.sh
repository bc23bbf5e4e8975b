#!/usr/bin/env bash
# Load test of generate_pairs (docs/reliability.md, "Load"):
#
#   scripts/soak.sh [MINUTES]        # default 10
#
# 1. Eight scenes: the three shipped ones and five random floor plans (make_scenes --random),
#    listed 40 x JOBS times over in a scene list, 150 pairs each. Scenes are taken in list order
#    and freed after their last pair, so the run keeps loading and freeing scenes: memory that
#    any of that leaks shows as growth.
# 2. generate_pairs on that list with --jobs equal to the cores, for MINUTES (Release build in
#    build/). Every 10 s it samples the pairs done and the resident set size (VmRSS) into
#    build/soak/samples.csv, then stops the run with SIGKILL and resumes the first two rounds of
#    the list over the same output, which must finish cleanly.
# 3. A short run of the same command from the AddressSanitizer build (build-asan/, built as
#    scripts/test.sh --sanitize builds it) with LeakSanitizer on: any leak fails it.
#
# Prints the pairs/s of every minute, the RSS at the start, after the first minute and at the
# end, and a verdict: the rate is steady when every minute after the first is within 25 % of
# their median, and memory is flat when RSS grows by less than 16 MB + 5 % after the first
# minute. Exits non-zero when either fails or LeakSanitizer reports a leak.
#
# Environment: SOAK_DIR (default build/soak), JOBS (default nproc), SKIP_LSAN=1 to skip step 3.
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-10}
SOAK_DIR=${SOAK_DIR:-build/soak}
JOBS=${JOBS:-$(nproc)}
scripts/setup.sh
[[ -x build/tools/generate_pairs && -x build/tools/make_scenes ]] || scripts/build.sh

rm -rf "$SOAK_DIR"
mkdir -p "$SOAK_DIR/scenes"
build/tools/make_scenes --random 5 --seed 2026 --out "$SOAK_DIR/scenes" >/dev/null
eight=("$PWD"/scenes/{room,apartment,studio}/*.obj "$(realpath "$SOAK_DIR")"/scenes/*/*.obj)
((${#eight[@]} == 8)) || { echo "soak.sh: expected 8 scenes, found ${#eight[@]}" >&2; exit 1; }
rounds=$((40 * JOBS))
for ((r = 0; r < rounds; r++)); do printf '%s\n' "${eight[@]}"; done >"$SOAK_DIR/scenes.txt"
head -16 "$SOAK_DIR/scenes.txt" >"$SOAK_DIR/scenes-2-rounds.txt"
args=(--pairs-per-scene 150 --resolution 256 --min-covis 0.5 --seed 0 --jobs "$JOBS"
  --format shards --out "$SOAK_DIR/out")

echo "soak.sh: generate_pairs on 8 scenes x $rounds rounds, --jobs $JOBS, for $minutes min" \
  "(log: $SOAK_DIR/run.log)"
build/tools/generate_pairs --scenes "$SOAK_DIR/scenes.txt" "${args[@]}" 2>"$SOAK_DIR/run.log" &
pid=$!
samples="$SOAK_DIR/samples.csv"
echo "seconds,pairs_done,rss_kb" >"$samples"
start=$(date +%s)
end=$((start + minutes * 60))
while kill -0 "$pid" 2>/dev/null && (($(date +%s) < end)); do
  sleep 10
  rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$pid/status" 2>/dev/null || echo "")
  done_=$(grep -o '\] [0-9]*/' "$SOAK_DIR/run.log" | tail -1 | tr -dc '0-9')
  [[ -n $rss ]] && echo "$(($(date +%s) - start)),${done_:-0},$rss" >>"$samples"
done
if ! kill -0 "$pid" 2>/dev/null; then
  wait "$pid" || true
  echo "soak.sh: FAIL: generate_pairs ended early:" >&2
  tail -3 "$SOAK_DIR/run.log" >&2
  exit 1
fi
kill -KILL "$pid"
wait "$pid" 2>/dev/null || true

# The killed run resumes: its first two rounds (done long before the kill) over the same output.
echo "soak.sh: killed after $minutes min; resuming the list's first two rounds over the same output"
status=0
if build/tools/generate_pairs --scenes "$SOAK_DIR/scenes-2-rounds.txt" "${args[@]}" --quiet \
  >"$SOAK_DIR/resume.json" 2>"$SOAK_DIR/resume.log"; then
  resumed=$(tail -1 "$SOAK_DIR/resume.json" | grep -o '"pairs":[0-9]*\|"pairs_this_run":[0-9]*' | tr '\n' ' ')
  echo "resumed run: finished ($resumed)"
else
  echo "soak.sh: FAIL: the resumed run failed:" >&2
  tail -3 "$SOAK_DIR/resume.log" >&2
  status=1
fi

awk -F, -v minutes="$minutes" '
  BEGIN { n = 0 }
  NR == 1 { next }
  { t[n] = $1; d[n] = $2; r[n] = $3; n++ }
  END {
    # pairs done at each whole minute (the last sample at or before it)
    for (m = 1; m <= minutes; m++) {
      best = -1
      for (i = 0; i < n; i++) if (t[i] <= m * 60) best = i
      done_at[m] = best >= 0 ? d[best] : 0
    }
    done_at[0] = 0
    line = "pairs/s per minute:"
    k = 0
    for (m = 1; m <= minutes; m++) {
      rate[m] = (done_at[m] - done_at[m - 1]) / 60.0
      line = line sprintf(" %.1f", rate[m])
      if (m > 1) { later[k++] = rate[m] }
    }
    print line
    # median of the minutes after the first
    for (i = 0; i < k; i++) for (j = i + 1; j < k; j++) if (later[j] < later[i]) { x = later[i]; later[i] = later[j]; later[j] = x }
    med = k ? (k % 2 ? later[int(k / 2)] : (later[k / 2 - 1] + later[k / 2]) / 2) : 0
    steady = 1
    for (m = 2; m <= minutes; m++) if (med <= 0 || rate[m] < 0.75 * med || rate[m] > 1.25 * med) steady = 0
    # RSS: first sample, the first sample after a minute, the last; and the largest
    after = -1; maxr = 0
    for (i = 0; i < n; i++) { if (after < 0 && t[i] >= 60) after = i; if (r[i] > maxr) maxr = r[i] }
    if (after < 0) after = 0
    growth = r[n - 1] - r[after]
    flat = growth < 16384 + 0.05 * r[after]
    printf "median %.1f pairs/s over minutes 2-%d; %d pairs in all\n", med, minutes, d[n - 1]
    printf "RSS: %.1f MB at %d s, %.1f MB at %d s, %.1f MB at %d s (largest %.1f MB): %+.1f MB after the first minute\n", r[0] / 1024, t[0], r[after] / 1024, t[after], r[n - 1] / 1024, t[n - 1], maxr / 1024, growth / 1024
    printf "rate %s, memory %s\n", steady ? "steady" : "NOT steady", flat ? "flat" : "NOT flat"
    exit !(steady && flat)
  }' "$samples" || status=1

if [[ ${SKIP_LSAN:-0} != 1 ]]; then
  source scripts/sanitizers/env.sh
  BUILD_DIR=build-asan scripts/build.sh "${PAIRCAST_ASAN_CMAKE_ARGS[@]}" >"$SOAK_DIR/asan-build.log" 2>&1 ||
    { echo "soak.sh: the ASan build failed (log: $SOAK_DIR/asan-build.log)" >&2; exit 1; }
  echo "soak.sh: LeakSanitizer run (build-asan/tools/generate_pairs, 16 scene loads x 4 pairs)"
  if build-asan/tools/generate_pairs --scenes "$SOAK_DIR/scenes-2-rounds.txt" --pairs-per-scene 4 \
    --resolution 128 --jobs "$JOBS" --out "$SOAK_DIR/lsan" --quiet >/dev/null 2>"$SOAK_DIR/lsan.log"; then
    echo "LeakSanitizer: no leak, no ASan or UBSan report"
  else
    echo "soak.sh: FAIL: the sanitizer run failed (log: $SOAK_DIR/lsan.log):" >&2
    grep -m3 -E "ERROR|SUMMARY|runtime error" "$SOAK_DIR/lsan.log" >&2 || tail -3 "$SOAK_DIR/lsan.log" >&2
    status=1
  fi
fi
exit "$status"
