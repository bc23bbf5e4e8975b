#!/usr/bin/env bash
# A one-node Slurm cluster in a folder, for the engine tests (tests/launch/): no systemd, cgroups
# or munge, ports on this machine only, every daemon started and stopped by its PID.
#
#   slurm_cluster.sh check            exit 0 when Slurm can run here, else say why and exit 3
#   slurm_cluster.sh start DIR PORT   write DIR/slurm.conf, start slurmctld (PORT) and slurmd
#                                     (PORT+1), wait until the node is idle; then point the
#                                     clients at it with SLURM_CONF=DIR/slurm.conf. Exit 3 as
#                                     check does; 1 when the cluster did not come up (the logs'
#                                     last lines on stderr)
#   slurm_cluster.sh stop DIR         cancel every job, wait for an empty queue, stop both daemons
# Job ids start at PORT, so that the rendezvous ports srun's tasks take from them (20000 + id mod
# 10000) differ between clusters.
#
# 3 is the only status that means "Slurm can't run here" (the engine tests skip on it); any other
# failure is the tests' failure.
#
# Auth: auth/none and cred/none where the plugins exist (Slurm 22.05 and 24.11, Debian 12 and 13);
# else auth/slurm and cred/slurm with a key generated into DIR, a set-up written from Slurm's
# documentation that no CI machine runs: a cluster that does not come up with it fails the tests.
set -euo pipefail

die() { echo "slurm_cluster: $*" >&2; exit 1; }
# Every Slurm command is bounded: a client whose daemon is gone retries for a long time.
slurm() { timeout 20 "$@"; }

plugin_dir() {
  local d
  for d in /usr/lib/*/slurm-wlm /usr/lib64/slurm /usr/lib/slurm; do
    [[ -e $d/proctrack_linuxproc.so ]] && { echo "$d"; return 0; }
  done
  return 1
}

# "auth/none cred/none" or "auth/slurm cred/slurm", whichever this Slurm has.
auth_plugins() {
  local d; d=$(plugin_dir) || return 1
  if [[ -e $d/auth_none.so && -e $d/cred_none.so ]]; then echo "auth/none cred/none"
  elif [[ -e $d/auth_slurm.so && -e $d/cred_slurm.so ]]; then echo "auth/slurm cred/slurm"
  else return 1; fi
}

check() {
  local t
  for t in slurmctld slurmd sbatch srun squeue sinfo scancel; do
    command -v "$t" >/dev/null || { echo "Slurm is not installed ($t not found: apt-get install slurmctld slurmd slurm-client, as scripts/setup.sh does)"; exit 3; }
  done
  [[ $(id -u) == 0 ]] || { echo "the test cluster runs its daemons as root; run the tests as root"; exit 3; }
  plugin_dir >/dev/null || { echo "Slurm's plugins (proctrack_linuxproc.so) were not found"; exit 3; }
  auth_plugins >/dev/null || { echo "this Slurm has neither auth/none+cred/none nor auth/slurm+cred/slurm"; exit 3; }
}

port_free() { ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }

write_conf() {
  local dir=$1 port=$2 auth cred
  read -r auth cred < <(auth_plugins)
  mkdir -p "$dir/state" "$dir/spool"
  # The machine's cores: nproc alone answers OMP_NUM_THREADS, which ctest sets to 1 per test.
  local cpus
  cpus=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)
  if [[ $auth == auth/slurm ]]; then
    # Read from beside slurm.conf; Slurm refuses a key that others can read.
    (umask 077; head -c 1024 /dev/urandom > "$dir/slurm.key")
  fi
  cat > "$dir/slurm.conf" <<CONF
ClusterName=paircast-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=$auth
CredType=$cred
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
SwitchType=switch/none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
SlurmdParameters=config_overrides
ReturnToService=2
MinJobAge=5
SchedulerParameters=batch_sched_delay=0
KillWait=2
FirstJobId=$port
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
  # slurmd >= 23 sets up its cgroup plugin even for proctrack/linuxproc and task/none, and stops
  # where no cgroup filesystem is mounted (a chroot); CgroupPlugin=disabled (23.02 on) skips it.
  # 22.05 knows no such value and needs none.
  local major
  major=$(slurmd -V | sed -nE 's/^slurm(-wlm)? ([0-9]+)\..*/\2/p')
  if ((${major:-0} >= 23)); then echo "CgroupPlugin=disabled" > "$dir/cgroup.conf"; fi
}

start() {
  local dir=$1 port=$2
  check >&2 || exit 3
  # slurmd's step sockets live in DIR/spool: a Unix socket path holds at most 108 bytes.
  ((${#dir} <= 48)) || die "$dir is too long for Slurm's sockets under it (at most 48 characters)"
  port_free "$port" && port_free $((port + 1)) || die "port $port or $((port + 1)) is taken"
  write_conf "$dir" "$port"
  export SLURM_CONF=$dir/slurm.conf
  # -D: in the foreground of a background job, so that $! is the daemon's PID.
  slurmctld -D -i -f "$SLURM_CONF" </dev/null >"$dir/slurmctld.out" 2>&1 &
  echo $! > "$dir/ctld.pid"
  slurmd -D -N localhost -f "$SLURM_CONF" </dev/null >"$dir/slurmd.out" 2>&1 &
  echo $! > "$dir/d.pid"
  local i
  for i in $(seq 100); do
    if [[ $(slurm sinfo -h -n localhost -o %t 2>/dev/null) == idle ]]; then return 0; fi
    kill -0 "$(cat "$dir/ctld.pid")" 2>/dev/null || break
    kill -0 "$(cat "$dir/d.pid")" 2>/dev/null || break
    sleep 0.1
  done
  local auth; read -r auth _ < <(auth_plugins)
  echo "slurm_cluster: the node did not come up idle with $auth; the logs end:" >&2
  tail -n 5 "$dir/slurmctld.log" "$dir/slurmd.log" "$dir/slurmctld.out" "$dir/slurmd.out" >&2 || true
  stop "$dir"
  exit 1
}

# Waits up to $2 tenths of a second for process $1 to end.
wait_gone() {
  local i
  for i in $(seq "$2"); do kill -0 "$1" 2>/dev/null || return 0; sleep 0.1; done
  return 1
}

stop() {
  local dir=$1 i pid
  export SLURM_CONF=$dir/slurm.conf
  # Jobs and slurmstepd outlive the daemons under proctrack/linuxproc: end them first.
  slurm scancel --full --quiet --user root >/dev/null 2>&1 || true
  for i in $(seq 150); do
    [[ -z $(slurm squeue -h -o %i 2>/dev/null) ]] && break
    sleep 0.1
  done
  # Both at once: each takes a second or two to shut down.
  local pids=()
  for f in d.pid ctld.pid; do
    [[ -f $dir/$f ]] || continue
    pid=$(cat "$dir/$f")
    kill -TERM "$pid" 2>/dev/null && pids+=("$pid")
    rm -f "$dir/$f"
  done
  for pid in "${pids[@]}"; do
    wait_gone "$pid" 100 || kill -KILL "$pid" 2>/dev/null || true
  done
}

case ${1:-} in
  check) check ;;
  start) [[ $# == 3 ]] || die "usage: $0 start DIR PORT"; start "$2" "$3" ;;
  stop) [[ $# == 2 ]] || die "usage: $0 stop DIR"; stop "$2" ;;
  *) die "usage: $0 check | start DIR PORT | stop DIR" ;;
esac
