#!/bin/bash
# Opt-in end-to-end test: brings up a one-node Slurm cluster on this
# machine (Debian's slurm-wlm and munge, daemons started by hand, talking
# on 127.0.0.1 only), submits a real job array of a small scene through
# submit.sh, waits for the merge job, and checks that the merged image is
# byte for byte the single-machine render. Not run by `cargo test`.
#
#   sudo examples/farm/slurm/local-cluster-test.sh [SHARDS] [PARALLEL]
#
# Needs root (apt-get, munged, slurmd). Builds prism in release mode unless
# PRISM names a binary. Everything (configuration, state, logs, images)
# goes to a fresh temporary folder, printed at the start and kept on
# failure; the daemons are stopped on exit.
set -euo pipefail
shards=${1:-7}
parallel=${2:-3}
repo=$(cd "$(dirname "$0")/../../.." && pwd)
start=$(date +%s)
say() { echo "[$(($(date +%s) - start))s] $*"; }

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  say "installing slurm-wlm and munge"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
fi

if [ -z "${PRISM:-}" ]; then
  say "building prism (release)"
  (cd "$repo" && cargo build --release --locked --quiet)
  PRISM="${CARGO_TARGET_DIR:-$repo/target}/release/prism"
fi
PRISM=$(readlink -f "$PRISM")
export PRISM

work=$(mktemp -d /tmp/prism-slurm.XXXXXX)
chmod 755 "$work"
say "working in $work"
conf=$work/slurm.conf
host=$(hostname -s)
cpus=$(nproc)
# Ports of our own, so that a Slurm already on the machine is not disturbed.
ctld_port=16817
d_port=16818

# munge: reuse the package's key, or make one; run the daemon as munge.
if [ ! -s /etc/munge/munge.key ]; then
  mungekey --create --keyfile=/etc/munge/munge.key
  chown munge:munge /etc/munge/munge.key
  chmod 400 /etc/munge/munge.key
fi
mkdir -p /run/munge /var/log/munge /var/lib/munge
chown munge:munge /run/munge /var/log/munge /var/lib/munge
munge_pid=""
if ! munge -n >/dev/null 2>&1; then
  su -s /bin/sh munge -c "/usr/sbin/munged --force"
  munge_pid=$(cat /run/munge/munged.pid 2>/dev/null || true)
fi
munge -n | unmunge >/dev/null

mkdir -p "$work/state" "$work/spool" "$work/images"
cat >"$conf" <<CONF
ClusterName=prism-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$d_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
SlurmdTimeout=60
NodeName=prismnode NodeHostname=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=local Nodes=prismnode Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$conf

cleanup() {
  status=$?
  for pidfile in "$work/slurmd.pid" "$work/slurmctld.pid"; do
    if [ -s "$pidfile" ]; then kill "$(cat "$pidfile")" 2>/dev/null || true; fi
  done
  if [ -n "$munge_pid" ]; then kill "$munge_pid" 2>/dev/null || true; fi
  if [ $status -eq 0 ]; then
    # The daemons write their state files as they exit: wait for them
    # (up to 10 s) before removing the folder.
    for _ in $(seq 20); do
      pgrep -f "$work/slurm.conf" >/dev/null || break
      sleep 0.5
    done
    rm -rf "$work" 2>/dev/null || { sleep 1; rm -rf "$work"; }
  else
    echo "FAILED (status $status); logs and images kept in $work" >&2
  fi
}
trap cleanup EXIT

say "starting slurmctld and slurmd on 127.0.0.1"
/usr/sbin/slurmctld -i -f "$conf"
/usr/sbin/slurmd -f "$conf" -N prismnode
for _ in $(seq 60); do
  if sinfo -h -o %t 2>/dev/null | grep -qE '^(idle|mix|alloc)'; then break; fi
  sleep 1
done
sinfo

scene=$repo/assets/cornell.toml
args=(--width 96 --height 72 --spp 8)
say "single-machine render"
"$PRISM" render "$scene" -o "$work/images/single.exr" --quiet "${args[@]}"

say "submitting $shards shards, at most $parallel at once"
read -r array merge < <(SBATCH_ARGS="--cpus-per-task=1" \
  "$repo/examples/farm/slurm/submit.sh" "$scene" "$shards" "$parallel" \
  "$work/shards" "$work/images/merged.exr" "${args[@]}")
say "array job $array, merge job $merge (afterok:$array)"

for _ in $(seq 600); do
  state=$(scontrol show job "$merge" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2 || true)
  case $state in
    COMPLETED) break ;;
    FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY)
      echo "merge job ended $state" >&2
      cat "$work"/shards/*.log >&2 || true
      exit 1
      ;;
  esac
  sleep 1
done
[ "$state" = COMPLETED ] || { echo "merge job still $state after 600 s" >&2; exit 1; }
tasks=$(scontrol show job "$array" | grep -c 'JobState=COMPLETED' || true)
say "array tasks completed: $tasks of $shards; merge job COMPLETED"
ls "$work/shards"/shard-*.exr | wc -l | xargs echo "shard files:"

if cmp "$work/images/single.exr" "$work/images/merged.exr"; then
  say "PASS: the merged image is byte for byte the single render ($(stat -c %s "$work/images/merged.exr") bytes)"
else
  echo "FAIL: merged image differs from the single render" >&2
  exit 1
fi
