#!/usr/bin/env python3
"""Where the slow updates of a replay spend their time.

Reads the CSV of `arbor replay FILE --latency-csv OUT.csv` (one row per update, with the phase
columns swap_ms, prepare_ms, top_ms, solve_ms and reelimination_mflop of UpdateStats) and prints,
for the updates above a latency bound: what kind of update each is, which phase took most of
its time, the phases' totals, and the flops of the tops they re-eliminated.

    scripts/latency-phases.py OUT.csv [BOUND_MS]      (BOUND_MS: 3)
"""
import csv
import statistics
import sys
from collections import Counter

PHASES = ["swap_ms", "prepare_ms", "top_ms", "solve_ms"]


def kind(row):
    if row["async_swapped"] == "1":
        return "swap"
    if int(row["variables_relinearized"]) > 0:
        return "relinearising"
    if int(row["cliques_reeliminated"]) > 0:
        return "re-eliminating, nothing relinearised"
    if int(row["cliques_updated"]) > 0:
        return "fold-in"
    return "other"


def quantile(sorted_values, q):
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    path = sys.argv[1]
    bound = float(sys.argv[2]) if len(sys.argv) == 3 else 3.0
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    missing = [c for c in PHASES + ["reelimination_mflop"] if rows and c not in rows[0]]
    if missing:
        sys.exit(f"{path}: no column {', '.join(missing)} (a CSV of an older arbor?)")
    value = lambda row, key: float(row[key])
    slow = [r for r in rows if value(r, "latency_ms") > bound]
    print(f"{path}: {len(rows)} updates, {len(slow)} above {bound} ms")
    if not slow:
        return
    by_kind = Counter((kind(r), max(PHASES, key=lambda k: value(r, k))) for r in slow)
    for (k, phase), n in by_kind.most_common():
        print(f"  {n:6d}  {k}; most time in {phase}")
    total = sum(value(r, "latency_ms") for r in slow)
    for key in PHASES:
        v = sorted(value(r, key) for r in slow)
        print(f"  {key}: {sum(v):.0f} ms ({100 * sum(v) / total:.0f}% of their {total:.0f} ms), "
              f"median {statistics.median(v):.2f}, max {v[-1]:.2f}")
    tops = [r for r in slow if value(r, "reelimination_mflop") > 0]
    if tops:
        mflop = sorted(value(r, "reelimination_mflop") for r in tops)
        rate = sorted(value(r, "reelimination_mflop") / value(r, "top_ms")
                      for r in tops if value(r, "top_ms") > 0)
        print(f"  {len(tops)} re-eliminated a top: MFlop p10 {quantile(mflop, 0.1):.1f}, "
              f"median {statistics.median(mflop):.1f}, p90 {quantile(mflop, 0.9):.1f}; "
              f"GFlop/s in step 4 median {statistics.median(rate):.1f}")


if __name__ == "__main__":
    main()
