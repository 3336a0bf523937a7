#!/usr/bin/env bash
# How long `arbor serve` takes to exit on SIGTERM while a background batch (RTR by default) is in
# flight: the stop cancels the batch (core/cancellation.h) instead of waiting for it. Streams the
# first COUNT edges of DATASET as a burst into `arbor serve --batch SOLVER --batch-every EVERY`,
# waits until they are all estimated, sends SIGTERM and times the exit. Runs over udpm inside a
# private network namespace of its own (only loopback; see lcm_bench.sh), so nothing leaves the
# machine. Prints one line per run: the stop time, the last batch's state and the exit
# refinement's (iterations, time, cut by --exit-refine-budget) from serve's JSON.
# usage: tools/bench/stop_latency.sh [BUILD_DIR] [DATASET_FILE]
# Environment: RUNS=5 COUNT=-1 SOLVER=rtr EVERY=20 SERVE_FLAGS=... (e.g. --no-refine)
set -euo pipefail
source "$(dirname "$0")/private_network.sh"
enter_private_network "$@"
build=${1:-build}
file=${2:-../shared/datasets/M3500.g2o}
arbor="$build/tools/arbor"
url="udpm://239.255.76.67:7667?ttl=0"
tmp=$(mktemp -d)
serve_pid=""
cleanup() {
  [ -n "$serve_pid" ] && kill -9 "$serve_pid" 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
read -r -a serve_flags <<<"${SERVE_FLAGS:-}"
for run in $(seq "${RUNS:-5}"); do
  "$arbor" serve --lcm-url "$url" --json --batch "${SOLVER:-rtr}" --batch-every "${EVERY:-20}" \
    ${serve_flags[@]+"${serve_flags[@]}"} >"$tmp/serve.json" 2>"$tmp/serve.err" &
  serve_pid=$!
  "$arbor" publish "$file" --lcm-url "$url" --information repair --burst --count "${COUNT:--1}" \
    --wait --wait-ready --timeout 300 >/dev/null 2>>"$tmp/pub.err"
  start=$(date +%s.%N)
  kill -TERM "$serve_pid"
  wait "$serve_pid" || true
  end=$(date +%s.%N)
  serve_pid=""
  /usr/bin/python3 - "$run" "$start" "$end" "$tmp/serve.json" <<'PY'
import json, sys
run, start, end, path = sys.argv[1:]
s = json.load(open(path))
b = s["batches"][-1] if s["batches"] else {}
print(f"run {run}: SIGTERM -> exit {float(end) - float(start):.3f} s; {len(s['batches'])} batches, "
      f"last cancelled={b.get('cancelled', False)} after {b.get('time_s', 0):.3f} s "
      f"(winner {b.get('winner', '-')}); exit refinement {s['exit_refine']['iterations']} "
      f"iterations in {s['exit_refine']['time_s']:.3f} s, cut={s['exit_refine']['cut']}; "
      f"applied {s['applied']}; F {s['F_final']:.6g}")
PY
done
