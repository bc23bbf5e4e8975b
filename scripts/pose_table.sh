#!/usr/bin/env bash
# Relative pose at a budget where it is learnt: the pose rows of scripts/finetune_table.sh on more
# scenes and ten times the steps, from random weights, from an mae checkpoint and from a
# cross-view checkpoint, over several seeds, with paired 95 % intervals and each against the
# identity.
#
#   scripts/pose_table.sh OUT [SEEDS]     (default 3 seeds; about 60 minutes on 2 cores)
#
# Steps (each skipped when its output exists, so a killed run continues): finetune_table.sh's
# two pre-trainings (OUT/table, PRETRAIN_ONLY=1); 6 random floor plans and a 100k-triangle
# Replica-like scan (make_scenes); 500 pairs with flow and depth of each of these and of the
# shipped room and apartment at 64 pixels (4,500 pairs) for training, and 150 of the shipped studio
# held out; then, for each seed and initialisation, finetune --task pose for 7 epochs of 16 pairs
# (1,967 steps, about 6 minutes) at --blr 2e-3; last, OUT/table.md and OUT/table.json.
# Environment: BUILD_DIR (default build), POSE_BLR (default 2e-3), POSE_EPOCHS (default 7).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/pose_table.sh OUT [SEEDS]}
seeds=${2:-3}
bin=${BUILD_DIR:-build}/tools
mkdir -p "$out"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}

BUDGET=small PRETRAIN_ONLY=1 scripts/finetune_table.sh "$out/table"
[[ -d $out/scenes/random_7_5 ]] ||
  "$bin/make_scenes" --random 6 --seed 7 --out "$out/scenes" > /dev/null
[[ -d $out/scenes/scan_replica_4 ]] ||
  "$bin/make_scenes" --scan replica --triangles 100000 --seed 4 --out "$out/scenes" > /dev/null

pairs() {  # OUT/NAME: pairs with flow and depth at 64 pixels
  local name=$1 pairs=$2 seed=$3
  shift 3
  [[ -f "$out/$name/summary.json" ]] ||
    "$bin/generate_pairs" --scenes "$@" --out "$out/$name" --pairs-per-scene "$pairs" \
      --shard-size 1000 --resolution 64 --save-flow --save-depth --seed "$seed" --quiet > /dev/null
}
pairs train 500 9 scenes/apartment scenes/room "$out"/scenes/random_7_{0..5} \
  "$out/scenes/scan_replica_4"
pairs heldout 150 6 scenes/studio

for ((seed = 0; seed < seeds; ++seed)); do
  for init in random mae croco; do
    run="$out/finetune/pose-$init-$seed"
    [[ -f "$run/heldout.json" ]] && continue
    ckpt=random
    [[ $init != random ]] && ckpt="$out/table/pretrain-$init/checkpoint-last.pth"
    "$bin/finetune" --task pose --init "$ckpt" --preset tiny --img-size 64 \
      --data "$out/train/pairs-*.tar" --eval-data "$out/heldout/pairs-*.tar" \
      --batch-size 16 --epochs "${POSE_EPOCHS:-7}" --warmup-epochs 1 --blr "${POSE_BLR:-2e-3}" \
      --seed "$seed" --out "$run" --quiet > /dev/null
    echo "pose_table: from $init, seed $seed done" >&2
  done
done
python3 scripts/finetune_table.py "$out" "$seeds" pose
