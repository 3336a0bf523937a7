#!/usr/bin/env bash
# Scores `arbor batch --robust` on the shared robust files (../shared/datasets/robust/, made by
# false loop closures appended to a shared dataset, with their labels): F over the base file's
# edges at the estimate against the clean F* (../shared/reference/optimum.tsv), precision and
# recall of the rejected edges against the labels (pairs unordered), GNC's steps and time.
#
#   scripts/eval-robust-batch.sh [--only NAME,NAME] [-- EXTRA ARBOR BATCH FLAGS]
#
# Environment: ARBOR (default build/tools/arbor), SHARED (default /work/shared). One TSV line a
# file on stdout.
set -euo pipefail
ARBOR=${ARBOR:-build/tools/arbor}
SHARED=${SHARED:-/work/shared}
only=""
if [[ ${1:-} == --only ]]; then only=$2; shift 2; fi
if [[ ${1:-} == -- ]]; then shift; fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
printf 'dataset\tthreshold\tF_clean/F*\tprecision\trecall\trejected\tlabels\tsteps\tmessage\tgnc_s\theld_out\ttaken_back\ttotal_s\n'
for g2o in "$SHARED"/datasets/robust/*.g2o; do
  name=$(basename "$g2o" .g2o)
  if [[ -n $only && ",$only," != *",$name,"* ]]; then continue; fi
  base=${name%_*_*}
  labels=${g2o%.g2o}.labels
  json=$("$ARBOR" batch "$g2o" --robust --json -o "$tmp/est.g2o" --rejected-out "$tmp/rej" "$@")
  # The base file's edges with the estimate's vertices, scored without a step.
  { grep '^VERTEX' "$tmp/est.g2o"; grep -v '^VERTEX' "$SHARED/datasets/$base.g2o"; } >"$tmp/clean.g2o"
  fclean=$("$ARBOR" batch "$tmp/clean.g2o" --init file --max-iterations 0 --json)
  python3 - "$json" "$fclean" "$SHARED/reference/optimum.tsv" "$base" "$labels" "$tmp/rej" "$name" <<'PY'
import json, sys
run, clean, optimum, base, labels, rej, name = sys.argv[1:]
run, clean = json.loads(run), json.loads(clean)
fstar = next(float(l.split('\t')[2]) for l in open(optimum) if l.split('\t')[0] == base)
pair = lambda l: frozenset(l.split()[:2])
truth = {pair(l) for l in open(labels) if l.strip()}
got = [pair(l) for l in open(rej) if l.strip()]
hit = sum(p in truth for p in got)
precision = hit / len(got) if got else 1.0
recall = hit / len(truth) if truth else 1.0
print(f"{name}\t{run['inlier_threshold']:.4g}\t{clean['F_final'] / fstar:.6g}\t{precision:.3f}\t"
      f"{recall:.3f}\t{len(got)}\t{len(truth)}\t{run['gnc_iterations']}\t{run['gnc_message']}\t"
      f"{run['gnc_time_s']:.3g}\t{run.get('known_outliers', 0)}\t{run.get('readmitted_online', 0)}\t"
      f"{run['total_s']:.3g}")
PY
done
