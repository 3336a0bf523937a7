#!/usr/bin/env bash
# Loss of a udpm burst against `arbor serve`'s receive buffer: a generated graph of EDGES edges
# (default 60,000) published back to back (`arbor publish --burst`), then its last edge alone as
# a fence (so a loss at the burst's tail shows as a gap too), once per receive buffer request in
# SIZES (serve's --recv-buf). Prints, per size, the SO_RCVBUF the kernel reported, the edges
# accepted, the gaps (accepted + gaps = sent: every loss reported), the updates the burst took and
# serve's peak resident memory (VmHWM before it is stopped). Runs inside a private
# network namespace of its own (only loopback; see lcm_bench.sh): nothing leaves the machine.
# usage: tools/bench/udpm_burst.sh [BUILD_DIR]
# Environment: EDGES=60000 SIZES="106496 524288 1048576 4194304" RUNS=1
set -euo pipefail
source "$(dirname "$0")/private_network.sh"
enter_private_network "$@"
build=${1:-build}
arbor="$build/tools/arbor"
url="udpm://239.255.76.67:7667?ttl=0"
tmp=$(mktemp -d)
serve_pid=""
cleanup() {
  [ -n "$serve_pid" ] && kill -9 "$serve_pid" 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
edges=${EDGES:-60000}
# A Manhattan world has ≈ 1.3 edges per pose; take exactly `edges` of them.
"$arbor" generate manhattan --poses $((edges * 10 / 12)) --grid 80 --seed 1 -o "$tmp/graph.g2o" \
  >/dev/null
total=$(grep -c '^EDGE' "$tmp/graph.g2o")
[ "$total" -ge "$edges" ] || { echo "generated only $total edges" >&2; exit 1; }
echo "| recv-buf asked | SO_RCVBUF reported | sent | accepted | gaps | accepted + gaps | updates | serve peak RSS MiB |"
echo "|---|---|---|---|---|---|---|---|"
for size in ${SIZES:-106496 524288 1048576 4194304}; do
  for run in $(seq "${RUNS:-1}"); do
    "$arbor" serve --lcm-url "$url" --recv-buf "$size" --no-refine --json >"$tmp/serve.json" \
      2>"$tmp/serve.err" &
    serve_pid=$!
    "$arbor" publish "$tmp/graph.g2o" --lcm-url "$url" --burst --count $((edges - 1)) \
      --wait-ready --timeout 60 >/dev/null
    for attempt in 1 2 3 4 5; do
      "$arbor" publish "$tmp/graph.g2o" --lcm-url "$url" --skip $((edges - 1)) --count 1 --wait \
        --wait-ready --timeout 60 >/dev/null 2>&1 && break
    done
    hwm_kib=$(awk '/^VmHWM/ {print $2}' "/proc/$serve_pid/status")
    kill -INT "$serve_pid"
    wait "$serve_pid" || true
    serve_pid=""
    /usr/bin/python3 - "$size" "$edges" "$tmp/serve.json" "$hwm_kib" <<'PY'
import json, sys
size, edges, path, hwm_kib = sys.argv[1:]
s = json.load(open(path))
print(f"| {size} | {s['recv_buf_bytes']} | {edges} | {s['accepted']} | {s['gaps']} | "
      f"{s['accepted'] + s['gaps']} | {s['updates']} | {int(hwm_kib) // 1024} |")
PY
  done
done
