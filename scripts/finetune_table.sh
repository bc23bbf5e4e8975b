#!/usr/bin/env bash
# The paper's fine-tuning table at our scale: the same fine-tuning budget from random weights,
# from an mae checkpoint (its encoder, a random decoder) and from a cross-view checkpoint
# (encoder and decoder), for flow, depth and relative pose, over several seeds, with paired 95 %
# intervals, and each against the task's trivial baseline.
#
#   scripts/finetune_table.sh OUT [SEEDS]     (default 3 seeds; about 20 minutes on 2 cores)
#   BUDGET=flow scripts/finetune_table.sh OUT [SEEDS]   (flow alone, at the budget that learns it)
#
# Steps (each skipped when its output exists, so a killed run continues): pairs with flow and
# depth from the shipped room and apartment (training) and studio (held out), wide ones and, for
# flow, flow-style ones (generate_pairs --motion near); pre-training of the
# tiny preset at 64 pixels on cross-view completion and on auto-completion (mae); then, for each
# seed, task and initialisation, finetune with the linear heads (pose: the pose head); last,
# OUT/table.md and OUT/table.json. Environment: BUILD_DIR (default build), PRETRAIN_EPOCHS
# (default 30: 1500 steps of 16 pairs), FINETUNE_EPOCHS (default 4: 400 steps of 8 pairs),
# TASKS (default "flow depth pose"), PATCH_SIZE (default 16: 4 x 4 patches; 8 gives 8 x 8 at
# about four times the time), POSE_BLR (default 4e-3; pose learns nothing at 1e-2:
# docs/finetune.md), PRETRAIN_ONLY=1 (stop after the two pre-trainings: scripts/pose_table.sh
# starts from them), HOMES=N (train on N homes furnished with Sweet Home 3D's training models,
# make_scenes --random N --furnish --models train --seed 21, and hold out a home of the held-out
# models, seed 99, instead of the shipped room, apartment and studio; use another OUT), AMP
# (default auto: bf16 where the CPU has bf16 units; none: float32; use another OUT).
# BUDGET (default small: the budget above) flow runs flow alone at the budget of docs/finetune.md
# that learns it, the pilot's run D: scripts/flow_pilot.sh pre-trains with 16-pixel patches for
# 20,000 steps of 16 on 150 wide pairs of each of 122 scenes (the shipped room and apartment,
# make_scenes --random 40 --seed 5 and --random 80 --seed 6) and fine-tunes each seed for
# FINETUNE_STEPS (default 20,000) steps of 8 on 150 flow-style pairs of each of the first 42,
# held out on 100 of the studio; OUT/finetune/flow-INIT-SEED name its runs, and the table ends
# with the flow targets, met or not. Precision is the tools' default, auto. HOMES, PATCH_SIZE,
# AMP, the epochs, POSE_BLR and PRETRAIN_ONLY are the small budget's and refused with
# BUDGET=flow, and an OUT holds one budget's runs (OUT/budget says which). A killed call skips
# the stages it finished. On a 2-core machine with bf16 units the pre-trainings took 17 and 14
# minutes and a fine-tune 17, so three seeds take about 3 hours.
# STUDY=DIR (with BUDGET=flow) builds the flow table from a co-visibility study's fine-tunes
# instead of training (DIR is covis_sweep's folder, OUT/sweep-flow of BUDGET=flow
# scripts/covis_ablation.sh OUT): seed k's random weights, mae and uniform_0.50 (CroCo's own
# set, as cross-view), each fine-tuned for flow by the study, measured with finetune --evaluate
# on the same 100 held-out pairs of the studio. Each seed of the study is then a seed of the table.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: [BUDGET=small|flow] scripts/finetune_table.sh OUT [SEEDS]}
seeds=${2:-3}
budget=${BUDGET:-small}
if [[ $budget != small && $budget != flow ]]; then
  echo "finetune_table.sh: BUDGET is small or flow, not '$budget'" >&2
  exit 2
fi
if [[ ! $seeds =~ ^[1-9][0-9]?$ ]]; then
  echo "finetune_table.sh: SEEDS is a whole number from 1 to 99, not '$seeds'" >&2
  exit 2
fi
if [[ $budget == flow && ${TASKS:-flow} != flow ]]; then
  echo "finetune_table.sh: BUDGET=flow fine-tunes flow alone, not TASKS '$TASKS'" >&2
  exit 2
