#!/usr/bin/env bash
# End-to-end latency of `arbor publish` -> `arbor serve`, per shared dataset: at 10 Hz (first 100
# edges), at 100 Hz (first 1000 edges) and as a burst (all edges). Over tcpq it starts Debian's
# LCM TCP hub on 127.0.0.1; over udpm (TRANSPORT=udpm) the script re-runs itself inside a private
# network namespace (unshare --net, or -rn unprivileged: only loopback, multicast on, 224.0.0.0/4
# routed to lo, ttl=0), so no datagram reaches the machine's network. Stops everything it starts.
# usage: tools/bench/lcm_bench.sh [BUILD_DIR] [SHARED_DIR] [DATASET ...]
# Environment (all optional):
#   TRANSPORT=tcpq|udpm   (default tcpq)
#   RECV_BUF=BYTES        udpm: serve's --recv-buf (default: serve's own)
#   RUNS="10 100 burst"   which runs, in this order (a number is a --rate in Hz)
#   COUNT10=100 COUNT100=1000   edges published at 10 Hz / 100 Hz (any other rate: COUNT100)
#   SERVE_FLAGS=... PUBLISH_FLAGS=...   extra flags, e.g. PUBLISH_FLAGS=--low-latency
#   WARMUP=1   first stream M3500 (a burst, then 2000 edges at 2 kHz) through the hub on another
#              channel prefix, untimed: the hub's JVM then runs compiled code, as a long-running
#              hub does; a cold hub adds ~0.1-0.2 ms per message until ~10^4 messages went by.
set -euo pipefail
transport=${TRANSPORT:-tcpq}
if [ "$transport" = udpm ]; then
  source "$(dirname "$0")/private_network.sh"
  enter_private_network "$@"
fi
build=${1:-build}
shared=${2:-../shared}
shift $(( $# > 2 ? 2 : $# ))
arbor="$build/tools/arbor"
port=$((20000 + RANDOM % 20000))
url="tcpq://127.0.0.1:$port"
[ "$transport" = udpm ] && url="udpm://239.255.76.67:7667?ttl=0"
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
[ -n "${RECV_BUF:-}" ] && serve_flags+=(--recv-buf "$RECV_BUF")
if [ "$transport" = tcpq ]; then
  java -cp /usr/share/java/lcm.jar lcm.lcm.TCPService "$port" >"$tmp/hub.log" 2>&1 &
  hub_pid=$!
  sleep 1
fi

datasets=("$@")
if [ ${#datasets[@]} -eq 0 ]; then
  for f in $(ls -S -r "$shared"/datasets/*.g2o); do datasets+=("$(basename "$f" .g2o)"); done
fi

if [ "$transport" = tcpq ] && [ "${WARMUP:-1}" = 1 ]; then
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

echo "| dataset | run | edges | e2e p50 ms | e2e p99 ms | e2e max ms | transport p50 ms | transport p99 ms | smoother p50 ms | smoother p99 ms | e2e − smoother p50 / p99 ms | gaps | updates | edges/s |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
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
t, u = s["transport_ms"], s["latency_ms"]
print(f"| {name} | {label} | {p['sent']} | {l['p50']:.3f} | {l['p99']:.3f} | {l['max']:.2f} | "
      f"{t['p50']:.3f} | {t['p99']:.3f} | {u['p50']:.3f} | {u['p99']:.3f} | "
      f"{l['p50'] - u['p50']:.3f} / {l['p99'] - u['p99']:.3f} | {s['gaps']} | {s['updates']} | "
      f"{p['sent'] / p['total_s']:.0f} |")
PY
  done
done
