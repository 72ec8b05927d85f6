#!/usr/bin/env bash
# A real Slurm array job on this machine: starts a one-node Slurm (Debian's slurm-wlm and
# munge; installed if missing), submits SWEEP as an array of SHARDS tasks and the merge
# step after it, waits, and checks the merged result against the same sweep run unsharded
# in one process (field for field, wall-clock times aside).
#   bash deploy/slurm/run-local.sh [SWEEP] [CASES] [SHARDS]     (default: platoons 40 4)
# Needs root (it writes /etc/slurm and starts the daemons).
set -euo pipefail
cd "$(dirname "$0")/../.."
SWEEP=${1:-platoons}
CASES=${2:-40}
SHARDS=${3:-4}
work=$(mktemp -d /tmp/host-sim-slurm.XXXX)
chmod 755 "$work"

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge
fi

# The binary the tasks run: cargo says where it built it.
cargo build --release -q -p host-sim
target=$(cargo metadata --format-version 1 --no-deps \
  | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
cp "$target/release/host-sim" "$work/host-sim"

# munge: a key, and the daemon.
if [ ! -s /etc/munge/munge.key ]; then
  dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key status=none
fi
chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
mkdir -p /run/munge && chown munge:munge /run/munge
pgrep -x munged >/dev/null || runuser -u munge -- munged

# One node: this host, with its cores and memory.
cpus=$(nproc)
mem=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512 ))
host=$(hostname -s)
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
cat > /etc/slurm/slurm.conf <<CONF
ClusterName=host-sim
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
pkill -x slurmctld || true
pkill -x slurmd || true
sleep 1
slurmctld
slurmd
for _ in $(seq 30); do sinfo -h -o %T 2>/dev/null | grep -qE 'idle|mixed' && break; sleep 1; done
sinfo

# The array job and the merge step after it.
cd "$work"
export SWEEP CASES SEED=1 OUT="$work/shards" HOST_SIM="$work/host-sim"
array=$(sbatch --parsable --array=0-$((SHARDS - 1)) --cpus-per-task=1 \
  --chdir="$work" "$OLDPWD/deploy/slurm/sweep.sbatch")
merge=$(sbatch --parsable --dependency=afterany:"$array" --chdir="$work" \
  "$OLDPWD/deploy/slurm/merge.sbatch")
echo "array job $array ($SHARDS tasks), merge job $merge"
start=$(date +%s)
while squeue -h -j "$array,$merge" 2>/dev/null | grep -q .; do
  if [ $(( $(date +%s) - start )) -gt 1800 ]; then echo "timed out" >&2; exit 1; fi
  sleep 2
done
sacct -n -j "$array,$merge" -o JobID,State,ExitCode 2>/dev/null || true
ls "$OUT"
test -s "$OUT/$SWEEP.json"

# The same sweep in one process, and the comparison.
"$HOST_SIM" "$SWEEP" --cases "$CASES" --seed 1 --json > "$work/unsharded.json" || [ $? -le 3 ]
python3 - "$OUT/$SWEEP.json" "$work/unsharded.json" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
def same(k, x, y):
    if isinstance(x, dict):
        assert list(x) == list(y), (k, list(x), list(y))
        for key in x:
            if key != "wall_seconds":
                same(f"{k}.{key}", x[key], y[key])
    elif isinstance(x, list):
        assert len(x) == len(y), k
        for i, (p, q) in enumerate(zip(x, y)):
            same(f"{k}[{i}]", p, q)
    elif isinstance(x, float) or isinstance(y, float):
        assert abs(x - y) <= 1e-9 * max(abs(x), abs(y), 1e-300), (k, x, y)
    else:
        assert x == y, (k, x, y)
same("", a, b)
print(f"merged Slurm array equals the unsharded run: {a.get('cases')} cases, wall {a.get('wall_seconds')} s summed over shards")
PY
