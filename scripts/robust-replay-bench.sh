#!/usr/bin/env bash
# The "Robust replay" table of docs/benchmarks.md: for each shared robust file, `arbor replay
# --robust` and the clean replay of its base file; F over the base file's edges at the robust
# estimate (the estimate's vertices with the base edges, scored by `arbor batch --init file
# --max-iterations 0`), F* from reference/optimum.tsv, precision and recall of the rejected edges
# against the labels (pairs unordered). Usage: scripts/robust-replay-bench.sh [NAME...]
# (default: every file in ../shared/datasets/robust/); ARBOR (default build/tools/arbor),
# SHARED (default ../shared), OUT (default /tmp/robust-replay). Prints one TSV row per file.
set -euo pipefail
ARBOR=${ARBOR:-build/tools/arbor}
SHARED=${SHARED:-../shared}
OUT=${OUT:-/tmp/robust-replay}
mkdir -p "$OUT"
names=("$@")
if [ ${#names[@]} -eq 0 ]; then
  for f in "$SHARED"/datasets/robust/*.g2o; do names+=("$(basename "$f" .g2o)"); done
fi
printf 'dataset\tF_clean/F*\tprecision\trecall\trejected\tlabels\ttotal_s\tp99_ms\tclean_total_s\tclean_p99_ms\tgraduation_steps\n'
for name in "${names[@]}"; do
  base=${name%_*}; base=${base%_*}
  file="$SHARED/datasets/robust/$name.g2o"
  # shellcheck disable=SC2086  # ROBUST_ARGS: extra flags, e.g. "--inlier-threshold 2"
  if ! timeout "${LIMIT:-300}" "$ARBOR" replay "$file" --robust ${ROBUST_ARGS:-} --json -o "$OUT/$name.est.g2o" \
    --rejected-out "$OUT/$name.rej" > "$OUT/$name.json"; then
    printf '%s\tno result in %s s\n' "$name" "${LIMIT:-300}"
    continue
  fi
  [ -s "$OUT/$base.clean.json" ] ||
    "$ARBOR" replay "$SHARED/datasets/$base.g2o" --json > "$OUT/$base.clean.json"
  { grep '^VERTEX' "$OUT/$name.est.g2o"; grep -v '^VERTEX' "$SHARED/datasets/$base.g2o"; } \
    > "$OUT/$name.scored.g2o"
  if ! "$ARBOR" batch "$OUT/$name.scored.g2o" --init file --max-iterations 0 --json \
    > "$OUT/$name.score.json" 2> "$OUT/$name.score.err"; then
    printf '%s\tdiverged (the estimate cannot be scored: %s)\n' "$name" "$(head -c 200 "$OUT/$name.score.err")"
    continue
  fi
  ${PYTHON:-python3} - "$name" "$base" "$OUT" "$SHARED" <<'PY'
import json, sys
name, base, out, shared = sys.argv[1:5]
r = json.load(open(f"{out}/{name}.json")); c = json.load(open(f"{out}/{base}.clean.json"))
F = json.load(open(f"{out}/{name}.score.json"))["F_final"]
star = {l.split("\t")[0]: float(l.split("\t")[2]) for l in open(f"{shared}/reference/optimum.tsv")
        if not l.startswith("#") and not l.startswith("dataset")}[base]
pairs = lambda p: {tuple(sorted(map(int, l.split()[:2]))) for l in open(p) if l.strip() and not l.startswith("#")}
rej, lab = pairs(f"{out}/{name}.rej"), pairs(f"{shared}/datasets/robust/{name}.labels")
tp = len(rej & lab)
prec = tp / len(rej) if rej else 1.0
print("\t".join([name, f"{F / star:.5g}", f"{prec:.4f}", f"{tp / len(lab):.4f}", str(len(rej)),
                 str(len(lab)), f"{r['total_s']:.3f}", f"{r['latency_ms']['p99']:.3f}",
                 f"{c['total_s']:.3f}", f"{c['latency_ms']['p99']:.3f}",
                 str(r['robust']['graduation_steps'])]))
PY
done
