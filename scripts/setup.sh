#!/usr/bin/env bash
# Installs the Debian 12 packages paircast needs, plus any named as arguments (scripts/fuzz.sh
# adds clang's). Idempotent: installs only what is missing, and runs `apt-get update` once, only
# when something is missing.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  libembree-dev libassimp-dev libeigen3-dev libopenimageio-dev openimageio-tools
  libgtest-dev libtorch-dev libopenblas0-pthread libgloo-dev
  nlohmann-json3-dev libcli11-dev libspdlog-dev libarchive-dev libnanoflann-dev libjpeg-dev
  libboost-dev  # Boost.Math: the t quantiles of the sweep's confidence intervals
  slurmctld slurmd slurm-client  # the engine tests (tests/launch/) run a one-node Slurm cluster
  # The Python package (python/): pybind11, numpy, and its tests and pip install.
  python3-dev python3-numpy pybind11-dev python3-pybind11 python3-pytest python3-setuptools
)
# Optional references for tests and benchmarks (Python side): torch, open3d, sklearn, and
# torchvision with PIL for naver/croco's own loader (bench/bench_loader.py).
if [[ "${PAIRCAST_WITH_REFERENCES:-1}" == 1 ]]; then
  PACKAGES+=(python3-numpy python3-torch python3-open3d python3-sklearn python3-openimageio)
  PACKAGES+=(python3-torchvision python3-pil)
  PACKAGES+=(chromium)  # the dataset report is checked in headless Chromium
fi

PACKAGES+=("$@")

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
  echo "setup: all ${#PACKAGES[@]} packages are installed"
  exit 0
fi
SUDO=""
if [[ $(id -u) != 0 ]]; then SUDO=sudo; fi
echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
