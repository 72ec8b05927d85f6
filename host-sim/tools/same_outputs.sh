#!/bin/bash
# Proof that a restructuring moved nothing: builds two revisions of this repository and
# compares what they print — every shipped scenario's trace and JSON summary (under both
# invariants, and two of them on the CAN hub), small runs of every sweep and of the
# paper's experiments, the experiments that run whole and shards of sweeps and experiments
# merged (each with its exit code) — with wall-clock figures left out of the JSON.
#
# Usage: host-sim/tools/same_outputs.sh OLD NEW [WORKDIR]
#   OLD, NEW  any git revisions (e.g. HEAD~1 HEAD)
#   WORKDIR   where the worktrees and outputs go (default: a new temporary directory)
# Exit 0 when every output is identical, 1 otherwise (the differing files are listed).
# About 10 minutes per revision on two cores.
set -euo pipefail
old=$1
new=$2
work=${3:-$(mktemp -d)}
repo=$(git rev-parse --show-toplevel)

# Every JSON object without the keys that measure time on this machine.
strip_json() {
  python3 -c '
import json, sys
TIMING = ("wall", "realtime", "elapsed", "per_s", "_ms", "_us", "seconds", "threads")
def strip(o):
    if isinstance(o, dict):
        return {k: strip(v) for k, v in o.items() if not any(w in k for w in TIMING)}
    if isinstance(o, list):
        return [strip(x) for x in o]
    return o
text = sys.stdin.read()
try:
    print(json.dumps(strip(json.loads(text)), sort_keys=True, indent=1))
except ValueError:
    print(text)
'
}

# capture REV OUT: builds REV and writes its outputs into OUT.
capture() {
  local rev=$1 out=$2 tree="$work/tree-$1"
  rm -rf "$out" && mkdir -p "$out"
  [ -d "$tree" ] || git -C "$repo" worktree add -f --detach "$tree" "$rev" >/dev/null
  (
    cd "$tree"
    cargo build -q --release -p host-sim
    # Cargo says where it built (CARGO_TARGET_DIR may move it).
    local target
    target=$(cargo metadata --format-version 1 --no-deps \
      | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
    local hs="$target/release/host-sim"
    for f in scenarios/*.toml; do
      local n
      n=$(basename "$f" .toml)
      for inv in paper leader-aware; do
        "$hs" run "$f" --invariant "$inv" --json --trace "$out/$n-$inv.csv" 2>/dev/null \
          | strip_json > "$out/$n-$inv.json" || true
      done
    done
    for n in multilane intersection; do
      "$hs" run "scenarios/$n.toml" --bus can-hub --json --trace "$out/$n-canhub.csv" \
        2>/dev/null | strip_json > "$out/$n-canhub.json" || true
    done
    local sweep
    for sweep in "platoons 40" "traffic 20" "deadends 20" "crossings 10" "liars 5" \
      "outages 5" "grids 3" "layouts 20"; do
      set -- $sweep
      "$hs" "$1" --cases "$2" --json 2>/dev/null | strip_json > "$out/$1.json" || true
    done
    for e in multilane throughput faults; do
      "$hs" experiment "$e" --json 2>/dev/null | strip_json > "$out/exp-$e.json" || true
    done
    # The experiments that run whole, each with its exit code.
    local run
    for run in "experiment network --grid 2x2 --duration 60" \
      "experiment lane-capacity --speeds 13.9 --vehicles 10" "worlds --vehicles 40 --duration 2" \
      "experiment attacks --only forged-grant,replayed-state --no-baseline"; do
      local name=${run// /_}
      set -- $run
      local code=0
      "$hs" "$@" --json > "$out/.w" 2>/dev/null || code=$?
      { strip_json < "$out/.w"; echo "exit $code"; } > "$out/whole-${name//,/+}.json"
      rm -f "$out/.w"
    done
    # Shards and their merge, with each exit code: what `host-sim merge` makes of them.
    for run in "deadends --cases 6" "crossings --cases 3" "platoons --cases 8" \
      "traffic --cases 4 --duration 10" "traffic --cases 4 --duration 10 --compare" \
      "liars --cases 3" "layouts --cases 8" "grids --cases 2 --duration 30" \
      "experiment multilane --seeds 4" "experiment throughput --seeds 1 --duration 30" \
      "experiment faults --seeds 2 --throughput-seeds 1 --duration 30" \
      "experiment faults --grid --losses 0,0.5 --delays 0 --runs 1"; do
      local name=${run// /_}
      set -- $run
      "$hs" "$@" --shard 0/2 > "$out/.a" 2>/dev/null || true
      "$hs" "$@" --shard 1/2 > "$out/.b" 2>/dev/null || true
      local code=0
      "$hs" merge "$out/.a" "$out/.b" --json > "$out/.m" 2>/dev/null || code=$?
      { strip_json < "$out/.m"; echo "exit $code"; } > "$out/merge-$name.json"
      rm -f "$out/.a" "$out/.b" "$out/.m"
    done
  )
}

capture "$old" "$work/old"
capture "$new" "$work/new"
same=0
different=0
for f in "$work/old"/*; do
  n=$(basename "$f")
  if cmp -s "$f" "$work/new/$n"; then
    same=$((same + 1))
  else
    different=$((different + 1))
    echo "different: $n"
  fi
done
echo "$old vs $new: $same outputs identical, $different different ($work)"
[ "$different" = 0 ]
