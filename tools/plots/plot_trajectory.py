#!/usr/bin/python3
"""Draws a trajectory, and a reference beside it, as `arbor plot` asks (tools/cli/plot_command.cc).

usage: plot_trajectory.py CSV OUT.png TITLE
CSV: header `series,x,y`, one row per pose in order; series `estimate` or `reference` (the
estimate already aligned onto the reference by the caller). Draws the x-y plane, equal axes,
the reference dashed grey under the estimate; TITLE above (the file names and ATE/RPE). Needs
matplotlib (Debian's python3-matplotlib; the Agg backend, no display).
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, png_path, title):
    series = {}
    with open(csv_path) as f:
        for row in csv.DictReader(f):
            xs, ys = series.setdefault(row["series"], ([], []))
            xs.append(float(row["x"]))
            ys.append(float(row["y"]))
    fig, ax = plt.subplots(figsize=(7, 7))
    if "reference" in series:
        ax.plot(*series["reference"], "--", color="0.5", linewidth=1.0, label="reference")
    if "estimate" in series:
        ax.plot(*series["estimate"], color="tab:blue", linewidth=1.0, label="estimate")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="best", fontsize=8)
    ax.grid(True, linewidth=0.3)
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
