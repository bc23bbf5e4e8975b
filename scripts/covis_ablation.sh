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
# FURNISH=1 furnishes the seven random plans with Sweet Home 3D's models instead of boxes
# (make_scenes --furnish: the six training plans with --models train, the held-out one with
# --models heldout; docs/scenes.md, "Furnished homes"), in another OUT.
# BUDGET=flow runs the study at the budget that learns flow (docs/finetune.md, "The regime that
# learns flow"): 16 px patches, 18,300 pairs per set and 20,000 steps of 16 on the shipped room
# and apartment plus 120 random floor plans, then every run and each seed's random weights
# fine-tuned for flow alone, 20,000 steps of 8 on 6,300 flow-style pairs. About 10 hours on 2
# cores; SEEDS=1 first gives one seed of every set in about 3.5 hours, and the same line with
# SEEDS=3 later adds the other two.
# Precision: covis_sweep's --amp auto (bf16 on CPUs with bf16 units); the figures of
# docs/covis_ablation.md were measured with --amp none (float32), which the extra options take.
# Usage: [BUDGET=study|flow] [SEEDS=3] scripts/covis_ablation.sh [OUT] [extra covis_sweep options]
# (OUT: runs/ablation). Rerun the same line to resume a killed sweep.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=${BUDGET:-study}
seeds=${SEEDS:-3}
if [[ $budget != study && $budget != flow ]]; then
  echo "covis_ablation.sh: BUDGET is study or flow, not '$budget'" >&2
  exit 2
fi
if [[ ! $seeds =~ ^[1-9][0-9]*$ ]]; then
  echo "covis_ablation.sh: SEEDS is a positive whole number, not '$seeds'" >&2
  exit 2
fi
OUT=${1:-runs/ablation}
shift || true
[[ -x build/tools/covis_sweep ]] || TARGETS="covis_sweep make_scenes" scripts/build.sh
SCENES=$OUT/scenes
furnish=() heldout_furnish=()
if [[ ${FURNISH:-0} == 1 ]]; then
  furnish=(--furnish --models train) heldout_furnish=(--furnish --models heldout)
fi

make_once() {  # DIR MAKE_SCENES_ARGS...: make_scenes into DIR unless it finished there before
  local dir=$1
  shift
  [[ -f $dir/.done ]] && return
  build/tools/make_scenes "$@" --out "$dir"
  touch "$dir/.done"
}

make_once "$SCENES/heldout" --random 1 --seed 99 "${heldout_furnish[@]}"
held=(--heldout scenes/studio "$SCENES/heldout/random_99_0")
if [[ $budget == study ]]; then
  if [[ ! -f $SCENES/.done ]]; then
    build/tools/make_scenes --random 6 --seed 7 "${furnish[@]}" --out "$SCENES"
    build/tools/make_scenes --scan scannet --triangles 100000 --seed 3 --out "$SCENES"
    build/tools/make_scenes --scan replica --triangles 100000 --seed 4 --out "$SCENES"
    touch "$SCENES/.done"
  fi
  exec build/tools/covis_sweep \
    --scenes scenes/room scenes/apartment "$SCENES"/random_7_{0..5} "$SCENES/scan_replica_4" \
    "$SCENES/scan_scannet_3_vh_clean_2.ply" "${held[@]}" --up auto \
    --sets bin_0.15,bin_0.55,bin_0.95,uniform_0.50 --baseline mae --seeds "$seeds" \
    --img-size 64 --patch-size 8 --resolution 73 --pairs-per-set 1024 --steps 640 \
    --downstream flow,depth --finetune-steps 200 --finetune-pairs 512 --finetune-eval-pairs 256 \
    --out "$OUT/sweep" "$@"
fi
make_once "$SCENES/plans40" --random 40 --seed 5 "${furnish[@]}"
make_once "$SCENES/plans80" --random 80 --seed 6 "${furnish[@]}"
exec build/tools/covis_sweep \
  --scenes scenes/room scenes/apartment "$SCENES/plans40" "$SCENES/plans80" "${held[@]}" --up y \
  --sets bin_0.15,bin_0.55,bin_0.95,uniform_0.50 --baseline mae --seeds "$seeds" \
  --img-size 64 --patch-size 16 --resolution 73 --pairs-per-set 18300 --steps 20000 \
  --downstream flow --finetune-steps 20000 --finetune-pairs 6300 --finetune-eval-pairs 256 \
  --out "$OUT/sweep-flow" "$@"
