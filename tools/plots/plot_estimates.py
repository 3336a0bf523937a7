#!/usr/bin/python3
"""Plots each solver's estimate of a pose graph overlaid, one PNG per dataset, as the paper's
Figures 3-5 (Juric et al., "A Comparison of Graph Optimization Approaches for Pose Estimation
in SLAM", MIPRO 2021).

usage: plot_estimates.py OUT_DIR PLOT_DIR [NAME ...]
Reads OUT_DIR/estimates/NAME/SOLVER.csv (header x,y or x,y,z; one row per pose, as written by
`arbor bench paper --out-dir OUT_DIR`) and, if present, OUT_DIR/results.tsv for F in the legend.
Writes PLOT_DIR/NAME_estimates.png: the trajectory (poses in order) of every solver overlaid,
and beside it one small panel per solver (the first six); 3D sets are drawn as their x-y
projection. Needs Debian's python3-matplotlib: run it with
/usr/bin/python3.
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# Solver order and colours: the same in every figure.
SOLVERS = ["replay", "lm", "gn", "dogleg", "rtr", "ceres"]
COLOURS = {"replay": "tab:blue", "lm": "tab:orange", "gn": "tab:green", "dogleg": "tab:red",
           "rtr": "tab:purple", "ceres": "tab:gray"}


def read_estimate(path):
    xs, ys = [], []
    with open(path) as f:
        for row in csv.DictReader(f):
            xs.append(float(row["x"]))
            ys.append(float(row["y"]))
    return xs, ys


def read_results(out_dir):
    """(dataset, solver) -> (F, termination) from results.tsv, or {} if absent."""
    path = os.path.join(out_dir, "results.tsv")
    table = {}
    if not os.path.exists(path):
        return table
    with open(path) as f:
        for row in csv.DictReader(f, delimiter="\t"):
            table[(row["dataset"], row["solver"])] = (row["F"], row["termination"])
    return table


def plot(out_dir, name, plot_dir, results):
    folder = os.path.join(out_dir, "estimates", name)
    found = [s[:-4] for s in os.listdir(folder) if s.endswith(".csv")]
    solvers = [s for s in SOLVERS if s in found] + sorted(s for s in found if s not in SOLVERS)
    if not solvers:
        raise SystemExit(f"{folder}: no estimates")
    estimates = {s: read_estimate(os.path.join(folder, s + ".csv")) for s in solvers}
    with open(os.path.join(folder, solvers[0] + ".csv")) as f:
        dims = len(f.readline().strip().split(","))
    # Left: every estimate overlaid; right: one small panel per solver (where they disagree the
    # overlay alone is unreadable).
    fig = plt.figure(figsize=(11, 5), dpi=90)
    grid = fig.add_gridspec(2, 5, width_ratios=[2.2, 2.2, 1, 1, 1])
    ax = fig.add_subplot(grid[:, :2])
    for k, solver in enumerate(solvers):
        xs, ys = estimates[solver]
        label = solver
        if (name, solver) in results:
            F, term = results[(name, solver)]
            label = f"{solver}: F={float(F):.6g} ({term})"
        # Later solvers draw thinner and dashed, so that identical estimates stay visible.
        ax.plot(xs, ys, lw=max(0.3, 0.9 - 0.1 * k), alpha=0.8, color=COLOURS.get(solver),
                ls="-" if k == 0 else (0, (4, 2 + k)), label=label)
    ax.set_title(f"{name}: estimates" + (" (x-y projection)" if dims == 3 else ""), fontsize=10)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=6)
    for k, solver in enumerate(solvers[:6]):
        small = fig.add_subplot(grid[k // 3, 2 + k % 3])
        xs, ys = estimates[solver]
        small.plot(xs, ys, lw=0.3, color=COLOURS.get(solver, "black"))
        small.set_title(solver, fontsize=8)
        small.set_aspect("equal", adjustable="datalim")
        small.set_xticks([])
        small.set_yticks([])
    fig.tight_layout()
    out = os.path.join(plot_dir, f"{name}_estimates.png")
    fig.savefig(out)
    plt.close(fig)
    print(out)


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    out_dir, plot_dir = sys.argv[1], sys.argv[2]
    os.makedirs(plot_dir, exist_ok=True)
    names = sys.argv[3:] or sorted(os.listdir(os.path.join(out_dir, "estimates")))
    results = read_results(out_dir)
    for name in names:
        plot(out_dir, name, plot_dir, results)


if __name__ == "__main__":
    main()
