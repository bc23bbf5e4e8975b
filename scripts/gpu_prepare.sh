#!/usr/bin/env bash
# Gathers in .gpu/ (git-ignored) what scripts/gpu_check.sh needs on a GPU machine that has a
# CUDA PyTorch but no network, no root and none of the render libraries: small shards made here
# by generate_pairs, naver/croco's models/ (the official CroCoNet, which paircast does not ship),
# fine-tuning pairs with flow and depth, the header-only libraries (nlohmann-json, CLI11, Eigen),
# libjpeg-turbo (headers and static library), OpenEXR's C library (headers and shared library, which
# needs only zlib) and GoogleTest's sources.
# Run it on the machine with the full build (Debian 12 with scripts/setup.sh's packages):
#
#   scripts/gpu_prepare.sh --croco-dir ~/src/croco [--pairs-per-scene 200] [--build build]
#
# Then carry .gpu along and run scripts/gpu_check.sh there. It comes to about 35 MiB, 18 MiB of
# which are the shards (600 pairs with the default 200 per scene).
set -euo pipefail
cd "$(dirname "$0")/.."
CROCO_DIR="" PAIRS=200 BUILD=build
while (($#)); do
  case "$1" in
    --croco-dir) CROCO_DIR=$2; shift 2 ;;
    --pairs-per-scene) PAIRS=$2; shift 2 ;;
    --build) BUILD=$2; shift 2 ;;
    *) echo "gpu_prepare: unknown argument $1" >&2; exit 2 ;;
  esac
done
[[ -n "$CROCO_DIR" && -f "$CROCO_DIR/models/croco.py" ]] ||
  { echo "gpu_prepare: give --croco-dir, a checkout of naver/croco" >&2; exit 2; }
[[ -x "$BUILD/tools/generate_pairs" ]] ||
  { echo "gpu_prepare: build generate_pairs first (cmake --build $BUILD --target generate_pairs)" >&2; exit 2; }

rm -rf .gpu && mkdir -p .gpu/prefix/include .gpu/prefix/lib .gpu/croco
# 256 x 256 pairs of the shipped scenes, as tar shards (pretrain crops 224 x 224 out of them).
"$BUILD/tools/generate_pairs" --scenes scenes/ --out .gpu/shards --pairs-per-scene "$PAIRS" \
  --resolution 256 --format shards --seed 0 > .gpu/generate.log
# finetune's pairs, 128 x 128 with flow and depth: the room and apartment to train on, the studio
# held out (about 16 MiB).
"$BUILD/tools/generate_pairs" --scenes scenes/room scenes/apartment --out .gpu/ft-train \
  --pairs-per-scene 16 --resolution 128 --save-flow --save-depth --seed 1 --quiet >> .gpu/generate.log
"$BUILD/tools/generate_pairs" --scenes scenes/studio --out .gpu/ft-eval \
  --pairs-per-scene 8 --resolution 128 --save-flow --save-depth --seed 2 --quiet >> .gpu/generate.log
cp -r "$CROCO_DIR/models" .gpu/croco/
git -C "$CROCO_DIR" rev-parse HEAD > .gpu/croco/COMMIT 2>/dev/null || true
cp -r /usr/include/nlohmann /usr/include/CLI .gpu/prefix/include/
# Eigen (header-only): cameras in shard records (util/camera.h).
mkdir -p .gpu/prefix/include/eigen3 && cp -r /usr/include/eigen3/Eigen .gpu/prefix/include/eigen3/
cp /usr/include/jpeglib.h /usr/include/jerror.h /usr/include/jmorecfg.h \
  /usr/include/x86_64-linux-gnu/jconfig.h .gpu/prefix/include/
# Static: nothing to find at run time, whatever the GPU machine's distribution.
cp /usr/lib/x86_64-linux-gnu/libjpeg.a .gpu/prefix/lib/
# OpenEXR's C interface: it links whatever C++ ABI pip's torch was built with.
mkdir -p .gpu/prefix/include/OpenEXR && cp /usr/include/OpenEXR/openexr*.h .gpu/prefix/include/OpenEXR/
cp -P /usr/lib/x86_64-linux-gnu/libOpenEXRCore*.so* .gpu/prefix/lib/
cp -r /usr/src/googletest .gpu/googletest
du -sh .gpu/* | sed "s/^/gpu_prepare: /"
du -sh .gpu | sed "s/^/gpu_prepare: total /"