fi
if [[ $budget == flow ]]; then  # the small budget's settings would be silently ignored
  for name in HOMES PATCH_SIZE AMP PRETRAIN_EPOCHS FINETUNE_EPOCHS POSE_BLR PRETRAIN_ONLY; do
    if [[ -n ${!name:-} ]]; then
      echo "finetune_table.sh: BUDGET=flow has settings of its own; $name is for BUDGET=small" >&2
      exit 2
    fi
  done
  if [[ ! ${FINETUNE_STEPS:-20000} =~ ^[1-9][0-9]{0,6}$ ]]; then
    echo "finetune_table.sh: FINETUNE_STEPS is a whole number from 1, not '$FINETUNE_STEPS'" >&2
    exit 2
  fi
fi
study=${STUDY:-}
if [[ -n $study && ($budget != flow || -n ${FINETUNE_STEPS:-}) ]]; then
  echo "finetune_table.sh: STUDY takes the study's flow fine-tunes as they are: BUDGET=flow," \
    "without FINETUNE_STEPS" >&2
  exit 2
fi
# An OUT holds one budget's runs: the flow budget's links would land in the small one's folders,
# and a study's measurements beside the pilot's runs.
label=$budget
[[ -n $study ]] && label=flow-study
made=small  # an OUT of before OUT/budget holds the small budget's runs
[[ -f $out/budget ]] && made=$(cat "$out/budget")
if [[ (-f $out/budget || -d $out/finetune) && $made != "$label" ]]; then
  echo "finetune_table.sh: $out holds BUDGET=$made's runs, not $label's: give another OUT" >&2
  exit 2
fi
bin=${BUILD_DIR:-build}/tools
pretrain_epochs=${PRETRAIN_EPOCHS:-30}
epochs=${FINETUNE_EPOCHS:-4}
read -r -a tasks <<< "${TASKS:-flow depth pose}"
patch=${PATCH_SIZE:-16}
amp=${AMP:-auto}
mkdir -p "$out"
echo "$label" > "$out/budget"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}

if [[ $budget == flow && -z $study ]]; then  # the pilot's run D, seed by seed, as the table's runs
  steps=${FINETUNE_STEPS:-20000} pretrain_steps=20000 plans=40 more_plans=80 per_scene=150
  PATCHES=16 SCALES=0 INITS="random mae croco" POS_EMBED=cosine MAX_RATIO='' \
    FLOORPLANS=$plans PRETRAIN_FLOORPLANS=$more_plans WIDE_PAIRS=$per_scene \
    FLOW_PAIRS=$per_scene PRETRAIN_STEPS=$pretrain_steps FINETUNE_STEPS=$steps \
    EVAL_EVERY=${EVAL_EVERY:-2000} SEEDS="$(seq -s ' ' 0 $((seeds - 1)))" \
    scripts/flow_pilot.sh "$out" > /dev/null
  mkdir -p "$out/finetune"
  for ((seed = 0; seed < seeds; ++seed)); do
    for init in random mae croco; do  # flow_pilot.sh's name for the run
      run=p16-scale0-$init-s$pretrain_steps-f$plans+$more_plans-n$per_scene-$steps
      ((seed > 0)) && run+=-seed$seed
      ln -sfnT "$run" "$out/finetune/flow-$init-$seed"
    done
  done
  INITS=random,mae,croco exec python3 scripts/finetune_table.py "$out" "$seeds" flow
fi

truth() {  # OUT/NAME PAIRS [generate_pairs flags] -- SCENES...: pairs with flow and depth, 64 px
  local name=$1 pairs=$2
  shift 2
  local flags=()
  while [[ $1 != -- ]]; do flags+=("$1"); shift; done
  shift
  [[ -f "$out/$name/summary.json" ]] ||
    "$bin/generate_pairs" --scenes "$@" --out "$out/$name" --pairs-per-scene "$pairs" \
      --resolution 64 --save-flow --save-depth --seed 7 --quiet "${flags[@]}" > /dev/null
}
# Flow fine-tunes and is held out on flow-style pairs (small, dense motions: generate_pairs
# --motion near), as docs/finetune.md's pilot; depth and pose on the wide pre-training pairs.
near=(--motion near --min-covis 0.6)

