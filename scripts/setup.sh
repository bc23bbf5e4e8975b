#!/usr/bin/env bash
# Installs the packages paircast needs on Debian 12 (bookworm) or 13 (trixie), plus any named as
# arguments (scripts/fuzz.sh adds clang's). Idempotent: installs only what is missing, and runs
# `apt-get update` once, only when something is missing. The release comes from /etc/os-release;
# both have the same package names (Debian 12: Embree 3, LibTorch 1.13, Python 3.11; Debian 13:
# Embree 4, LibTorch 2.6, Python 3.13). Another system stops with exit status 2.
set -euo pipefail

os_release=${PAIRCAST_OS_RELEASE:-/etc/os-release}
release=$(. "$os_release" 2>/dev/null && echo "${ID:-}:${VERSION_ID:-}") || release=":"
case "$release" in
  debian:12 | debian:13) ;;
  *)
    pretty=$(. "$os_release" 2>/dev/null && echo "${PRETTY_NAME:-}") || true
    echo "setup: known releases are Debian 12 (bookworm) and Debian 13 (trixie), not" \
      "'${pretty:-unknown, no $os_release}'" >&2
    exit 2
    ;;
esac

PACKAGES=(
  build-essential cmake ninja-build pkg-config ccache
  libembree-dev libassimp-dev libeigen3-dev libopenimageio-dev openimageio-tools
  libgtest-dev libtorch-dev libopenblas0-openmp libgloo-dev
  nlohmann-json3-dev libcli11-dev libspdlog-dev libarchive-dev libnanoflann-dev libjpeg-dev zlib1g-dev
  libboost-dev  # Boost.Math: the t quantiles of the sweep's confidence intervals
  libopenexr-dev  # OpenEXR's C library: EXR depth in the trainer-only build (util/exr_codec.h)
  libdraco-dev  # the glTF tests encode a Draco mesh (scripts/test_inventory.py expects them)
  slurmctld slurmd slurm-client  # the engine tests (tests/launch/) run a one-node Slurm cluster
  sweethome3d-furniture  # make_scenes --furnish: Sweet Home 3D's furniture catalogues (CC0, CC-BY)
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

# LibTorch's BLAS: OpenBLAS built on OpenMP, the runtime of LibTorch's own threads. The pthread
# build, which apt prefers when both are installed, keeps a second pool of threads that spin
# against LibTorch's: CroCo training steps on 2 cores ran 1.2-10x slower with it (docs/releases.md,
# "OpenBLAS"). Without any OpenBLAS, LibTorch falls back to a reference BLAS, 20x slower.
select_openmp_blas() {
  local name target
  for name in libblas.so.3 liblapack.so.3 libopenblas.so.0; do
    name=$name-$(dpkg-architecture -qDEB_HOST_MULTIARCH 2>/dev/null || echo x86_64-linux-gnu)
    target=$(update-alternatives --list "$name" 2>/dev/null | grep /openblas-openmp/ | head -1) ||
      continue
    [[ $(update-alternatives --query "$name" | sed -n 's/^Value: //p') == "$target" ]] && continue
    echo "setup: $name -> $target"
    $SUDO update-alternatives --quiet --set "$name" "$target"
  done
}

SUDO=""
if [[ $(id -u) != 0 ]]; then SUDO=sudo; fi
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
  echo "setup: all ${#PACKAGES[@]} packages are installed"
  select_openmp_blas
  exit 0
fi
echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
select_openmp_blas
