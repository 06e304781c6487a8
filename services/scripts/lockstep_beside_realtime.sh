#!/usr/bin/env bash
# Runs the pendulum in real time (1 kHz, the default wait) while lockstep runs of the pendulum
# follow one another beside it, once for each lockstep wait, interleaved; prints per run the
# real-time run's deadline misses and end-to-end latency and the lockstep runs' loops/s. It
# answers whether a lockstep job (a sweep, a replay) on the same machine costs a real-time
# loop its deadlines, by how it waits.
#
#   services/scripts/lockstep_beside_realtime.sh [RUNS] [SECONDS] [LOCKSTEP WAITS...]
#   (defaults: 3 runs of 20 s, lockstep handoff and block, and none for the real-time run alone)
#
# Uses target/release/looplab (build it first: cargo build --release); NEIGHBOUR=PATH runs the
# lockstep runs with another build's looplab (to compare with an older release).
set -euo pipefail
runs=${1:-3}
seconds=${2:-20}
shift $(($# < 2 ? $# : 2))
waits=("$@")
[ $# -eq 0 ] && waits=(none handoff block)
root=$(cd "$(dirname "$0")/../.." && pwd)
looplab=$root/target/release/looplab
neighbour_looplab=${NEIGHBOUR:-$looplab}
out=$(mktemp -d /tmp/looplab-beside.XXXXXX)

printf '%-9s %3s %9s %12s %12s %14s\n' lockstep run misses 'e2e p50 µs' 'e2e p99 µs' 'lockstep loops/s'
for run in $(seq 1 "$runs"); do
  for wait in "${waits[@]}"; do
    dir=$out/$wait-$run
    mkdir -p "$dir"
    neighbour=
    if [ "$wait" != none ]; then
      # Lockstep runs back to back until the real-time run is over.
      ( n=0; while [ ! -e "$dir/done" ]; do
          "$neighbour_looplab" run pendulum --mode lockstep --duration 10 -q --set wait.lockstep="\"$wait\"" \
            --out "$dir/lockstep-$n" > /dev/null 2>&1 || true
          n=$((n + 1)); done ) &
      neighbour=$!
    fi
    "$looplab" run pendulum --duration "$seconds" -q --out "$dir/realtime" > "$dir/realtime.log" 2>&1 || true
    touch "$dir/done"
    [ -n "$neighbour" ] && wait "$neighbour"
    python3 - "$dir" "$wait" "$run" <<'PY'
import glob, json, sys
folder, wait, run = sys.argv[1:]
try:
    s = json.load(open(f"{folder}/realtime/summary.json"))
except OSError:
    print(f"{wait:<9} {run:>3}  no summary (see {folder}/realtime.log)")
    sys.exit()
rates = []
for path in glob.glob(f"{folder}/lockstep-*/summary.json"):
    t = json.load(open(path))
    if t.get("completed"):
        rates.append(t["loops_per_s"])
e2e = s["latency_ns"]["end_to_end"]
us = lambda v: "-" if v is None else f"{v / 1e3:.1f}"
rate = f"{sorted(rates)[len(rates) // 2]:.0f}" if rates else "-"
print(f"{wait:<9} {run:>3} {s['deadline_misses']:>9} {us(e2e['p50']):>12} {us(e2e['p99']):>12} {rate:>14}")
PY
  done
done
echo "run folders: $out"
