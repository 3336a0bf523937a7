#!/usr/bin/env bash
# End-to-end latency of `arbor publish` -> `arbor serve` over tcpq on loopback, per shared
# dataset: at 10 Hz (first 100 edges), at 100 Hz (first 1000 edges) and as a burst (all edges).
# Starts Debian's LCM TCP hub on 127.0.0.1 and stops everything it starts.
# usage: tools/bench/lcm_bench.sh [BUILD_DIR] [SHARED_DIR] [DATASET ...]
# Environment (all optional):
#   RUNS="10 100 burst"   which runs, in this order (a number is a --rate in Hz)
#   COUNT10=100 COUNT100=1000   edges published at 10 Hz / 100 Hz (any other rate: COUNT100)
#   SERVE_FLAGS=... PUBLISH_FLAGS=...   extra flags, e.g. PUBLISH_FLAGS=--low-latency
#   WARMUP=1   first stream M3500 (a burst, then 2000 edges at 2 kHz) through the hub on another
#              channel prefix, untimed: the hub's JVM then runs compiled code, as a long-running
#              hub does; a cold hub adds ~0.1-0.2 ms per message until ~10^4 messages went by.
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
read -r -a runs <<<"${RUNS:-10 100 burst}"
read -r -a serve_flags <<<"${SERVE_FLAGS:-}"
read -r -a publish_flags <<<"${PUBLISH_FLAGS:-}"
java -cp /usr/share/java/lcm.jar lcm.lcm.TCPService "$port" >"$tmp/hub.log" 2>&1 &
hub_pid=$!
sleep 1

datasets=("$@")
if [ ${#datasets[@]} -eq 0 ]; then
  for f in $(ls -S -r "$shared"/datasets/*.g2o); do datasets+=("$(basename "$f" .g2o)"); done
fi

if [ "${WARMUP:-1}" = 1 ]; then
  warm="$shared/datasets/M3500.g2o"
  [ -f "$warm" ] || warm="$shared/datasets/${datasets[0]}.g2o"
  "$arbor" serve --lcm-url "$url" --channel-prefix WARMUP_ --no-refine >/dev/null 2>&1 &
  serve_pid=$!
  "$arbor" publish "$warm" --lcm-url "$url" --channel-prefix WARMUP_ --information repair \
    --burst --wait --wait-ready --timeout 120 >/dev/null 2>>"$tmp/pub.err"
  "$arbor" publish "$warm" --lcm-url "$url" --channel-prefix WARMUP_ --information repair \
    --sender 2 --rate 2000 --count 2000 --wait --timeout 120 >/dev/null 2>>"$tmp/pub.err"
  kill -INT "$serve_pid"
  wait "$serve_pid" || true
  serve_pid=""
fi

echo "| dataset | run | edges | e2e p50 ms | e2e p99 ms | e2e max ms | transport p50 ms | smoother p50 ms | updates | edges/s |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for name in "${datasets[@]}"; do
  file="$shared/datasets/$name.g2o"
  info=refuse
  [ "$name" = cubicle ] && info=repair
  for run in "${runs[@]}"; do
    if [ "$run" = burst ]; then
      rate=(--burst); label="burst"; count=-1
    else
      rate=(--rate "$run"); label="$run Hz"
      if [ "$run" = 10 ]; then count=${COUNT10:-100}; else count=${COUNT100:-1000}; fi
    fi
    "$arbor" serve --lcm-url "$url" --json ${serve_flags[@]+"${serve_flags[@]}"} \
      >"$tmp/serve.json" 2>"$tmp/serve.err" &
    serve_pid=$!
    "$arbor" publish "$file" --lcm-url "$url" --information "$info" "${rate[@]}" --count "$count" \
      --wait --wait-ready --timeout 600 --json ${publish_flags[@]+"${publish_flags[@]}"} \
      >"$tmp/pub.json" 2>>"$tmp/pub.err"
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
