#!/usr/bin/env bash
# The whole trainer on a GPU machine, in one go (about 6 minutes on an H200 with 16 cores): the
# trainer-only build (PAIRCAST_WITH_RENDER=OFF) against the machine's pip torch, the CUDA tests,
# bench_train (base, 224 x 224, bf16, batch 64) beside the official CroCo train step in the same
# run, then pretrain from shards for a few hundred steps, whose checkpoint must load strictly
# into the official CroCoNet; finetune for flow with the DPT head, whose checkpoint must load
# strictly into naver/croco's CroCoDownstreamBinocular; last, the multi-GPU code path on one GPU
# (an NCCL group of one).
#
#   scripts/gpu_prepare.sh --croco-dir ~/src/croco      # once, on the CPU machine: fills .gpu/
#   scripts/gpu_check.sh                                # on the GPU machine, with .gpu/ carried
#   scripts/gpu_check.sh --cpu-dry-run                  # the same steps on a CPU, tiny preset
#
# Outputs go to $OUT when it is set (else gpu-check-out/): gpu_check.log (everything),
# bench_train.json, bench_train_unfused.json (CUDA: LibTorch's own AdamW step),
# pretrain_summary.json, pretrain_log.jsonl, loss.svg, checkpoint_check.json,
# finetune_check.json (finetune's summary, then check_downstream.py's line).
# Environment: PYTHON (a python3 with torch; default python3), JOBS (default nproc), STEPS
# (pretrain steps, default 300), BATCH (default 64).
set -uo pipefail
cd "$(dirname "$0")/.."
DRY=0
[[ "${1:-}" == "--cpu-dry-run" ]] && DRY=1
OUT=${OUT:-$PWD/gpu-check-out}
mkdir -p "$OUT"
exec > >(tee "$OUT/gpu_check.log") 2>&1
PYTHON=${PYTHON:-python3}
JOBS=${JOBS:-$(nproc)}
G=$PWD/.gpu
[[ -d "$G/shards" && -d "$G/croco/models" ]] ||
  { echo "gpu_check: .gpu/ is missing: run scripts/gpu_prepare.sh on the CPU machine first"; exit 2; }
TMPD=${TMPDIR:-/tmp}  # what does not come back: at most 8 files come back from $OUT
declare -A RESULT
stage() { echo; echo "=== $(date +%T) $*"; }
ok() { RESULT[$1]=$2; echo "gpu_check: $1: $2"; }

if ((DRY)); then
  # This machine's CPU and Debian's LibTorch: the same steps, scaled down.
  DEVICE=cpu PRESET=tiny BATCH=${BATCH:-8} STEPS=${STEPS:-20} BENCH_STEPS=6 WARM=2 WORKERS=2
  FT_BATCH=4 FT_STEPS=10
  THREADS=${THREADS:-2} BUILD_DIR=build-trainer-only NICE="nice -n 10"
  TORCH_PREFIX="" NCCL_INC="" EXTRA=()
  [[ "$PYTHON" == python3 ]] && PYTHON=/usr/bin/python3
else
  DEVICE=cuda PRESET=base BATCH=${BATCH:-64} STEPS=${STEPS:-300} BENCH_STEPS=40 WARM=10
  FT_BATCH=16 FT_STEPS=60
  WORKERS=$(($(nproc) - 1)) THREADS=4 BUILD_DIR=build-gpu NICE=""
  TORCH_PREFIX=$("$PYTHON" -c 'import torch; print(torch.utils.cmake_prefix_path)')
  # pip's torch links NCCL from the nvidia-nccl package, whose header it does not ship.
  NCCL_INC=$("$PYTHON" -c 'import nvidia.nccl, os; print(os.path.join(list(nvidia.nccl.__path__)[0], "include"))' 2>/dev/null || true)
  EXTRA=(-DCMAKE_CUDA_ARCHITECTURES=90)
  # Recent LibTorch headers (2.10 and later) are written for C++20.
  "$PYTHON" -c 'import torch, sys; v = tuple(int(x) for x in torch.__version__.split("+")[0].split(".")[:2]); sys.exit(v < (2, 10))' &&
    EXTRA+=(-DCMAKE_CXX_STANDARD=20)
  export TORCH_CUDA_ARCH_LIST=${TORCH_CUDA_ARCH_LIST:-9.0}
  # Torch's CMake config looks for the CUDA toolkit (nvcc) even though nothing here is CUDA code.
  [[ -d /usr/local/cuda/bin ]] && export PATH=$PATH:/usr/local/cuda/bin
fi
GENERATOR=(-G Ninja)
command -v ninja >/dev/null || GENERATOR=()

stage "machine"
uname -m; nproc; (command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv) || true
"$PYTHON" -c 'import torch; print("torch", torch.__version__, "cuda", torch.version.cuda, torch.cuda.is_available())' || true
cmake --version | head -1; g++ --version | head -1; (command -v nvcc >/dev/null && nvcc --version | tail -1) || true