from_study() {  # OUT/finetune/flow-INIT-SEED/heldout.json from STUDY's finished flow fine-tunes
  truth flow-heldout 100 "${near[@]}" -- scenes/studio  # flow_pilot.sh's held-out pairs
  local seed init set ft run
  for ((seed = 0; seed < seeds; ++seed)); do
    for init in random mae croco; do
      set=$init
      [[ $init == croco ]] && set=uniform_0.50
      ft=$study/runs/$set/seed-$seed/finetune-flow run=$out/finetune/flow-$init-$seed
      [[ -f $run/heldout.json ]] && continue
      if [[ ! -f $ft/heldout.json ]]; then  # written when the fine-tune ends
        echo "finetune_table.sh: $ft: no finished flow fine-tune of $set, seed $seed" >&2
        exit 2
      fi
      mkdir -p "$run"
      # shellcheck disable=SC2046  # the fine-tune's model settings, one flag and value each
      "$bin/finetune" --evaluate --task flow --head linear --checkpoint "$ft/checkpoint-last.pth" \
        $(python3 -c 'import json, sys; s = json.load(open(sys.argv[1]))
print(*(f"--{k.replace(chr(95), chr(45))} {s[k]}" for k in
        ("preset", "img_size", "patch_size", "flow_scale")))' "$ft/settings.json") \
        --eval-data "$out/flow-heldout/pairs-*.tar" --quiet | tail -n 1 > "$run/heldout.tmp"
      mv "$run/heldout.tmp" "$run/heldout.json"
    done
  done
}
if [[ -n $study ]]; then
  from_study
  INITS=random,mae,croco exec python3 scripts/finetune_table.py "$out" "$seeds" flow
fi

if [[ ${HOMES:-0} -gt 0 ]]; then
  [[ -d "$out/homes" ]] ||
    "$bin/make_scenes" --random "$HOMES" --furnish --models train --seed 21 --out "$out/homes" \
      2> /dev/null > /dev/null
  [[ -d "$out/heldout-home" ]] ||
    "$bin/make_scenes" --random 1 --furnish --models heldout --seed 99 \
      --out "$out/heldout-home" 2> /dev/null > /dev/null
  train_scenes=("$out/homes") heldout_scenes=("$out/heldout-home") per_scene=$((800 / HOMES))
else
  train_scenes=(scenes/room scenes/apartment) heldout_scenes=(scenes/studio) per_scene=400
fi
truth train "$per_scene" -- "${train_scenes[@]}"
truth heldout 100 -- "${heldout_scenes[@]}"
if [[ " ${tasks[*]} " == *" flow "* ]]; then
  truth flow-train "$per_scene" "${near[@]}" -- "${train_scenes[@]}"
  truth flow-heldout 100 "${near[@]}" -- "${heldout_scenes[@]}"
fi

for task in croco mae; do
  [[ -f "$out/pretrain-$task/summary.json" ]] ||
    "$bin/pretrain" --data "$out/train/pairs-*.tar" --task "$task" --preset tiny --img-size 64 \
      --patch-size "$patch" --amp "$amp" \
      --batch-size 16 --epochs "$pretrain_epochs" --blr 6e-3 --seed 0 \
      --out "$out/pretrain-$task" --quiet > /dev/null
done
[[ ${PRETRAIN_ONLY:-0} == 1 ]] && exit 0

for ((seed = 0; seed < seeds; ++seed)); do
  for task in "${tasks[@]}"; do
    for init in random mae croco; do
      run="$out/finetune/$task-$init-$seed"
      [[ -f "$run/heldout.json" ]] && continue
      ckpt=random
      [[ $init != random ]] && ckpt="$out/pretrain-$init/checkpoint-last.pth"
      head=linear blr=1e-2 data=train
      [[ $task == pose ]] && head=pose blr=${POSE_BLR:-4e-3}
      [[ $task == flow ]] && data=flow-train
      "$bin/finetune" --task "$task" --head "$head" --init "$ckpt" --preset tiny --img-size 64 \
        --patch-size "$patch" --amp "$amp" \
        --data "$out/$data/pairs-*.tar" --eval-data "$out/${data/train/heldout}/pairs-*.tar" \
        --batch-size 8 --epochs "$epochs" --warmup-epochs 1 --blr "$blr" --seed "$seed" \
        --out "$run" --quiet > /dev/null
      echo "finetune_table: $task from $init, seed $seed done" >&2
    done
  done
done
python3 scripts/finetune_table.py "$out" "$seeds" "${tasks[@]}"
