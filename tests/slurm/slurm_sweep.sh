#!/usr/bin/env bash
# A sweep spread by a real scheduler (issue 52): a one-node Slurm from Debian's packages
# (slurmctld, slurmd, munged; `.ci/run` installs slurm-wlm and munge) on private ports, a
# private munge socket and a private slurm.conf (SLURM_CONF), all under one temporary
# directory. It submits examples/slurm/sweep.sbatch as an array of 4 shards and
# examples/slurm/merge.sbatch with --dependency=afterok on the array, waits for the merge with a
# deadline, and compares the merged sweep with the unsharded sweep run here: sweep.csv,
# sweep_paper.md and sweep_robots.png byte for byte. Then it stops the daemons it started (by their pids) and
# removes the directory. Needs root (slurmd runs jobs as their user; SlurmUser=root).
# A sweep's runs are single-process simulations: no iceoryx2 service, nothing in /dev/shm.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$PWD
bin=${PHEROMONE_BIN:-${CARGO_TARGET_DIR:-target}/debug/pheromone}
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
deadline_s=${SLURM_TEST_DEADLINE_S:-150}

for t in slurmctld slurmd munged sbatch squeue sinfo scontrol; do
    command -v "$t" >/dev/null || PATH=$PATH:/usr/sbin
    command -v "$t" >/dev/null || { echo "slurm_sweep.sh: $t missing (apt-get install slurm-wlm munge)" >&2; exit 1; }
done
[ "$(id -u)" = 0 ] || { echo "slurm_sweep.sh: needs root (SlurmUser=root, slurmd starts jobs as their user)" >&2; exit 1; }
[ -x "$bin" ] || { echo "slurm_sweep.sh: no pheromone binary at $bin (cargo build)" >&2; exit 1; }

tmp=$(mktemp -d /tmp/pheromone-slurm.XXXXXX)
chmod 755 "$tmp"
pids=()
cleanup() {
    local rc=$?
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    for p in "${pids[@]}"; do
        for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
        kill -9 "$p" 2>/dev/null || true
        wait "$p" 2>/dev/null || true
    done
    if [ "$rc" != 0 ]; then
        for f in "$tmp"/*.log "$tmp"/run/*.out; do
            [ -f "$f" ] && { echo "--- $f"; tail -n 30 "$f"; }
        done
    fi
    rm -rf "$tmp"
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Two free TCP ports for slurmctld and slurmd.
read -r port_ctld port_d < <(python3 -c '
import socket
s = [socket.socket() for _ in range(2)]
for x in s: x.bind(("127.0.0.1", 0))
print(*(x.getsockname()[1] for x in s))')
host=$(hostname -s)

echo "== munged (key and socket in $tmp/munge)"
mkdir -m 700 "$tmp/munge"
dd if=/dev/urandom of="$tmp/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge/munge.key"
munged --foreground --force --key-file="$tmp/munge/munge.key" --socket="$tmp/munge/munge.socket" \
    --pid-file="$tmp/munge/munged.pid" --log-file="$tmp/munged.log" --seed-file="$tmp/munge/munged.seed" 2>>"$tmp/munged.log" &
pids+=($!)

echo "== slurm.conf: node $host, CPUs=2, slurmctld :$port_ctld, slurmd :$port_d"
mkdir -p "$tmp/state" "$tmp/spool" "$tmp/run"
cat > "$tmp/slurm.conf" <<CONF
ClusterName=pheromone-test
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port_ctld
SlurmdPort=$port_d
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$tmp/munge/munge.socket
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/slurmctld.log
SlurmdLogFile=$tmp/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
MpiDefault=none
ReturnToService=2
SlurmdParameters=config_overrides
MailProg=/bin/true
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$tmp/slurm.conf

# The unsharded sweep, here, while the daemons start.
sweep=(ias-ss --robots 2,3 --trials 2 --duration 40)
"$bin" sweep "${sweep[@]}" --jobs 1 --out "$tmp/whole" 2>"$tmp/whole.log"

for _ in $(seq 100); do [ -S "$tmp/munge/munge.socket" ] && break; sleep 0.1; done
[ -S "$tmp/munge/munge.socket" ] || { echo "munged did not create its socket" >&2; exit 1; }

echo "== slurmctld, slurmd (foreground daemons, SLURM_CONF=$SLURM_CONF)"
started=$(date +%s.%N)
slurmctld -D -i >>"$tmp/slurmctld.out.log" 2>&1 &
pids+=($!)
slurmd -D -N "$host" >>"$tmp/slurmd.out.log" 2>&1 &
pids+=($!)
end=$(( $(date +%s) + 60 ))
until [ "$(sinfo -h -n "$host" -o %T 2>/dev/null)" = idle ]; do
    [ "$(date +%s)" -lt "$end" ] || { echo "node $host not idle after 60 s: $(sinfo -h -o '%T %E' 2>&1)" >&2; exit 1; }
    sleep 0.2
done
up=$(date +%s.%N)
echo "node $host idle after $(python3 -c "print(round($up - $started, 1))") s"

echo "== sbatch: the array of 4 shards, the merge after it"
cd "$tmp/run"
export PHEROMONE=$bin SWEEP_DIR=$tmp/run/sweep
jid=$(sbatch --parsable --array=0-3 "$root/examples/slurm/sweep.sbatch" "${sweep[@]}")
mid=$(sbatch --parsable --dependency="afterok:$jid" "$root/examples/slurm/merge.sbatch" 4)
echo "array job $jid, merge job $mid"
submitted=$(date +%s.%N)
end=$(( $(date +%s) + deadline_s ))
while squeue -h -j "$jid,$mid" -o %i 2>/dev/null | grep -q .; do
    if squeue -h -j "$mid" -o %r | grep -q DependencyNeverSatisfied; then
        echo "a shard failed: the merge can never start" >&2
        scontrol show job "$jid" >&2 || true
        exit 1
    fi
    [ "$(date +%s)" -lt "$end" ] || { echo "jobs not done after $deadline_s s:" >&2; squeue >&2; exit 1; }
    sleep 0.5
done
done_at=$(date +%s.%N)
for k in 0 1 2 3; do
    grep -h "done:" "$tmp/run/pheromone-sweep-${jid}_$k.out" | sed "s/^/  task $k: /" || true
done
state=$(scontrol show job "$mid" | grep -o 'JobState=[A-Z_]*' || true)
echo "jobs done $(python3 -c "print(round($done_at - $submitted, 1))") s after submission (merge: $state)"
[ "$state" = JobState=COMPLETED ] || { echo "merge job $mid: $state" >&2; exit 1; }

echo "== merged (4 shards under Slurm) against the unsharded sweep"
merged=$SWEEP_DIR/merged
for f in sweep.csv sweep_paper.md sweep_robots.png; do
    cmp "$tmp/whole/$f" "$merged/$f"
done
rows=$(($(wc -l < "$merged/sweep.csv") - 1))
for k in 0 1 2 3; do
    [ -f "$SWEEP_DIR/shard-$k/shard.json" ] || { echo "no shard $k" >&2; exit 1; }
done
echo "byte for byte equal: sweep.csv ($rows rows), sweep_paper.md, sweep_robots.png"
cd "$root"