stage "configure and build the trainer-only build in $BUILD_DIR"
t0=$SECONDS
cmake -S . -B "$BUILD_DIR" "${GENERATOR[@]}" -DCMAKE_BUILD_TYPE=Release -DPAIRCAST_WITH_RENDER=OFF \
  -DCMAKE_PREFIX_PATH="${TORCH_PREFIX:+$TORCH_PREFIX;}$G/prefix" \
  -DPAIRCAST_GTEST_SOURCE_DIR="$G/googletest" -DPAIRCAST_NCCL_INCLUDE_DIR="$NCCL_INC" \
  -DCMAKE_DISABLE_FIND_PACKAGE_embree=ON -DCMAKE_DISABLE_FIND_PACKAGE_assimp=ON \
  -DCMAKE_DISABLE_FIND_PACKAGE_OpenImageIO=ON -DCMAKE_DISABLE_FIND_PACKAGE_LibArchive=ON \
  "${EXTRA[@]}" > "$TMPD/configure.txt" 2>&1
rc=$?
grep -E "^-- paircast|Torch|CUDA|Error|error" "$TMPD/configure.txt" | head -20
if ((rc)); then tail -30 "$TMPD/configure.txt"; ok build "configure failed"; exit 1; fi
$NICE cmake --build "$BUILD_DIR" -j "$JOBS" --target pretrain finetune model_info bench_train gpu_tests 2>&1 | tail -15
[[ -x "$BUILD_DIR/tools/pretrain" && -x "$BUILD_DIR/tools/finetune" && -x "$BUILD_DIR/tests/gpu_tests" ]] || { ok build "failed"; exit 1; }
ok build "$((SECONDS - t0)) s"
ldd "$BUILD_DIR/tools/pretrain" "$BUILD_DIR/tools/finetune" |
  grep -E -i "embree|assimp|OpenImageIO|archive" && ok render_libs "LINKED (should not be)" ||
  ok render_libs "none linked"

stage "tests (gpu_tests: SDPA forward, fused AdamW, train step and resume, NCCL group of one)"
timeout 300 "$BUILD_DIR/tests/gpu_tests" > "$TMPD/gpu_tests.txt" 2>&1
rc=$?
grep -E "^\[ *(OK|FAILED|SKIPPED|PASSED|RUN) *\]|Failure|error|skip" "$TMPD/gpu_tests.txt" | tail -30
# On the GPU machine no CUDA test may skip: a LibTorch built without CUDA skips them all and passes.
skipped=$(grep -E "^\[  SKIPPED \] (Cuda|Pretrain\.Cuda)" "$TMPD/gpu_tests.txt" | sort -u |
  sed 's/^\[  SKIPPED \] //; s/ (.*//' | tr '\n' ' ')
if ((rc)); then
  ok tests "FAILED (rc $rc)"
elif [[ $DEVICE == cuda && -n "$skipped" ]]; then
  ok tests "FAILED: CUDA tests skipped on a GPU machine: $skipped"
  rc=1
else
  ok tests passed
fi
"$BUILD_DIR/tools/model_info" --preset base | tail -1

stage "bench_train: $PRESET, 224 x 224, $DEVICE (bf16 on CUDA), batch $BATCH, beside the official step"
timeout 240 "$BUILD_DIR/bench/bench_train" --presets "$PRESET" --batch "$BATCH" --steps "$BENCH_STEPS" \
  --warmup-steps "$WARM" --workers "$WORKERS" --threads "$THREADS" --device "$DEVICE" --amp bf16 \
  --data "$G/shards/*.tar" --croco-dir "$G/croco" --python "$PYTHON" | tee "$TMPD/bench_train.txt"
tail -1 "$TMPD/bench_train.txt" > "$OUT/bench_train.json"
ok bench_train "$(grep -E "pairs/s" "$TMPD/bench_train.txt" | tr '\n' ' ' | tr -s ' ')"
if [[ $DEVICE == cuda ]]; then  # what the fused AdamW step is worth
  timeout 150 "$BUILD_DIR/bench/bench_train" --presets "$PRESET" --batch "$BATCH" --steps "$BENCH_STEPS" \
    --warmup-steps "$WARM" --workers "$WORKERS" --threads "$THREADS" --device "$DEVICE" --amp bf16 \
    --data "$G/shards/*.tar" --no-fused-adamw | tee "$TMPD/bench_unfused.txt"
  tail -1 "$TMPD/bench_unfused.txt" > "$OUT/bench_train_unfused.json"
  ok bench_unfused "$(grep -E "pairs/s" "$TMPD/bench_unfused.txt" | tr '\n' ' ' | tr -s ' ')"
fi

