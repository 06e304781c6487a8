#!/usr/bin/env bash
# Runs the pendulum in real time with each wait strategy while a CPU hog (`yes`) and an fsync
# disk writer (`dd … conv=fsync` in a loop) load the machine, and prints, per run, whether the
# pendulum stayed up (max |θ|), the deadline misses and the end-to-end latency.
#
#   services/scripts/under_load.sh [RUNS] [SECONDS] [STRATEGIES...]
#   (defaults: 3 runs of 30 s, block and adaptive, interleaved so that both see the same load)
#
# Uses target/release/looplab (build it first: cargo build --release).
set -euo pipefail
runs=${1:-3}
seconds=${2:-30}
shift $(($# < 2 ? $# : 2))
strategies=("${@:-block}")
[ $# -eq 0 ] && strategies=(block adaptive)
root=$(cd "$(dirname "$0")/../.." && pwd)
looplab=$root/target/release/looplab
out=$(mktemp -d /tmp/looplab-under-load.XXXXXX)
scratch=$(mktemp /tmp/looplab-under-load-io.XXXXXX)

yes > /dev/null &
hog=$!
( while :; do dd if=/dev/zero of="$scratch" bs=1M count=64 conv=fsync status=none; done ) &
writer=$!
trap 'kill $hog $writer 2>/dev/null; wait 2>/dev/null; rm -f "$scratch"' EXIT

printf '%-9s %3s %12s %9s %16s %16s %s\n' strategy run 'max |θ| rad' misses 'e2e p50 µs' 'e2e p99 µs' verdict
for run in $(seq 1 "$runs"); do
  for strategy in "${strategies[@]}"; do
    dir=$out/$strategy-$run
    "$looplab" run pendulum --set wait.strategy="$strategy" --set duration_s="$seconds" --out "$dir" \
      > "$dir.log" 2>&1 || true
    python3 - "$dir/summary.json" "$strategy" "$run" <<'PY'
import json, sys
path, strategy, run = sys.argv[1:]
try:
    s = json.load(open(path))
except OSError:
    print(f"{strategy:<9} {run:>3}  no summary (see {path[:-13]}.log)")
    sys.exit()
theta = s["metrics"].get("theta_max_abs_rad")
e2e = s["latency_ns"]["end_to_end"]
us = lambda v: "-" if v is None else f"{v / 1e3:.1f}"
up = isinstance(theta, float) and theta < 0.5
print(f"{strategy:<9} {run:>3} {theta:>12.3f} {s['deadline_misses']:>9} {us(e2e['p50']):>16} {us(e2e['p99']):>16} "
      f"{'stayed up' if up else 'FELL'}")
PY
  done
done
echo "run folders: $out"
