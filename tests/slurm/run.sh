#!/bin/sh
# The SLURM path against a real single-node SLURM (make test-slurm; needs root and the
# Debian packages slurm-wlm and munge). Starts a private munged (its own key and socket)
# and slurmctld + slurmd (their own config, ports, state and spool folders under a fresh
# /tmp folder), submits scripts/slurm-render.sbatch as one job and as a job array (one
# frame per array task), compares every output with a local render, and stops everything
# it started. When the daemons cannot run here it says why and skips (exit 0), unless
# SLURM_REQUIRED=1. Ends with "integration: N passed, N failed".
# Usage: BUILD=build sh tests/slurm/run.sh
set -u
cd "$(dirname "$0")/../.." || exit 2
BUILD=${BUILD:-build}
BIN=$(cd "$BUILD" && pwd)
M=$BIN/master
X=$BIN/exrtool
T=$(mktemp -d /tmp/brume-slurm.XXXXXX)
chmod 755 "$T"
pass=0
fail=0
export SLURM_CONF="$T/etc/slurm.conf"
stop_pidfile() { [ -s "$1" ] && kill "$(cat "$1")" 2>/dev/null; }
cleanup() {
  command -v scancel >/dev/null 2>&1 && [ -s "$T/slurmctld.pid" ] && scancel --quiet --user "$(id -un)" 2>/dev/null
  stop_pidfile "$T/slurmd.pid"; stop_pidfile "$T/slurmctld.pid"; stop_pidfile "$T/munge/munged.pid"
  sleep 0.5
  [ -n "${KEEP_T:-}" ] || rm -rf "$T"
}
trap cleanup EXIT
ok() { pass=$((pass + 1)); echo "ok: $1"; }
bad() { fail=$((fail + 1)); echo "FAIL: $1"; for f in "$T"/job*.out "$T/slurmctld.log" "$T/slurmd.log"; do [ -s "$f" ] && { echo "  $f:"; tail -12 "$f" | sed 's/^/    /'; }; done; }
skip() {
  echo "skip: SLURM test: $1"
  if [ "${SLURM_REQUIRED:-0}" = 1 ]; then echo "integration: 0 passed, 1 failed"; exit 1; fi
  echo "integration: 0 passed, 0 failed (skipped)"
  exit 0
}

[ "$(id -u)" = 0 ] || skip "not root (slurmd must run as root)"
for p in munged slurmctld slurmd sbatch srun sinfo scancel; do
  command -v $p >/dev/null 2>&1 || [ -x /usr/sbin/$p ] || skip "$p not installed (apt-get install slurm-wlm munge)"
done
PATH=$PATH:/usr/sbin
node=$(hostname)
getent hosts "$node" >/dev/null || skip "this host's name $node does not resolve"
cpus=$(nproc)

# --- munge: a private daemon with its own key and socket ---
mkdir -p "$T/munge" && chmod 700 "$T/munge"
dd if=/dev/urandom of="$T/munge/munge.key" bs=1024 count=1 2>/dev/null && chmod 600 "$T/munge/munge.key"
munged --force --key-file="$T/munge/munge.key" --socket="$T/munge/munge.sock" --pid-file="$T/munge/munged.pid" \
  --log-file="$T/munge/munged.log" --seed-file="$T/munge/seed" >"$T/munge/start.log" 2>&1 ||
  skip "munged does not start: $(tail -1 "$T/munge/start.log")"
i=0
while [ ! -S "$T/munge/munge.sock" ] && [ $i -lt 50 ]; do sleep 0.1; i=$((i + 1)); done
[ -S "$T/munge/munge.sock" ] || skip "munged made no socket: $(tail -1 "$T/munge/munged.log")"

