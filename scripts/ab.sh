#!/usr/bin/env bash
# The A/B guard: is a change to the smoother, the factors or the robust layer slower, or does it
# move a result? Builds two revisions of Arbor and replays the same files with each, interleaved
# (old, new, new, old, ... so drift on the machine falls on both), pinned to one core, best of N.
# Prints per file the best `update_s` (the updates' own time, as `arbor replay --json` reports
# it) of each build, their ratio new/old, p99 of each, and whether F_final moved.
# --instructions counts instead the instructions the updates execute (callgrind, collecting
# inside OnlineSmoother::update() only), one run each: slower (~50x), but the same count on a
# loaded machine, where wall-clock ratios of a few percent drown in the noise.
#
#   scripts/ab.sh OLD_REF NEW_REF [options] [-- replay flags...]
#     OLD_REF, NEW_REF   any git revision; WORKTREE is the checkout's uncommitted state
#     -n N               runs per file and build, best kept (default 3)
#     --sets LIST        comma-separated files: a name in $DATASETS (.g2o optional) or a path
#                        (default: the six shared 2D sets and data/'s replays)
#     --cpu C            core to pin to (default: the last one)
#     --arbor-old PATH, --arbor-new PATH   use these binaries instead of building
#     --instructions     instructions of the updates (valgrind's callgrind) instead of seconds
#   Everything after -- goes to both `arbor replay` runs (default: --threads 1).
#   Environment: DATASETS (default ../shared/datasets), ARBOR_AB_DIR (builds, default
#   ~/.cache/arbor-ab: one folder per commit, reused), F_TOL (relative, default 1e-9).
#
# A benchmark, not a test: its figures go into the note of the change it guards
# (docs/benchmarks.md, "The A/B guard"). Exit status 0 unless a build or a replay fails.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
datasets=${DATASETS:-$repo/../shared/datasets}
cache=${ARBOR_AB_DIR:-$HOME/.cache/arbor-ab}
f_tol=${F_TOL:-1e-9}
runs=3
cpu=$(($(nproc) - 1))
sets="intel,MIT,M3500,M3500a,M3500b,manhattan,$repo/data/manhattan_2d.g2o"
arbor_old="" arbor_new="" instructions=0
replay_flags=(--threads 1)

usage() { sed -n '2,25p' "$0" | sed 's/^# \{0,1\}//'; }
die() { echo "ab.sh: $*" >&2; exit 2; }

[ $# -ge 1 ] && { [ "$1" = -h ] || [ "$1" = --help ]; } && { usage; exit 0; }
[ $# -ge 2 ] || { usage >&2; exit 2; }
old_ref=$1 new_ref=$2
shift 2
while [ $# -gt 0 ]; do
  case $1 in
    -n) [[ ${2:-} =~ ^[1-9][0-9]*$ ]] || die "-n takes a positive count, not '${2:-}'"
        runs=$2; shift 2 ;;
    --sets) sets=${2:?--sets takes a list}; shift 2 ;;
    --cpu) [[ ${2:-} =~ ^[0-9]+$ ]] && [ "$2" -lt "$(nproc)" ] ||
             die "--cpu takes a core number below $(nproc), not '${2:-}'"
           cpu=$2; shift 2 ;;
    --arbor-old) arbor_old=${2:?}; shift 2 ;;
    --arbor-new) arbor_new=${2:?}; shift 2 ;;
    --instructions) instructions=1; runs=1; shift ;;
    --) shift; replay_flags=("$@"); break ;;
    *) die "unknown option '$1' (see --help)" ;;
  esac
done
command -v jq >/dev/null || die "needs jq (scripts/install-deps.sh installs it)"

# Resolves a revision to a commit; WORKTREE snapshots the uncommitted state as a commit object
# (git stash create: nothing in the checkout changes).
resolve() {
  if [ "$1" = WORKTREE ]; then
    local c
    c=$(git -C "$repo" stash create)
    if [ -n "$c" ]; then echo "$c"; else git -C "$repo" rev-parse HEAD; fi
  else
    git -C "$repo" rev-parse --verify "$1^{commit}" 2>/dev/null || die "no revision '$1'"
  fi
}

# Builds the arbor binary of a commit once (Release, no tests, benchmarks or Python) and prints
# its path. The sources come from git archive, so the checkout is never touched.
build() {
  local sha=$1 dir=$cache/$1
  if [ ! -x "$dir/build/tools/arbor" ]; then
    echo "ab.sh: building $sha in $dir" >&2
    rm -rf "$dir" && mkdir -p "$dir/src"
    git -C "$repo" archive "$sha" | tar -x -C "$dir/src"
    local launcher=()
    command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache
                                             -DCMAKE_C_COMPILER_LAUNCHER=ccache)
    cmake -S "$dir/src" -B "$dir/build" -DCMAKE_BUILD_TYPE=Release -DARBOR_BUILD_TESTS=OFF \
      -DARBOR_BUILD_BENCHMARKS=OFF -DARBOR_PYTHON=OFF "${launcher[@]}" >"$dir/build.log" 2>&1 &&
      cmake --build "$dir/build" -j "$(nproc)" --target arbor >>"$dir/build.log" 2>&1 ||
      { tail -20 "$dir/build.log" >&2; die "build of $sha failed (log: $dir/build.log)"; }
  fi
  echo "$dir/build/tools/arbor"
}

