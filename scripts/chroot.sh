#!/usr/bin/env bash
# Runs a command of this checkout inside a chroot of another Debian release, made here with
# debootstrap from the Debian registry that apt already uses, and kept for later runs.
#
#   scripts/chroot.sh debian13 scripts/test.sh      the test suite on Debian 13 (trixie)
#   scripts/chroot.sh debian12 scripts/demo.sh      the demo on Debian 12 (bookworm)
#   scripts/chroot.sh debian13 --remove             deletes that release's chroot
#
# The chroot lives in $PAIRCAST_CHROOT_DIR/<release> (default /var/cache/paircast/chroots), with
# its packages, its build folders and its compiler cache, so a second run only rebuilds what
# changed. Each run copies the checkout's files (tracked and untracked, not ignored) to
# /work/paircast inside, and ../shared beside it to /work/shared when it exists, then mounts
# /proc, /sys and /dev, runs the command as root in /work/paircast, and unmounts on the way out.
# It needs root, debootstrap (installed when missing) and the network to the Debian registry.
# Variables passed through: CI, JOBS, CTEST_ARGS, BUILD_DIR and every PAIRCAST_* one.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
if (($# < 2)); then
  usage >&2
  exit 2
fi
release=$1
shift
case "$release" in
  debian12) suite=bookworm ;;
  debian13) suite=trixie ;;
  *)
    echo "chroot.sh: unknown release '$release' (known: debian12, debian13)" >&2
    exit 2
    ;;
esac
if [[ $(id -u) != 0 ]]; then
  echo "chroot.sh: needs root (debootstrap, mount and chroot)" >&2
  exit 2
fi
base=${PAIRCAST_CHROOT_DIR:-/var/cache/paircast/chroots}
root=$base/$release
if [[ "$1" == --remove ]]; then
  rm -rf --one-file-system "$root" "$root.tmp"
  echo "chroot.sh: removed $root"
  exit 0
fi

# The first Debian archive that apt reads here (sources.list or deb822 .sources).
host_mirror() {
  local m
  m=$(grep -hsE '^(URIs:|deb) ' /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list \
    /etc/apt/sources.list | grep -v security | sed -E 's/^URIs: *//; s/^deb (\[[^]]*\] )?//' |
    awk '{print $1; exit}')
  echo "${m:-http://deb.debian.org/debian}"
}

# debootstrap into <root>.tmp, then one rename: a run killed half-way starts again from scratch.
make_root() {
  [[ -f "$root/.paircast-chroot" ]] && return
  command -v debootstrap >/dev/null || scripts/setup.sh debootstrap
  local mirror
  mirror=$(host_mirror)
  echo "chroot.sh: making a $release ($suite) chroot in $root from $mirror"
  rm -rf --one-file-system "$root.tmp"
  mkdir -p "$base"
  debootstrap --variant=minbase --include=ca-certificates "$suite" "$root.tmp" "$mirror" \
    >"$base/$release-debootstrap.log" 2>&1 || {
    echo "chroot.sh: debootstrap failed, see $base/$release-debootstrap.log" >&2
    exit 1
  }
  touch "$root.tmp/.paircast-chroot"
  mv "$root.tmp" "$root"
}

# The checkout's files into /work/paircast, keeping the build folders of earlier runs (tar keeps
# the files' times, so the build redoes only what changed).
copy_tree() {
  local dest=$root/work/paircast
  mkdir -p "$dest"
  find "$dest" -mindepth 1 -maxdepth 1 ! -name 'build*' -exec rm -rf {} +
  git ls-files -z -co --exclude-standard |
    while IFS= read -r -d '' f; do [[ -e "$f" ]] && printf '%s\0' "$f"; done |
    tar -c --null -T - | tar -x -C "$dest"
  rm -rf "$root/work/shared"
  if [[ -d ../shared ]]; then cp -r ../shared "$root/work/shared"; fi
}

mounted=()
mount_into() {  # mount_into TARGET MOUNT-ARGUMENTS...
  local target=$root$1
  shift
  mkdir -p "$target"
  mount "$@" "$target"
  mounted=("$target" "${mounted[@]}")
}
unmount_all() {
  local m
  for m in "${mounted[@]}"; do umount "$m" 2>/dev/null || umount -l "$m" || true; done
}

# No daemon starts when a package is installed inside (slurmd, slurmctld): Debian's policy-rc.d
# convention, exit status 101. The host's name resolves there as here (Slurm, Gloo).
deny_service_starts() {
  [[ -x "$root/usr/sbin/policy-rc.d" ]] && return
  printf '#!/bin/sh\n# chroot.sh: no service starts in this chroot\nexit 101\n' \
    >"$root/usr/sbin/policy-rc.d"
  chmod +x "$root/usr/sbin/policy-rc.d"
}

make_root
deny_service_starts
copy_tree
cp /etc/resolv.conf "$root/etc/resolv.conf"
cp /etc/hosts "$root/etc/hosts"
trap unmount_all EXIT
mount_into /proc -t proc proc
mount_into /sys -t sysfs sys
mount_into /dev --bind /dev
mount_into /dev/pts --bind /dev/pts
mount_into /dev/shm --bind /dev/shm

pass=(HOME=/root PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8)
pass+=(CCACHE_DIR=/var/cache/ccache)
for v in CI JOBS CTEST_ARGS BUILD_DIR $(compgen -e | grep '^PAIRCAST_' || true); do
  [[ -n "${!v+x}" ]] && pass+=("$v=${!v}")
done
echo "chroot.sh: $release: $*"
status=0
chroot "$root" /usr/bin/env -i "${pass[@]}" /bin/bash -c 'cd /work/paircast && exec "$@"' \
  chroot.sh "$@" || status=$?
exit "$status"