stage "pretrain: $PRESET from shards on $DEVICE for $STEPS steps"
RUN=$TMPD/gpu_check_run
rm -rf "$RUN"
timeout 300 "$BUILD_DIR/tools/pretrain" --data "$G/shards/*.tar" --preset "$PRESET" \
  --batch-size "$BATCH" --max-steps "$STEPS" --epochs 100 --warmup-epochs 2 --blr 6e-4 \
  --device "$DEVICE" --amp bf16 --workers "$WORKERS" --save-every 100 --out "$RUN" --quiet |
  tail -1 | tee "$OUT/pretrain_summary.json"
cp "$RUN/log.jsonl" "$OUT/pretrain_log.jsonl" 2>/dev/null
cp "$RUN/loss.svg" "$OUT/loss.svg" 2>/dev/null
"$PYTHON" - "$RUN/log.jsonl" "$WARM" "$BATCH" <<'EOF' | tee -a "$OUT/pretrain_summary.json"
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
skip, batch = int(sys.argv[2]), int(sys.argv[3])
k = max(1, len(rows) // 10)
first = sum(r["loss"] for r in rows[:k]) / k
last = sum(r["loss"] for r in rows[-k:]) / k
steady = [r for r in rows if r["step"] >= skip]  # after the device's warm-up
secs = sum(batch / r["pairs_per_s"] for r in steady)
wait = sum(r["data_wait"] * batch / r["pairs_per_s"] for r in steady) / max(secs, 1e-12)
print(json.dumps({"loss_first": first, "loss_last": last, "loss_falls": last < first,
                  "steady_pairs_per_s": len(steady) * batch / max(secs, 1e-12),
                  "data_wait": wait, "data_wait_under_5pct": wait < 0.05}))
EOF
ok pretrain "$(tail -1 "$OUT/pretrain_summary.json")"

stage "the checkpoint in Python: torch.load, then strictly into the official CroCoNet"
"$PYTHON" scripts/check_checkpoint.py "$RUN/checkpoint-last.pth" --croco-dir "$G/croco" |
  tee "$OUT/checkpoint_check.json"
ok checkpoint "$(tail -1 "$OUT/checkpoint_check.json")"

stage "finetune: flow, DPT head, 128 x 128, $PRESET from random weights on $DEVICE; then naver/croco's classes"
FT=$TMPD/gpu_check_ft
rm -rf "$FT"
[[ -d "$G/ft-train" ]] || echo "gpu_check: .gpu/ft-train is missing: run scripts/gpu_prepare.sh again"
timeout 240 "$BUILD_DIR/tools/finetune" --task flow --preset "$PRESET" --img-size 128 \
  --data "$G/ft-train/*.tar" --eval-data "$G/ft-eval/*.tar" --batch-size "$FT_BATCH" \
  --max-steps "$FT_STEPS" --epochs 100 --device "$DEVICE" --amp bf16 --out "$FT" --quiet |
  tail -1 | tee "$OUT/finetune_check.json"
# --predict on a held-out pair, against naver/croco's model with the same weights and images.
mkdir -p "$FT/pair" && tar -xf "$G/ft-eval/pairs-000000.tar" -C "$FT/pair"
one=$(ls "$FT/pair"/*.1.jpg | head -1)
"$BUILD_DIR/tools/finetune" --predict --checkpoint "$FT/checkpoint-last.pth" --image1 "$one" \
  --image2 "${one%.1.jpg}.2.jpg" --out "$FT/pair/ours.flo" > /dev/null
"$PYTHON" scripts/check_downstream.py "$FT/checkpoint-last.pth" --croco-dir "$G/croco" \
  --image1 "$one" --image2 "${one%.1.jpg}.2.jpg" --ours "$FT/pair/ours.flo" |
  tee -a "$OUT/finetune_check.json"
ok finetune "$(tail -1 "$OUT/finetune_check.json")"

stage "the multi-process code path on one device (PAIRCAST_PROCESS_GROUP=1, WORLD_SIZE=1)"
PAIRCAST_PROCESS_GROUP=1 WORLD_SIZE=1 RANK=0 LOCAL_RANK=0 MASTER_ADDR=127.0.0.1 MASTER_PORT=29517 \
  timeout 120 "$BUILD_DIR/tools/pretrain" --data "$G/shards/*.tar" --preset "$PRESET" \
  --batch-size "$BATCH" --max-steps 10 --epochs 100 --device "$DEVICE" --amp bf16 \
  --workers "$WORKERS" --out "$RUN-pg" --quiet | tail -1
ok process_group "rc ${PIPESTATUS[0]}"

stage "summary"
for k in build render_libs tests bench_train bench_unfused pretrain checkpoint finetune process_group; do
  printf '%-14s %s\n' "$k" "${RESULT[$k]:-not run}"
done
# The run fails when a stage failed: a CUDA test that skipped on the GPU machine included.
for k in "${!RESULT[@]}"; do
  [[ "${RESULT[$k]}" == *FAILED* ]] && { echo "gpu_check: FAILED ($k)"; exit 1; }
done
echo "gpu_check: no stage FAILED"
