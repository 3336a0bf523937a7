#!/usr/bin/env bash
# Installs dependencies, builds Arbor, and replays a graph shipped in data/ edge by edge
# (per-update latency, final F, and batch LM from the incremental estimate), then solves it
# in batch for comparison. Usage: scripts/run-demo.sh [FILE]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
build=${ARBOR_BUILD_DIR:-build}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j "$(nproc)" --target arbor
file=${1:-data/manhattan_2d.g2o}
echo "== arbor replay $file"
"$build/tools/arbor" replay "$file"
echo
echo "== arbor batch $file --init spanning-tree"
"$build/tools/arbor" batch "$file" --init spanning-tree
