#!/usr/bin/env bash
# The learning test of flow fine-tuning: fine-tuned from a cross-view checkpoint, a small CroCo
# ends with held-out flow AEPE at most 0.7 of zero flow's. It runs the cheapest regime that learns
# flow (docs/finetune.md, "The regime that learns flow") through scripts/flow_pilot.sh, on the
# shipped scenes and 120 floor plans of make_scenes: cross-view pre-training, 20,000 steps of 16 on
# wide pairs of 122 scenes; the linear head fine-tuned 20,000 steps of 8 on flow-style pairs of
# 42 scenes; held out on flow-style pairs of the studio. It fails, exit status 1, when the
# fine-tune ends above the threshold.
#
#   tests/learning/flow_learns.sh [OUT]      (default OUT: BUILD_DIR/learning/flow)
#
# About 40 minutes on 2 cores alone, so it is not in the suite that scripts/test.sh and CI run (75
# minutes in all for two Debian releases); docs/releases.md says when to run it. Every stage is
# kept in OUT: a killed run continues where it stopped, and a second run only checks.
# Environment: BUILD_DIR (default build, built by scripts/build.sh), MAX_RATIO (default
# croco=0.7), SEEDS (default 0).
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-${BUILD_DIR:-build}/learning/flow}
PATCHES=16 SCALES=0 INITS=croco PRETRAIN_STEPS=20000 FINETUNE_STEPS=20000 EVAL_EVERY=1000 \
  FLOORPLANS=40 PRETRAIN_FLOORPLANS=80 FLOW_PAIRS=150 WIDE_PAIRS=150 POS_EMBED=cosine \
  SEEDS=${SEEDS:-0} \
  MAX_RATIO=${MAX_RATIO:-croco=0.7} scripts/flow_pilot.sh "$out"
echo "flow_learns: passed; the table is $out/pilot.md"
