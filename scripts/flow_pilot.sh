#!/usr/bin/env bash
# The flow pilot: in which regime does a small CroCo learn optical flow, and does cross-view
# pre-training help it? For each patch size and flow scale, the tiny preset at 64 pixels is
# fine-tuned for flow (linear head) from random weights, from an mae checkpoint and from a
# cross-view checkpoint, on flow-style pairs (generate_pairs --motion near), and measured on
# held-out flow-style pairs of another scene against zero flow, with curves (--eval-every).
#
#   scripts/flow_pilot.sh OUT
#
# Steps (each skipped when its output exists, so a killed run continues): wide pre-training pairs
# of the training scenes (covis >= 0.5, as finetune_table.sh); flow-style pairs of the same
# scenes (training) and of the studio (held out); pre-training on cross-view completion and on
# auto-completion (mae), those INITS starts from, for each patch size, on the wide pairs of
# every training scene (on two scenes, cross-view completion memorises them:
# bench/croco_reference_probe.py); the fine-tunes; last, OUT/pilot.md (the table) and
# OUT/curves.json (held-out AEPE against steps, from each fine-tune's log.jsonl).
# Environment: BUILD_DIR (default build), PATCHES (default "8 16"), SCALES (default "0 1": 0 is
# finetune's default flow scale, img_size / 16; 1 regresses pixels), PRETRAIN_STEPS (default
# 1000, of 16 pairs), FINETUNE_STEPS (default 800, of 8 pairs), EVAL_EVERY (default 100),
# SEEDS (default "0": the fine-tunes' seeds; a seed N > 0 ends the run's name in -seedN, and
# OUT/pilot.md pairs the initialisations seed by seed), INITS (default "random mae croco"),
# FLOORPLANS (default 0: also train on this many random floor plans of make_scenes --seed 5, in
# pre-training and fine-tuning), PRETRAIN_FLOORPLANS (default 0: this many more, make_scenes
# --seed 6, in pre-training alone; "+N" in the names), FLOW_PAIRS
# (default 400: flow-style pairs a training scene), WIDE_PAIRS (wide pre-training pairs a
# training scene; default 400 with no floor plans, else 150), POS_EMBED (default cosine;
# RoPE100: CroCo v2's positions, in the run names), MAX_RATIO (INIT=RATIO: fail, exit status 1,
# when a fine-tune from INIT that this call names ends above RATIO times zero flow's held-out
# AEPE; see tests/learning/flow_learns.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/flow_pilot.sh OUT}
bin=${BUILD_DIR:-build}/tools
read -r -a patches <<< "${PATCHES:-8 16}"
read -r -a scales <<< "${SCALES:-0 1}"
read -r -a inits <<< "${INITS:-random mae croco}"
pretrain_steps=${PRETRAIN_STEPS:-1000}
finetune_steps=${FINETUNE_STEPS:-800}
eval_every=${EVAL_EVERY:-100}
read -r -a seeds <<< "${SEEDS:-${SEED:-0}}"
floorplans=${FLOORPLANS:-0}
pretrain_floorplans=${PRETRAIN_FLOORPLANS:-0}
flow_pairs=${FLOW_PAIRS:-400}
wide_pairs=${WIDE_PAIRS:-$((floorplans > 0 ? 150 : 400))}
pos_embed=${POS_EMBED:-cosine}
pe=""
[[ $pos_embed != cosine ]] && pe="-$pos_embed"
mkdir -p "$out"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}

pairs() {  # OUT/NAME PAIRS-PER-SCENE [generate_pairs flags] -- SCENES...
  local name=$1 n=$2
  shift 2
  local flags=()
  while [[ $1 != -- ]]; do flags+=("$1"); shift; done
  shift
  [[ -f "$out/$name/summary.json" ]] ||
    "$bin/generate_pairs" --scenes "$@" --out "$out/$name" --pairs-per-scene "$n" \
      --resolution 64 --save-flow --save-depth --seed 7 --quiet "${flags[@]}" > /dev/null
}
pair_count() {  # OUT/NAME's pairs, from its summary.json
  python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["pairs"])' "$out/$1/summary.json"
}
train_scenes=(scenes/room scenes/apartment)
if ((floorplans > 0)); then
  [[ -d "$out/floorplans-$floorplans" ]] ||
    "$bin/make_scenes" --random "$floorplans" --seed 5 --out "$out/floorplans-$floorplans" > /dev/null
  train_scenes+=("$out/floorplans-$floorplans")
