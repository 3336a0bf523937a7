#!/usr/bin/env bash
# Robots on several hosts: three robots, each in a network namespace of its own running its own
# `arbor publish --resend-window`, and `arbor serve` in a fourth, joined by veth links to one
# bridge; udpm multicast (ttl=1) crosses the bridge, nothing else. Robot 1's link drops LOSS% of
# its UDP datagrams each way (nftables `numgen random`, in robot 1's namespace) and is cut
# (`ip link set down` on its bridge port) for OUTAGE_S seconds, OUTAGE_AT seconds after the
# robots start. Each robot streams its own generated Manhattan world (pose ids moved by
# 100,000 × robot) at RATE edges/s. Prints one table row per run: the edges, what the link
# dropped, what robot 1 resent, serve's counters, F against `arbor replay` of the merged file.
#
# Everything runs inside a private parent namespace made by this script (`unshare --net --pid
# --fork --kill-child --mount-proc`): its only links are the bridge and the veths made here, so
# no datagram reaches the machine's network, and when the script ends (or is killed) the kernel
# ends every process in it and the namespaces and links go with them. Exits 77 when the machine
# does not allow network namespaces.
#
# usage: tools/bench/several_hosts.sh [BUILD_DIR]
# Environment: POSES="1500 700 700" (robots 1..3) RATE=100 LOSS=5 OUTAGE_AT=5 OUTAGE_S=10 RUNS=1
#   RESEND=100000 (each publisher's --resend-window; 0: none, to see what the link loses)
#   ARBOR=PATH (the arbor executable; default BUILD_DIR/tools/arbor)
#   OUT=DIR (keep each run's files in DIR/run<k>: serve.json, publish<r>.json, merged.g2o,
#   link.json; the test reads them) GUARD=240 (seconds: every process is ended by then)
set -euo pipefail
if [ -z "${ARBOR_HOSTS_PARENT:-}" ]; then
  export ARBOR_HOSTS_PARENT=1
  if unshare --net --pid --fork --mount-proc true 2>/dev/null; then
    exec unshare --net --pid --fork --kill-child --mount-proc -- bash "$0" "$@"
  elif unshare -r --net --pid --fork --mount-proc true 2>/dev/null; then
    exec unshare -r --net --pid --fork --kill-child --mount-proc -- bash "$0" "$@"
  fi
  echo "$(basename "$0"): skipped: this machine does not allow network namespaces (unshare --net)" >&2
  exit 77
fi
for tool in ip nft nsenter jq; do
  command -v "$tool" >/dev/null || { echo "$(basename "$0"): skipped: no '$tool'" >&2; exit 77; }
done
ip link set lo up
# The parent namespace is private: nothing but loopback before the bridge is made here.
if [ "$(ip -o link show | wc -l)" != 1 ]; then
  echo "$(basename "$0"): not in a private network namespace; stopping" >&2
  exit 1
fi

build=${1:-build}
arbor="$(realpath "${ARBOR:-$build/tools/arbor}")"
read -r -a poses <<<"${POSES:-1500 700 700}"
rate=${RATE:-100}
loss=${LOSS:-5}
outage_at=${OUTAGE_AT:-5}
outage_s=${OUTAGE_S:-10}
runs=${RUNS:-1}
guard=${GUARD:-240}
resend=${RESEND:-100000}
resend_flags=(--resend-window "$resend")
[ "$resend" = 0 ] && resend_flags=()
out=${OUT:-}
# ttl=1: a datagram crosses the bridge segment and no router; the bridge is the only way out of
# each namespace, and the parent namespace has no way out at all.
url="udpm://239.255.76.67:7667?ttl=1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

hosts=(serve robot1 robot2 robot3)
declare -A ns_pid
# Host k: a namespace held by a `sleep` (ended with this script's pid namespace: every process
# in it ends when the script does), a veth pair "port<k>" (on the bridge) / "eth0" (inside),
# address 10.56.0.<k+1>/24, 224.0.0.0/4 routed to eth0.
make_network() {
  ip link add br56 type bridge mcast_snooping 0
  ip link set br56 up
  for k in 0 1 2 3; do
    unshare --net -- sleep infinity &
    local pid=$!
    while [ "$(readlink /proc/$pid/ns/net)" = "$(readlink /proc/self/ns/net)" ]; do sleep 0.01; done
    ns_pid[${hosts[$k]}]=$pid
    ip link add "port$k" type veth peer name "eth$k"
    ip link set "eth$k" netns "$pid"
    ip link set "port$k" master br56 up
    nsenter -t "$pid" -n sh -c "ip link set lo up && ip link set eth$k name eth0 &&
      ip addr add 10.56.0.$((k + 1))/24 dev eth0 && ip link set eth0 up &&
      ip route add 224.0.0.0/4 dev eth0"
  done
}
# Robot 1's radio: LOSS% of the frames it sends and of those sent to it lost on the way
# (dropped, counted, by the bridge: the sender does not know), like a lossy radio link. Made
# afresh for each run, so its counters start at 0.
make_radio() {
  nft delete table bridge radio 2>/dev/null || true
  nft -f - <<EOF
table bridge radio {
  chain forward {
    type filter hook forward priority 0;
    iifname "port1" meta l4proto udp numgen random mod 100 < $loss counter drop comment "out";
    oifname "port1" meta l4proto udp numgen random mod 100 < $loss counter drop comment "in";
  }
}
EOF
}
# In HOST's namespace: nsenter -t "${ns_pid[HOST]}" -n -- CMD (it execs CMD: $! is CMD's pid).
# `timeout --foreground` passes a SIGTERM to its command once (without --foreground it signals
# its process group as well: a second signal, which cuts serve's exit refinement).

