#!/usr/bin/env bash
# The paper's fine-tuning table at our scale: the same fine-tuning budget from random weights,
# from an mae checkpoint (its encoder, a random decoder) and from a cross-view checkpoint
# (encoder and decoder), for flow and depth, over several seeds, with paired 95 % intervals.
#
#   scripts/finetune_table.sh OUT [SEEDS]     (default 3 seeds; about 25 minutes on 2 cores)
#
# Steps (each skipped when its output exists, so a killed run continues): pairs with flow and
# depth from the shipped room and apartment (training) and studio (held out); pre-training of the
# tiny preset at 64 pixels on cross-view completion and on auto-completion (mae); then, for each
# seed, task and initialisation, finetune with the linear heads; last, OUT/table.md and
# OUT/table.json. Environment: BUILD_DIR (default build), PRETRAIN_EPOCHS (default 30: 1500
# steps of 16 pairs), FINETUNE_EPOCHS (default 4: 400 steps of 8 pairs).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/finetune_table.sh OUT [SEEDS]}
seeds=${2:-3}
bin=${BUILD_DIR:-build}/tools
pretrain_epochs=${PRETRAIN_EPOCHS:-30}
epochs=${FINETUNE_EPOCHS:-4}
mkdir -p "$out"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}

truth() {  # OUT/NAME: pairs of the scenes with flow and depth at 64 pixels
  local name=$1 pairs=$2
  shift 2
  [[ -f "$out/$name/summary.json" ]] ||
    "$bin/generate_pairs" --scenes "$@" --out "$out/$name" --pairs-per-scene "$pairs" \
      --resolution 64 --save-flow --save-depth --seed 7 --quiet > /dev/null
}
truth train 400 scenes/room scenes/apartment
truth heldout 100 scenes/studio

for task in croco mae; do
  [[ -f "$out/pretrain-$task/summary.json" ]] ||
    "$bin/pretrain" --data "$out/train/pairs-*.tar" --task "$task" --preset tiny --img-size 64 \
      --batch-size 16 --epochs "$pretrain_epochs" --blr 6e-3 --seed 0 \
      --out "$out/pretrain-$task" --quiet > /dev/null
done

for ((seed = 0; seed < seeds; ++seed)); do
  for task in flow depth; do
    for init in random mae croco; do
      run="$out/finetune/$task-$init-$seed"
      [[ -f "$run/heldout.json" ]] && continue
      ckpt=random
      [[ $init != random ]] && ckpt="$out/pretrain-$init/checkpoint-last.pth"
      "$bin/finetune" --task "$task" --head linear --init "$ckpt" --preset tiny --img-size 64 \
        --data "$out/train/pairs-*.tar" --eval-data "$out/heldout/pairs-*.tar" \
        --batch-size 8 --epochs "$epochs" --warmup-epochs 1 --blr 1e-2 --seed "$seed" \
        --out "$run" --quiet > /dev/null
      echo "finetune_table: $task from $init, seed $seed done" >&2
    done
  done
done
python3 scripts/finetune_table.py "$out" "$seeds"