fi
flow_train=flow-train-f$floorplans-n$flow_pairs
wide=wide-f$floorplans-n$wide_pairs
pairs "$wide" "$wide_pairs" -- "${train_scenes[@]}"
wide_n=$(pair_count "$wide")
pretrain_data=("$out/$wide/pairs-*.tar")
plans=f$floorplans
if ((pretrain_floorplans > 0)); then
  more=floorplans-pretrain-$pretrain_floorplans
  [[ -d "$out/$more" ]] ||
    "$bin/make_scenes" --random "$pretrain_floorplans" --seed 6 --out "$out/$more" > /dev/null
  pairs "wide-$more-n$wide_pairs" "$wide_pairs" -- "$out/$more"
  wide_n=$((wide_n + $(pair_count "wide-$more-n$wide_pairs")))
  pretrain_data+=("$out/wide-$more-n$wide_pairs/pairs-*.tar")
  plans+=+$pretrain_floorplans
fi
pairs "$flow_train" "$flow_pairs" --motion near --min-covis 0.6 -- "${train_scenes[@]}"
pairs flow-heldout 100 --motion near --min-covis 0.6 -- scenes/studio

for patch in "${patches[@]}"; do
  for task in croco mae; do
    [[ " ${inits[*]} " == *" $task "* ]] || continue  # only the checkpoints a fine-tune starts from
    run="$out/pretrain-$task-p$patch$pe-s$pretrain_steps-$plans"
    [[ -f "$run/summary.json" ]] ||
      "$bin/pretrain" --data "${pretrain_data[@]}" --task "$task" --preset tiny --img-size 64 \
        --patch-size "$patch" --pos-embed "$pos_embed" --batch-size 16 \
        --epochs $(((pretrain_steps * 16 + wide_n - 1) / wide_n)) \
        --max-steps "$pretrain_steps" --blr 6e-3 --seed 0 --out "$run" --quiet > /dev/null
    echo "flow_pilot: pre-trained $task with $patch-pixel patches" >&2
  done
done

pairs_n=$(pair_count "$flow_train")
finetune() {  # SEED PATCH SCALE INIT: one fine-tune, unless it is done
  local seed=$1 patch=$2 scale=$3 init=$4
  local run="$out/finetune/p$patch$pe-scale$scale-$init-s$pretrain_steps-$plans-n$flow_pairs-$finetune_steps"
  ((seed > 0)) && run+=-seed$seed
  runs_asked+=("$(basename "$run")")
  [[ -f "$run/heldout.json" ]] && return
  local ckpt=random
  [[ $init != random ]] && ckpt="$out/pretrain-$init-p$patch$pe-s$pretrain_steps-$plans/checkpoint-last.pth"
  "$bin/finetune" --task flow --head linear --init "$ckpt" --preset tiny --img-size 64 \
    --patch-size "$patch" --pos-embed "$pos_embed" --flow-scale "$scale" \
    --data "$out/$flow_train/pairs-*.tar" --eval-data "$out/flow-heldout/pairs-*.tar" \
    --batch-size 8 --epochs $(((finetune_steps * 8 + pairs_n - 1) / pairs_n)) \
    --max-steps "$finetune_steps" \
    --eval-every "$eval_every" --seed "$seed" --out "$run" --quiet > /dev/null
  echo "flow_pilot: fine-tuned p$patch-s$scale-$init, seed $seed" >&2
}
runs_asked=()
for seed in "${seeds[@]}"; do
  for patch in "${patches[@]}"; do
    for scale in "${scales[@]}"; do
      for init in "${inits[@]}"; do finetune "$seed" "$patch" "$scale" "$init"; done
    done
  done
done
check=()
if [[ -n ${MAX_RATIO:-} ]]; then
  check=(--max-ratio "$MAX_RATIO" --check-runs "$(IFS=,; echo "${runs_asked[*]}")")
fi
python3 scripts/flow_pilot.py "$out" "${check[@]}"
