#!/bin/bash
# The batch switch's A/B (docs/benchmarks.md, "Never costlier than batch"): CPU seconds (user +
# sys) of `arbor replay DATASET.g2o --threads 1` with the batch switch on (A, the defaults) and
# off (B: --batch-top-share 1 --reorder-decay 0), interleaved, REPS pairs.
# Usage: scripts/batch-switch-ab.sh DATASET [REPS]   (ARBOR=path/to/arbor, DATASETS=dir)
set -euo pipefail
arbor=${ARBOR:-build/tools/arbor}
datasets=${DATASETS:-/work/shared/datasets}
ds=$1
reps=${2:-3}
for rep in $(seq "$reps"); do
  for cfg in A B; do
    flags=()
    [ "$cfg" = B ] && flags=(--batch-top-share 1 --reorder-decay 0)
    out=$({ /usr/bin/time -f "CPU %U %S" "$arbor" replay "$datasets/$ds.g2o" --threads 1 \
      "${flags[@]}"; } 2>&1)
    cpu=$(echo "$out" | awk '/^CPU/{print $2 + $3}')
    updates=$(echo "$out" | sed -n 's/^total.*(updates \([0-9.e+-]*\) s.*/\1/p')
    F=$(echo "$out" | awk '/^F final/{print $3}')
    echo "$ds $cfg pair $rep: cpu_s=$cpu updates_wall_s=$updates F=$F"
  done
done
