#!/usr/bin/env bash
# Set-up, build, and the main job on the shipped scenes: CroCo pre-training pairs from
# scenes/ and from two homes furnished with Sweet Home 3D's models (make_scenes --furnish;
# DEMO_HOMES=0 leaves them out), written as shards and in CroCo's folder layout under demo-out/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
# Only the commands the demo runs: the tests and benchmarks are scripts/test.sh's business.
TARGETS="render_view generate_pairs make_scenes" scripts/build.sh
# pretrain and reconstruct exist when CMake found LibTorch.
targets=$(cmake --build build --target help)
if grep -qE '(^|[ .])pretrain(:|$)' <<<"$targets"; then
  TARGETS="pretrain reconstruct" scripts/build.sh
fi
OUT=${OUT:-demo-out}
mkdir -p "$OUT"

echo "== rendering views of the shipped apartment"
build/tools/render_view --scene scenes/apartment/apartment.obj --random 4 --out "$OUT/views" \
  --resolution 256 --seed 1

homes=()
if [[ ${DEMO_HOMES:-2} -gt 0 ]]; then
  echo "== furnishing ${DEMO_HOMES:-2} homes with Sweet Home 3D's models (credits.json beside each)"
  if ! build/tools/make_scenes --random "${DEMO_HOMES:-2}" --furnish --seed 1 --out "$OUT/homes" \
    2> "$OUT/homes.log"; then
    cat "$OUT/homes.log" >&2
    exit 1
  fi
  homes=("$OUT/homes")
fi

echo "== generating CroCo pairs from scenes/ ${homes[*]}"
build/tools/generate_pairs --scenes scenes "${homes[@]}" --out "$OUT/pairs" --pairs-per-scene 200 \
  --resolution 256 --hfov 60 --min-covis 0.5 --seed 0 --jobs "$(nproc)" --format both --save-depth

if [[ -x build/tools/pretrain ]]; then
  echo "== pre-training CroCo (tiny) on them for a few minutes (CPU)"
  # 128x128 crops keep the demo short on a laptop; the paper trains at 224.
  build/tools/pretrain --data "$OUT/pairs/pairs-*.tar" --preset tiny --img-size 128 \
    --batch-size 16 --epochs 20 --warmup-epochs 2 --blr 1.5e-3 --max-steps "${DEMO_STEPS:-600}" \
    --out "$OUT/train" --save-every 100 --log-every 5 --recon-every 100 --resume
  build/tools/reconstruct --checkpoint "$OUT/train/checkpoint-last.pth" \
    --image1 "$OUT/pairs/apartment/00000000_1.jpeg" --image2 "$OUT/pairs/apartment/00000000_2.jpeg" \
    --seed 1 --out "$OUT/train/reconstruction.png"
fi
echo
echo "demo outputs:"
echo "  views (PNG, depth EXR, normals EXR, camera JSON): $OUT/views"
echo "  pairs (shards, CroCo layout, summary.json, credits.json of the homes' models): $OUT/pairs"
((${#homes[@]})) && echo "  furnished homes (OBJ, credits.json; skipped models in homes.log): $OUT/homes"
[[ -d "$OUT/train" ]] && echo "  training (checkpoint-last.pth, log.jsonl, loss.svg, reconstruction.png): $OUT/train"
exit 0
