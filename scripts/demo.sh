#!/usr/bin/env bash
# Set-up, build, and the main job on the shipped scenes: CroCo pre-training pairs from
# scenes/, written as shards and in CroCo's folder layout under demo-out/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
OUT=${OUT:-demo-out}
mkdir -p "$OUT"

echo "== rendering views of the shipped apartment"
build/tools/render_view --scene scenes/apartment/apartment.obj --random 4 --out "$OUT/views" \
  --resolution 256 --seed 1

if [[ -x build/tools/generate_pairs ]]; then
  echo "== generating CroCo pairs from scenes/"
  build/tools/generate_pairs --scenes scenes --out "$OUT/pairs" --pairs-per-scene 50 \
    --resolution 256 --hfov 60 --min-covis 0.5 --seed 0 --jobs "$(nproc)" --format both \
    --save-depth
fi
echo
echo "demo outputs:"
echo "  views (PNG, depth EXR, normals EXR, camera JSON): $OUT/views"
[[ -d "$OUT/pairs" ]] && echo "  pairs (shards, CroCo layout, summary.json): $OUT/pairs"
exit 0
