#!/usr/bin/env bash
# scripts/slurm-local.sh SCENE N OUT: renders SCENE as an N-task Slurm array
# job and merges it, on a throwaway one-node Slurm started on this machine
# (Debian's slurmctld, slurmd and munge; `bash scripts/install-deps.sh`
# installs them). Everything lives in a temporary directory: the
# munge key and socket, slurm.conf (no cgroups: proctrack/linuxproc,
# task/none), spool, state and logs, on ports that are free, so it runs
# beside any other Slurm. The jobs are those of deploy/slurm/render.sbatch;
# OUT receives tile_I.exr, image.png and image.exr. The script waits for
# both jobs, checks that every task and the merge completed, and stops every
# daemon it started, by the pids in their pid files, whatever happens.
#
# Needs root (munged and slurmd run as root).
# DISPLACE names the binary (default: target/release/displace if built,
# else `displace` on PATH); DISPLACE_ARGS adds render options;
# SLURM_LOCAL_TIMEOUT bounds the wait (seconds, default 900);
# SLURM_LOCAL_LOGS=DIR keeps the daemons' and the jobs' logs there.
set -euo pipefail
if [ $# -ne 3 ]; then
  echo "usage: $0 SCENE N OUT" >&2
  exit 2
fi
root=$(cd "$(dirname "$0")/.." && pwd)
scene=$(realpath "$1") n=$2 out=$(realpath -m "$3")
case $n in '' | *[!0-9]* | 0) echo "$0: N must be a positive whole number, got '$n'" >&2; exit 2 ;; esac
[ -f "$scene" ] || { echo "$0: $scene: no such scene file" >&2; exit 2; }
if [ -z "${DISPLACE:-}" ]; then
  if [ -x "$root/target/release/displace" ]; then DISPLACE=$root/target/release/displace; else DISPLACE=$(command -v displace || true); fi
fi
[ -x "${DISPLACE:-}" ] || { echo "$0: no displace binary (set DISPLACE)" >&2; exit 2; }
export DISPLACE
for tool in munged slurmctld slurmd sbatch squeue scontrol sinfo; do
  command -v "$tool" >/dev/null || { echo "$0: $tool not found: run 'bash scripts/install-deps.sh'" >&2; exit 2; }
done
[ "$(id -u)" -eq 0 ] || { echo "$0: needs root (munged and slurmd run as root here)" >&2; exit 2; }
mkdir -p "$out"

tmp=$(mktemp -d /tmp/slurm-local.XXXXXX)
chmod 755 "$tmp"
stop() {
  local rc=$?
  for pidfile in "$tmp/slurmd.pid" "$tmp/slurmctld.pid" "$tmp/munged.pid"; do
    [ -s "$pidfile" ] || continue
    local pid
    pid=$(cat "$pidfile")
    kill "$pid" 2>/dev/null || continue
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null || true
  done
  if [ -n "${SLURM_LOCAL_LOGS:-}" ]; then
    mkdir -p "$SLURM_LOCAL_LOGS" && cp "$tmp"/*.log "$tmp"/*.out "$SLURM_LOCAL_LOGS"/ 2>/dev/null || true
  fi
  if [ $rc -ne 0 ]; then
    for log in "$tmp"/*.log "$tmp"/task_*.out "$tmp"/merge.out; do
      [ -f "$log" ] && { echo "--- $log"; tail -n 20 "$log"; }
    done >&2
  fi
  rm -rf "$tmp"
  exit $rc
}
trap stop EXIT
trap 'exit 130' INT TERM

# A port nothing listens on.
free_port() {
  local p
  while :; do
    p=$((20000 + RANDOM % 20000))
    if ! ss -Hltn "sport = :$p" 2>/dev/null | grep -q .; then echo "$p"; return; fi
  done
}

# munge: a fresh key and a private socket.
dd if=/dev/urandom of="$tmp/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge.key"
munged --force --key-file="$tmp/munge.key" --socket="$tmp/munge.socket" \
  --pid-file="$tmp/munged.pid" --log-file="$tmp/munged.log" --seed-file="$tmp/munged.seed" 2>"$tmp/munged.stderr.log"
for _ in $(seq 50); do [ -S "$tmp/munge.socket" ] && break; sleep 0.1; done
[ -S "$tmp/munge.socket" ] || { echo "$0: munged did not start" >&2; exit 1; }

host=$(hostname -s)
ctl_port=$(free_port)
d_port=$(free_port)
while [ "$d_port" = "$ctl_port" ]; do d_port=$(free_port); done
mkdir -p "$tmp/spool" "$tmp/state"
cat >"$tmp/slurm.conf" <<CONF
ClusterName=displace-local
SlurmctldHost=$host
SlurmctldPort=$ctl_port
SlurmdPort=$d_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$tmp/munge.socket
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SlurmUser=root
SlurmdUser=root
ReturnToService=2
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmdSpoolDir=$tmp/spool
StateSaveLocation=$tmp/state
SlurmctldLogFile=$tmp/slurmctld.log
SlurmdLogFile=$tmp/slurmd.log
MinJobAge=600
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$tmp/slurm.conf
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
for _ in $(seq 100); do
  state=$(sinfo -h -N -o %t 2>/dev/null || true)
  [ "$state" = idle ] && break
  sleep 0.2
done
[ "$state" = idle ] || { echo "$0: the node did not come up (state '$state')" >&2; exit 1; }

start=$(date +%s.%N)
cd "$tmp"
array=$(sbatch --parsable --array=0-$((n - 1)) -o "$tmp/task_%a.out" \
  "$root/deploy/slurm/render.sbatch" "$scene" "$n" "$out")
merge=$(sbatch --parsable --dependency=afterok:"$array" --export=ALL,DISPLACE_STEP=merge \
  -o "$tmp/merge.out" "$root/deploy/slurm/render.sbatch" "$scene" "$n" "$out")
deadline=$(($(date +%s) + ${SLURM_LOCAL_TIMEOUT:-900}))
while [ -n "$(squeue -h -j "$array,$merge" 2>/dev/null)" ]; do
  [ "$(date +%s)" -lt "$deadline" ] || { echo "$0: jobs still running after ${SLURM_LOCAL_TIMEOUT:-900} s" >&2; scancel "$array" "$merge" || true; exit 1; }
  sleep 0.5
done
end=$(date +%s.%N)

# Every task and the merge must have completed (exit 0).
states=$(scontrol -o show job "$array" | grep -o 'JobState=[A-Z_]*' | sort | uniq -c)
merged=$(scontrol -o show job "$merge" | grep -o 'JobState=[A-Z_]*')
if [ "$(scontrol -o show job "$array" | grep -c 'JobState=COMPLETED')" -ne "$n" ] || [ "$merged" != JobState=COMPLETED ]; then
  echo "$0: array $array: $states; merge $merge: $merged" >&2
  exit 1
fi
for f in image.png image.exr; do
  [ -s "$out/$f" ] || { echo "$0: $out/$f was not written" >&2; exit 1; }
done
awk -v n="$n" -v a="$array" -v m="$merge" -v s="$start" -v e="$end" -v o="$out/image.png" \
  'BEGIN { printf "slurm-local: %d tasks (job %s) and the merge (job %s) completed in %.1f s -> %s\n", n, a, m, e - s, o }'