old_sha=$(resolve "$old_ref") new_sha=$(resolve "$new_ref")
[ -n "$arbor_old" ] || arbor_old=$(build "$old_sha")
[ -n "$arbor_new" ] || arbor_new=$(build "$new_sha")

path_of() {
  case $1 in
    */*) echo "$1" ;;
    *.g2o) echo "$datasets/$1" ;;
    *) echo "$datasets/$1.g2o" ;;
  esac
}

# One pinned replay; prints "update_s p99_ms F_final" (--instructions: the updates'
# instructions in place of update_s, p99 0).
replay() {
  local out err
  if [ "$instructions" = 1 ]; then
    err=$(mktemp)
    out=$(valgrind --tool=callgrind --callgrind-out-file=/dev/null \
      '--toggle-collect=arbor::OnlineSmoother<*>::update()' \
      "$1" replay "$2" --json "${replay_flags[@]}" 2>"$err") ||
      { cat "$err" >&2; die "replay of $2 with $1 under callgrind failed"; }
    local ir
    ir=$(sed -n 's/.*Collected : \([0-9]*\).*/\1/p' "$err")
    rm -f "$err"
    jq -r --arg ir "$ir" '"\($ir) 0 \(.F_final)"' <<<"$out"
    return
  fi
  out=$(taskset -c "$cpu" "$1" replay "$2" --json "${replay_flags[@]}") ||
    die "replay of $2 with $1 failed"
  jq -r '"\(.update_s) \(.latency_ms.p99) \(.F_final)"' <<<"$out"
}

echo "A/B guard: old $old_ref ($(git -C "$repo" rev-parse --short "$old_sha")), new $new_ref" \
  "($(git -C "$repo" rev-parse --short "$new_sha")); best of $runs, pinned to core $cpu$([ "$instructions" = 1 ] && echo ", callgrind");" \
  "arbor replay FILE ${replay_flags[*]}"
if [ "$instructions" = 1 ]; then
  printf '%-22s %14s %14s %7s  %s\n' file old_Ir new_Ir ratio F
else
  printf '%-22s %10s %10s %7s %9s %9s %7s  %s\n' file old_s new_s ratio old_p99 new_p99 ratio F
fi
IFS=, read -r -a files <<<"$sets"
ratios=()
for name in "${files[@]}"; do
  file=$(path_of "$name")
  [ -f "$file" ] || die "no file '$file' (from '$name')"
  best_old="" best_new="" p99_old="" p99_new="" F_old="" F_new=""
  for r in $(seq "$runs"); do
    # Alternate who goes first, so a warming or cooling machine favours neither.
    order="old new"
    [ $((r % 2)) -eq 0 ] && order="new old"
    for who in $order; do
      if [ "$who" = old ]; then bin=$arbor_old; else bin=$arbor_new; fi
      read -r t p99 F <<<"$(replay "$bin" "$file")"
      [ -n "$t" ] || exit 2
      if [ "$who" = old ]; then
        F_old=$F
        if [ -z "$best_old" ] || awk "BEGIN{exit !($t < $best_old)}"; then
          best_old=$t p99_old=$p99
        fi
      else
        F_new=$F
        if [ -z "$best_new" ] || awk "BEGIN{exit !($t < $best_new)}"; then
          best_new=$t p99_new=$p99
        fi
      fi
    done
  done
  ratio=$(awk "BEGIN{printf \"%.3f\", $best_new / $best_old}")
  p99_ratio=$(awk "BEGIN{printf \"%.3f\", ($p99_old > 0) ? $p99_new / $p99_old : 1}")
  F_note=$(awk -v a="$F_old" -v b="$F_new" -v tol="$f_tol" 'BEGIN{
    d = (a > b ? a - b : b - a) / (a > 0 ? a : 1)
    if (d <= tol) printf "same (%.10g)", b; else printf "MOVED %.10g -> %.10g (%.2e)", a, b, d }')
  ratios+=("$ratio")
  name=$(basename "$file" .g2o)
  if [ "$instructions" = 1 ]; then
    printf '%-22s %14d %14d %7s  %s\n' "$name" "$best_old" "$best_new" "$ratio" "$F_note"
  else
    printf '%-22s %10.4f %10.4f %7s %9.4f %9.4f %7s  %s\n' "$name" "$best_old" "$best_new" \
      "$ratio" "$p99_old" "$p99_new" "$p99_ratio" "$F_note"
  fi
done
printf '%s\n' "${ratios[@]}" |
  awk '{s += log($1); n++; if ($1 > m) m = $1} END{printf "geometric mean of the ratios %.3f, largest %.3f\n", exp(s / n), m}'
