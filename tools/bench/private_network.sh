# Sourced by the udpm benchmark scripts: enter_private_network "$@" re-runs the calling script
# inside a private network namespace of its own (unshare --net, or -rn unprivileged), brings up
# loopback with multicast and routes 224.0.0.0/4 to it, and stops unless loopback is the only
# interface, so no datagram with ttl=0 can reach the machine's network.
enter_private_network() {
  if [ -z "${ARBOR_PRIVATE_NETWORK:-}" ]; then
    export ARBOR_PRIVATE_NETWORK=1
    unshare --net true 2>/dev/null && exec unshare --net -- bash "$0" "$@"
    exec unshare -rn -- bash "$0" "$@"
  fi
  ip link set lo up
  ip link set lo multicast on
  ip route add 224.0.0.0/4 dev lo
  if [ "$(ip -o link show | wc -l)" != 1 ]; then
    echo "$(basename "$0"): not in a private network namespace (interfaces besides lo); stopping" >&2
    exit 1
  fi
}
