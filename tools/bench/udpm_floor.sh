#!/usr/bin/env bash
# The floor of one LCM udpm hop here (tools/bench/lcm_pingpong.cc): raw LCM ping-pong between two
# processes, no Arbor code on the path, at the gaps the streaming benchmarks use (10 ms: 100 Hz,
# 100 ms: 10 Hz). Runs inside a private network namespace of its own (only loopback; see
# lcm_bench.sh): nothing leaves the machine. Prints a table row per gap.
# usage: tools/bench/udpm_floor.sh [BUILD_DIR]
# Environment: GAPS="10 100" PINGS=1000
set -euo pipefail
source "$(dirname "$0")/private_network.sh"
enter_private_network "$@"
build=${1:-build}
tool="$build/tools/arbor-lcm-pingpong"
url="udpm://239.255.76.67:7667?ttl=0"
echo_pid=""
trap '[ -n "$echo_pid" ] && kill -9 "$echo_pid" 2>/dev/null || true' EXIT
echo "| gap ms | pings | one-way p50 ms | one-way p99 ms | max ms |"
echo "|---|---|---|---|---|"
for gap in ${GAPS:-10 100}; do
  "$tool" echo "$url" &
  echo_pid=$!
  "$tool" ping "$url" "${PINGS:-1000}" "$gap"
  wait "$echo_pid"
  echo_pid=""
done
