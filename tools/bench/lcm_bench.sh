#!/usr/bin/env bash
# End-to-end latency of `arbor publish` -> `arbor serve` over tcpq on loopback, per shared
# dataset: at 10 Hz (first 100 edges), at 100 Hz (first 1000 edges) and as a burst (all edges).
# Starts Debian's LCM TCP hub on 127.0.0.1 and stops everything it starts.
# usage: tools/bench/lcm_bench.sh [BUILD_DIR] [SHARED_DIR] [DATASET ...]
set -euo pipefail
build=${1:-build}
shared=${2:-../shared}
shift $(( $# > 2 ? 2 : $# ))
arbor="$build/tools/arbor"
port=$((20000 + RANDOM % 20000))
url="tcpq://127.0.0.1:$port"
tmp=$(mktemp -d)
hub_pid=""
serve_pid=""
cleanup() {
  [ -n "$serve_pid" ] && kill "$serve_pid" 2>/dev/null || true
  [ -n "$hub_pid" ] && kill "$hub_pid" 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
java -cp /usr/share/java/lcm.jar lcm.lcm.TCPService "$port" >"$tmp/hub.log" 2>&1 &
hub_pid=$!
sleep 1

datasets=("$@")
if [ ${#datasets[@]} -eq 0 ]; then
  for f in $(ls -S -r "$shared"/datasets/*.g2o); do datasets+=("$(basename "$f" .g2o)"); done
fi

echo "| dataset | run | edges | e2e p50 ms | e2e p99 ms | e2e max ms | transport p50 ms | smoother p50 ms | updates | edges/s |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for name in "${datasets[@]}"; do
  file="$shared/datasets/$name.g2o"
  info=refuse
  [ "$name" = cubicle ] && info=repair
  for run in "10 100" "100 1000" "burst -1"; do
    set -- $run
    "$arbor" serve --lcm-url "$url" --json >"$tmp/serve.json" 2>"$tmp/serve.err" &
    serve_pid=$!
    if [ "$1" = burst ]; then rate=(--burst); label="burst"; else rate=(--rate "$1"); label="$1 Hz"; fi
    "$arbor" publish "$file" --lcm-url "$url" --information "$info" "${rate[@]}" --count "$2" \
      --wait --wait-ready --timeout 600 --json >"$tmp/pub.json" 2>>"$tmp/pub.err"
    kill -INT "$serve_pid"
    wait "$serve_pid" || true
    serve_pid=""
    /usr/bin/python3 - "$name" "$label" "$tmp/pub.json" "$tmp/serve.json" <<'PY'
import json, sys
name, label, pub, srv = sys.argv[1:]
p = json.load(open(pub)); s = json.load(open(srv))
l = p["latency_ms"]
print(f"| {name} | {label} | {p['sent']} | {l['p50']:.3f} | {l['p99']:.3f} | {l['max']:.2f} | "
      f"{s['transport_ms']['p50']:.3f} | {s['latency_ms']['p50']:.3f} | {s['updates']} | "
      f"{p['sent'] / p['total_s']:.0f} |")
PY
  done
done
