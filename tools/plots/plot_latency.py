#!/usr/bin/python3
"""Plots per-update latency against step from `arbor replay --latency-csv` files.

usage: plot_latency.py OUT_DIR CSV [CSV ...]
Writes OUT_DIR/<name>_latency.png per CSV (name = CSV file stem): latency of every update
(log scale) and a running p99 over a window of 200 updates, so a reader can see whether latency
stays flat as the graph grows. Needs Debian's python3-matplotlib: run it with /usr/bin/python3.
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def running_percentile(values, window, q):
    out = []
    for k in range(len(values)):
        chunk = sorted(values[max(0, k - window + 1): k + 1])
        out.append(chunk[min(len(chunk) - 1, int(q * len(chunk)))])
    return out


def plot(csv_path, out_dir):
    name = os.path.splitext(os.path.basename(csv_path))[0]
    steps, edges, latency = [], [], []
    with open(csv_path) as f:
        for row in csv.DictReader(f):
            steps.append(int(row["step"]))
            edges.append(int(row["edges"]))
            latency.append(float(row["latency_ms"]))
    if not steps:
        raise SystemExit(f"{csv_path}: no rows")
    fig, ax = plt.subplots(figsize=(8, 3.5), dpi=110)
    ax.scatter(steps, latency, s=2, alpha=0.35, color="tab:blue", label="update latency")
    ax.plot(steps, running_percentile(latency, 200, 0.99), color="tab:red", lw=1.2,
            label="running p99 (200 updates)")
    ax.set_yscale("log")
    ax.set_xlabel("update (edges fed in order of max(i, j))")
    ax.set_ylabel("latency [ms]")
    ax.set_title(f"{name}: {len(steps)} updates, {edges[-1]} edges")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    out = os.path.join(out_dir, f"{name}_latency.png")
    fig.savefig(out)
    plt.close(fig)
    print(out)


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    os.makedirs(sys.argv[1], exist_ok=True)
    for path in sys.argv[2:]:
        plot(path, sys.argv[1])


if __name__ == "__main__":
    main()
