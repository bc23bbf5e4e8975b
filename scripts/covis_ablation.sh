#!/usr/bin/env bash
# The co-visibility ablation of docs/covis_ablation.md, as measured there: bins 0.15, 0.55 and
# 0.95, CroCo's own set (uniform 0.50: covis >= 0.5) and the mae baseline, 3 seeds each, on the
# shipped scenes plus six random floor plans and two scan-like rooms. Held out: the shipped
# studio and a seventh random floor plan, so that the reference-use probe has a view 2 from
# another scene. The tiny model at 64 px with 8 px patches (an 8 x 8 grid), 640 steps of 16 per
# run: the budget the pilot of docs/covis_ablation.md chose. Then every run, and each seed's
# random weights, fine-tuned for flow and depth (--downstream; linear heads, 200 steps of 8 on
# 512 pairs of the training scenes) and measured on 256 held-out pairs. About 90 minutes on
# 2 cores; fine-tunes that exist are reused, so adding --downstream to a finished study only
# fine-tunes.
# FURNISH=1 furnishes the random plans with Sweet Home 3D's models instead of boxes
# (make_scenes --furnish: the training plans with --models train, the held-out one with
# --models heldout; docs/scenes.md, "Furnished homes"), in another OUT.
# BUDGET=flow runs the study at the budget that learns flow (docs/finetune.md, "The regime that
# learns flow"): 16 px patches, 18,300 pairs per set and 20,000 steps of 16 on the shipped room
# and apartment plus 120 random floor plans, then every run and each seed's random weights
# fine-tuned for flow alone, 20,000 steps of 8 on 6,344 flow-style pairs (6,300 asked for).
# About 10 hours of one process on 2 cores, and about 6 in two; NSEEDS=1 first gives one seed of
# every set, and the same line with NSEEDS=3 later adds the other two.
# NSEEDS is how many seeds each set and baseline trains with (covis_sweep --seeds; 3), not a
# list of seeds as flow_pilot.sh's SEEDS is. FIRST_SEED (0) is the first seed's index
# (covis_sweep --first-seed): a study can so run in parts, one seed or more each, on several
# machines or days, each part in its own OUT; `build/tools/covis_sweep --merge PART/sweep-flow...
# --out MERGED` then writes the report of all their seeds from the parts' results.json files.
# PROCESSES (2) is how many runs train at once (covis_sweep --processes), each on 1/PROCESSES of
# the threads (OMP_NUM_THREADS, else the cores): on 2 cores two one-thread runs train 1.7x
# faster than one two-thread run.
# Precision: covis_sweep's --amp auto (bf16 on CPUs with bf16 units). The 3-seed study's figures
# in docs/covis_ablation.md were measured with --amp none (float32), which the extra options
# take, in one process (PROCESSES=1; two differ from it in floating-point order alone); the flow
# budget runs with auto.
# Usage: [BUDGET=study|flow] [NSEEDS=3] [FIRST_SEED=0] [PROCESSES=2]
#        scripts/covis_ablation.sh [OUT] [extra covis_sweep options]
# (OUT: runs/ablation). Rerun the same line to resume a killed sweep.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${BUDGET:-study}
seeds=${NSEEDS:-3}
first_seed=${FIRST_SEED:-0}
processes=${PROCESSES:-2}
if [[ $budget != study && $budget != flow ]]; then
  echo "covis_ablation.sh: BUDGET is study or flow, not '$budget'" >&2
  exit 2
fi
if [[ ! $seeds =~ ^[1-9][0-9]{0,2}$ ]]; then
  echo "covis_ablation.sh: NSEEDS is a whole number from 1 to 999, not '$seeds'" >&2
  exit 2
fi
if [[ ! $first_seed =~ ^(0|[1-9][0-9]{0,2})$ ]] || ((first_seed + seeds > 1000)); then
  echo "covis_ablation.sh: FIRST_SEED is a whole number from 0 and FIRST_SEED + NSEEDS at" \
    "most 1000, not '$first_seed'" >&2
  exit 2
fi
if [[ ! $processes =~ ^[1-9][0-9]?$ ]] || ((processes > 64)); then
  echo "covis_ablation.sh: PROCESSES is a whole number from 1 to 64, not '$processes'" >&2
  exit 2
