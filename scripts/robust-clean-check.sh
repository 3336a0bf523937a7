#!/usr/bin/env bash
# Issue 14's clean-data goal, on every shared dataset: `arbor replay FILE --robust` against the
# plain `arbor replay FILE` (both with --information repair, which only cubicle needs), F of
# each, the robust F's relative difference, and the loop closures rejected (goal: F within 0.1%,
# at most 1% rejected). Usage: scripts/robust-clean-check.sh [NAME...] (default: every .g2o in
# ../shared/datasets/); ARBOR (default build/tools/arbor), SHARED (default ../shared), OUT
# (default /tmp/robust-clean), extra replay flags in ARGS (e.g. "--threads 1"). One TSV row per
# file.
set -euo pipefail
ARBOR=${ARBOR:-build/tools/arbor}
SHARED=${SHARED:-../shared}
OUT=${OUT:-/tmp/robust-clean}
mkdir -p "$OUT"
names=("$@")
if [ ${#names[@]} -eq 0 ]; then
  for f in "$SHARED"/datasets/*.g2o; do names+=("$(basename "$f" .g2o)"); done
fi
printf 'dataset\tF_plain\tF_robust\trobust/plain-1\trejected\tloop_closures\ttotal_s_plain\ttotal_s_robust\n'
for name in "${names[@]}"; do
  file="$SHARED/datasets/$name.g2o"
  # shellcheck disable=SC2086  # ARGS: extra replay flags
  if ! "$ARBOR" replay "$file" --information repair ${ARGS:-} --json > "$OUT/$name.plain.json" ||
    ! "$ARBOR" replay "$file" --information repair --robust ${ARGS:-} --json \
      > "$OUT/$name.robust.json"; then
    printf '%s\tno result\n' "$name"
    continue
  fi
  ${PYTHON:-python3} - "$OUT/$name.plain.json" "$OUT/$name.robust.json" "$name" <<'PY'
import json, sys
p, r = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
g = r["robust"]
closures = g["closures_inlier"] + g["closures_outlier"]
print("\t".join([sys.argv[3], f"{p['F_final']:.10g}", f"{r['F_final']:.10g}",
                 f"{r['F_final'] / p['F_final'] - 1:+.2e}", str(g["closures_outlier"]),
                 str(closures), f"{p['total_s']:.3f}", f"{r['total_s']:.3f}"]))
PY
done
