#!/usr/bin/env bash
# The co-visibility ablation of docs/covis_ablation.md, as measured there: bins 0.15, 0.55 and
# 0.95 and the mae baseline, 3 seeds each, on the shipped scenes plus six random floor plans and
# two scan-like rooms, with the shipped studio held out. About an hour on 2 cores.
# Usage: scripts/covis_ablation.sh [OUT] [extra covis_sweep options]   (OUT: runs/ablation)
# Rerun the same line to resume a killed sweep.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-runs/ablation}
shift || true
[[ -x build/tools/covis_sweep ]] || TARGETS="covis_sweep make_scenes" scripts/build.sh
SCENES=$OUT/scenes
if [[ ! -f $SCENES/.done ]]; then
  build/tools/make_scenes --random 6 --seed 7 --out "$SCENES"
  build/tools/make_scenes --scan scannet --triangles 100000 --seed 3 --out "$SCENES"
  build/tools/make_scenes --scan replica --triangles 100000 --seed 4 --out "$SCENES"
  touch "$SCENES/.done"
fi
exec build/tools/covis_sweep \
  --scenes scenes/room scenes/apartment "$SCENES"/random_7_{0..5} "$SCENES/scan_replica_4" \
  "$SCENES/scan_scannet_3_vh_clean_2.ply" \
  --heldout scenes/studio --up auto \
  --mode bin --centers 0.15,0.55,0.95 --baseline mae --seeds 3 \
  --pairs-per-set 1024 --steps 1200 --out "$OUT/sweep" "$@"