# --- slurmctld + slurmd, single node ---
# Ports P .. P + 40, free now: from the kernel's pick for a bind to port 0 (as
# tests/integration/lib.sh's free_port), a run of 41 that all bind.
P=$(python3 -c 'import socket
def free(p):
    s = socket.socket()
    try:
        s.bind(("", p))
        return True
    except OSError:
        return False
    finally:
        s.close()
for _ in range(100):
    s = socket.socket(); s.bind(("", 0)); base = s.getsockname()[1]; s.close()
    if base + 40 < 65536 and all(free(base + i) for i in range(41)):
        print(base)
        break') || skip "no run of 41 free TCP ports"
[ -n "$P" ] || skip "no run of 41 free TCP ports"
mkdir -p "$T/etc" "$T/state" "$T/spool"
cat >"$SLURM_CONF" <<EOF
ClusterName=brumetest
SlurmctldHost=$node
SlurmctldPort=$P
SlurmdPort=$((P + 1))
SrunPortRange=$((P + 2))-$((P + 40))
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$T/munge/munge.sock
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/slurmctld.log
SlurmdLogFile=$T/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/builtin
MpiDefault=none
ReturnToService=2
SlurmctldTimeout=30
SlurmdTimeout=30
KillWait=5
NodeName=$node CPUs=$cpus State=UNKNOWN
PartitionName=test Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -i >"$T/ctld.start" 2>&1 || skip "slurmctld does not start: $(tail -1 "$T/ctld.start") $(tail -1 "$T/slurmctld.log" 2>/dev/null)"
slurmd >"$T/d.start" 2>&1 || skip "slurmd does not start: $(tail -1 "$T/d.start") $(tail -1 "$T/slurmd.log" 2>/dev/null)"
i=0
state=""
while [ $i -lt 150 ]; do
  state=$(sinfo -h -n "$node" -o %t 2>/dev/null | head -1)
  [ "$state" = idle ] && break
  sleep 0.2; i=$((i + 1))
done
[ "$state" = idle ] || skip "the node did not come up (state \"$state\"): $(grep -i error "$T/slurmd.log" "$T/slurmctld.log" 2>/dev/null | tail -2 | tr '\n' ' ')"
echo "slurm: slurmctld and slurmd up on $node ($cpus CPUs), munge at $T/munge/munge.sock"

SB=scripts/slurm-render.sbatch
# --- one job: master on the first node, workers by srun ---
timeout 120 $M scenes/cornell/cornell.json -o "$T/ref.exr" --workers 1 --spp 4 --tile 32 >"$T/ref.log" 2>&1 || bad "reference render"
mkdir -p "$T/out"
BRUME_BIN=$BIN timeout 180 sbatch --wait --quiet -o "$T/job1.out" -J brume-test $SB scenes/cornell/cornell.json "$T/out/one.exr" \
  --spp 4 --tile 32 && r=0 || r=1
if [ $r = 0 ] && grep -q "master at tcp://$node:" "$T/job1.out" && python3 -c 'import json, sys; sys.exit(json.load(open(sys.argv[1]))["counters"]["workers_joined"] != 1)' "$T/out/one.exr.stats.json" &&
  grep -q "master exited with status 0" "$T/job1.out" && $X cmp "$T/ref.exr" "$T/out/one.exr" >/dev/null &&
  ! ls -a "$T/out" | grep -q brume-keys; then
  ok "sbatch: master on the first node, a worker per node via srun (CurveZMQ, per-job keys removed), identical pixels"
else bad "sbatch: master on the first node, a worker per node via srun, identical pixels"; fi

# --- a job array: one frame per array task ---
mkdir -p "$T/ref"
timeout 120 $M scenes/motion/motion.json -o "$T/ref/f.exr" --frames 0:2 --workers 1 --spp 64 --tile 16 >"$T/ref.log" 2>&1 ||
  bad "reference frames"
BRUME_BIN=$BIN timeout 240 sbatch --wait --quiet --array=0-2 -o "$T/job2-%a.out" -J brume-array $SB scenes/motion/motion.json \
  "$T/out/f.exr" --spp 64 --tile 16 && r=0 || r=1
same=0
for f in 0000 0001 0002; do $X cmp "$T/ref/f.$f.exr" "$T/out/f.$f.exr" >/dev/null 2>&1 && same=$((same + 1)); done
if [ $r = 0 ] && [ $same = 3 ] && [ "$(ls "$T/out" | grep '^f\.' | tr '\n' ' ')" = "f.0000.exr f.0000.exr.stats.json f.0001.exr f.0001.exr.stats.json f.0002.exr f.0002.exr.stats.json " ]; then
  ok "sbatch --array=0-2: one frame per array task, f.0000..f.0002 identical to a local render, each task's own stats"
else echo "slurm: $same of 3 frames identical; files: $(ls "$T/out" | tr '\n' ' ')"; bad "sbatch --array=0-2: one frame per array task"; fi

echo "integration: $pass passed, $fail failed"
[ $fail = 0 ]