fi
OUT=${1:-runs/ablation}
shift || true
SCENES=$OUT/scenes
furnish=() heldout_furnish=()
if [[ ${FURNISH:-0} == 1 ]]; then
  furnish=(--furnish --models train) heldout_furnish=(--furnish --models heldout)
fi
heldout_opts=(--random 1 --seed 99 "${heldout_furnish[@]}")
plans40_opts=(--random 40 --seed 5 "${furnish[@]}")
plans80_opts=(--random 80 --seed 6 "${furnish[@]}")
study_scenes="study${furnish[*]:+ ${furnish[*]}}"  # the six plans and two scans of the study

made_with() {  # DIR WHAT: true when DIR/.done says it was made with WHAT; refuses other options
  local dir=$1 what=$2 made
  [[ -f $dir/.done ]] || return 1
  made=$(cat "$dir/.done")
  [[ -z $made || $made == "$what" ]] && return 0  # empty: made before .done kept the options
  echo "covis_ablation.sh: $dir was made with '$made', not '$what': give another OUT" >&2
  exit 2
}

make_once() {  # DIR MAKE_SCENES_ARGS...: make_scenes into DIR unless it was made there before
  local dir=$1
  shift
  made_with "$dir" "make_scenes $*" && return
  build/tools/make_scenes "$@" --out "$dir"
  echo "make_scenes $*" > "$dir/.done"
}

# An OUT whose scenes were made with other options (FURNISH) is refused before anything is built.
made_with "$SCENES/heldout" "make_scenes ${heldout_opts[*]}" || true
if [[ $budget == study ]]; then
  made_with "$SCENES" "$study_scenes" || true
else
  made_with "$SCENES/plans40" "make_scenes ${plans40_opts[*]}" || true
  made_with "$SCENES/plans80" "make_scenes ${plans80_opts[*]}" || true
fi
[[ -x build/tools/covis_sweep ]] || TARGETS="covis_sweep make_scenes" scripts/build.sh

make_once "$SCENES/heldout" "${heldout_opts[@]}"
held=(--heldout scenes/studio "$SCENES/heldout/random_99_0")
if [[ $budget == study ]]; then
  if ! made_with "$SCENES" "$study_scenes"; then
    build/tools/make_scenes --random 6 --seed 7 "${furnish[@]}" --out "$SCENES"
    build/tools/make_scenes --scan scannet --triangles 100000 --seed 3 --out "$SCENES"
    build/tools/make_scenes --scan replica --triangles 100000 --seed 4 --out "$SCENES"
    echo "$study_scenes" > "$SCENES/.done"
  fi
  exec build/tools/covis_sweep \
    --scenes scenes/room scenes/apartment "$SCENES"/random_7_{0..5} "$SCENES/scan_replica_4" \
    "$SCENES/scan_scannet_3_vh_clean_2.ply" "${held[@]}" --up auto \
    --sets bin_0.15,bin_0.55,bin_0.95,uniform_0.50 --baseline mae --seeds "$seeds" \
    --first-seed "$first_seed" --img-size 64 --patch-size 8 --resolution 73 \
    --pairs-per-set 1024 --steps 640 \
    --downstream flow,depth --finetune-steps 200 --finetune-pairs 512 --finetune-eval-pairs 256 \
    --processes "$processes" --out "$OUT/sweep" "$@"
fi
make_once "$SCENES/plans40" "${plans40_opts[@]}"
make_once "$SCENES/plans80" "${plans80_opts[@]}"
exec build/tools/covis_sweep \
  --scenes scenes/room scenes/apartment "$SCENES/plans40" "$SCENES/plans80" "${held[@]}" --up y \
  --sets bin_0.15,bin_0.55,bin_0.95,uniform_0.50 --baseline mae --seeds "$seeds" \
  --first-seed "$first_seed" --img-size 64 --patch-size 16 --resolution 73 \
  --pairs-per-set 18300 --steps 20000 \
  --downstream flow --finetune-steps 20000 --finetune-pairs 6300 --finetune-eval-pairs 256 \
  --processes "$processes" --out "$OUT/sweep-flow" "$@"