# Three robots' worlds, pose ids moved apart, and the merged file for `arbor replay`.
make_worlds() {
  : >"$1/merged.g2o"
  for r in 1 2 3; do
    "$arbor" generate manhattan --poses "${poses[$((r - 1))]}" --seed "$r" -o "$1/gen$r.g2o" \
      >/dev/null
    awk -v off=$((100000 * r)) '
      $1 == "VERTEX_SE2" { $2 += off }
      $1 == "EDGE_SE2" { $2 += off; $3 += off }
      { print }' "$1/gen$r.g2o" >"$1/robot$r.g2o"
    cat "$1/robot$r.g2o" >>"$1/merged.g2o"
  done
}

make_network
echo "| run | edges (robots 1, 2, 3) | robot 1 link: lost out / in, cut (dropped out) | robot 1 resent | serve accepted | applied | duplicates | gaps | given up | held | last robot acknowledged s | F serve | F replay | relative difference |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
for run in $(seq "$runs"); do
  dir="$tmp/run$run"
  [ -n "$out" ] && dir="$out/run$run"
  mkdir -p "$dir"
  make_worlds "$dir"
  make_radio
  tx_dropped() {  # what robot 1's eth0 dropped for want of a carrier (its link cut)
    nsenter -t "${ns_pid[robot1]}" -n ip -s -j link show eth0 | jq '.[0].stats64.tx.dropped'
  }
  cut_before=$(tx_dropped)
  nsenter -t "${ns_pid[serve]}" -n -- timeout --foreground -k 5 "$guard" "$arbor" serve --lcm-url "$url" --json --status-period 0.2 \
    --dim 2 --exit-refine-budget none >"$dir/serve.json" 2>"$dir/serve.err" &
  serve_pid=$!
  for _ in $(seq 500); do grep -q "receive link up" "$dir/serve.err" && break; sleep 0.02; done
  start=$(date +%s.%N)
  robot_pids=()
  for r in 1 2 3; do
    nsenter -t "${ns_pid[robot$r]}" -n -- timeout --foreground -k 5 "$guard" "$arbor" publish "$dir/robot$r.g2o" --lcm-url "$url" \
      --sender "$r" --rate "$rate" "${resend_flags[@]}" --wait-ready --timeout 60 --json \
      >"$dir/publish$r.json" 2>"$dir/publish$r.err" &
    robot_pids+=($!)
  done
  # Robot 1's link cut mid-stream: its bridge port down, the robot's eth0 loses its carrier.
  sleep "$outage_at"
  ip link set port1 down
  sleep "$outage_s"
  ip link set port1 up
  cut=$(($(tx_dropped) - cut_before))
  failed=0
  for pid in "${robot_pids[@]}"; do wait "$pid" || failed=1; done
  done_s=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { print b - a }')
  kill -TERM "$serve_pid"
  wait "$serve_pid" || failed=1
  nft -j list table bridge radio |
    jq '[.nftables[] | select(.rule) | {(.rule.comment): .rule.expr[] | select(.counter) | .counter.packets}] | add + {outage_dropped_out: '"$cut"', outage_s: '"$outage_s"', outage_at: '"$outage_at"', loss_percent: '"$loss"'}' \
      >"$dir/link.json"
  replay_f=$("$arbor" replay "$dir/merged.g2o" --json | jq '.F_final')
  edges=$(for r in 1 2 3; do grep -c '^EDGE' "$dir/robot$r.g2o"; done | paste -sd, -)
  jq -r --argjson f "$replay_f" --slurpfile link "$dir/link.json" \
    --slurpfile p1 "$dir/publish1.json" --arg run "$run" --arg edges "$edges" --arg t "$done_s" '
    "| \($run) | \($edges) | \($link[0].out) / \($link[0].in), \($link[0].outage_s) s (\($link[0].outage_dropped_out)) | " +
    "\($p1[0].resend.resent) | \(.accepted) | \(.applied) | \(.duplicates) | \(.gaps) | " +
    "\(.loss_recovery.given_up) | \(.loss_recovery.held) | \($t | tonumber | . * 10 | round / 10) | " +
    "\(.F_final) | \($f) | \(((.F_final - $f) / $f) | fabs) |"' "$dir/serve.json"
  [ "$failed" = 0 ] || { echo "run $run: a process failed; see $dir" >&2; exit 1; }
done
