#!/usr/bin/env bash
# Does realism pay? Cross-view pre-training on furnished homes against pre-training on the same
# floor plans with box furniture, with the same budget, then fine-tuning both (and random
# weights) for flow and depth, evaluated on held-out furnished homes whose models no training
# home has. Paired 95 % intervals over seeds (scripts/finetune_table.py).
#
#   scripts/realism_table.sh OUT [SEEDS]     (default 3 seeds)
#
# Steps, each skipped when its output exists (a killed run continues): PLANS random plans
# (default 6, make_scenes --random --seed 21) written with box furniture and furnished with the
# training models (--models train); HELDOUT furnished homes (default 2, seed 99) with the
# held-out models; wide pre-training pairs (covis >= 0.5, 64 px) from each training set;
# fine-tuning pairs with flow and depth from the furnished training homes, and held-out ones;
# cross-view pre-training of the tiny preset on each (the fine-tuning table's budget: 1500 steps
# of 16); then fine-tunes of flow and depth from random weights, the box and the furnished
# checkpoints (400 steps of 8, linear heads); last OUT/table.md. Environment: BUILD_DIR,
# PLANS, HELDOUT, PRETRAIN_EPOCHS (default 30), FINETUNE_EPOCHS (default 4), PAIRS_PER_SCENE
# (default 134: about 800 pairs a set).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/realism_table.sh OUT [SEEDS]}
seeds=${2:-3}
bin=${BUILD_DIR:-build}/tools
plans=${PLANS:-6}
heldout=${HELDOUT:-2}
pretrain_epochs=${PRETRAIN_EPOCHS:-30}
epochs=${FINETUNE_EPOCHS:-4}
per_scene=${PAIRS_PER_SCENE:-134}
mkdir -p "$out"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}

scenes() {  # OUT/NAME: make_scenes with the rest of the arguments
  local name=$1
  shift
  [[ -d "$out/$name" ]] || "$bin/make_scenes" --out "$out/$name" "$@" > /dev/null
}
scenes box --random "$plans" --seed 21
scenes furnished --random "$plans" --seed 21 --furnish --models train
scenes heldout-homes --random "$heldout" --seed 99 --furnish --models heldout

pairs() {  # OUT/NAME from SCENES: wide pairs, or with flow and depth (extra arguments)
  local name=$1 from=$2 count=$3
  shift 3
  [[ -f "$out/$name/summary.json" ]] ||
    "$bin/generate_pairs" --scenes "$out/$from" --out "$out/$name" --pairs-per-scene "$count" \
      --resolution 64 --seed 7 --quiet "$@" > /dev/null
}
pairs wide-box box "$per_scene"
pairs wide-furnished furnished "$per_scene"
pairs train furnished "$per_scene" --save-flow --save-depth
pairs heldout heldout-homes 50 --save-flow --save-depth

for set in box furnished; do
  [[ -f "$out/pretrain-$set/summary.json" ]] ||
    "$bin/pretrain" --data "$out/wide-$set/pairs-*.tar" --task croco --preset tiny --img-size 64 \
      --batch-size 16 --epochs "$pretrain_epochs" --blr 6e-3 --seed 0 \
      --out "$out/pretrain-$set" --quiet > /dev/null
  echo "realism_table: pre-training on $set scenes done" >&2
done

for ((seed = 0; seed < seeds; ++seed)); do
  for task in flow depth; do
    for init in random box furnished; do
      run="$out/finetune/$task-$init-$seed"
      [[ -f "$run/heldout.json" ]] && continue
      ckpt=random
      [[ $init != random ]] && ckpt="$out/pretrain-$init/checkpoint-last.pth"
      "$bin/finetune" --task "$task" --head linear --init "$ckpt" --preset tiny --img-size 64 \
        --data "$out/train/pairs-*.tar" --eval-data "$out/heldout/pairs-*.tar" \
        --batch-size 8 --epochs "$epochs" --warmup-epochs 1 --blr 1e-2 --seed "$seed" \
        --out "$run" --quiet > /dev/null
      echo "realism_table: $task from $init, seed $seed done" >&2
    done
  done
done
INITS=random,box,furnished python3 scripts/finetune_table.py "$out" "$seeds" flow depth
