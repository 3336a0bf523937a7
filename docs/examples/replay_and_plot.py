#!/usr/bin/env python3
"""Replays a pose-graph file through Arbor's online smoother, as `arbor replay` does (one
update per edge, edges in order of their later pose), and plots the estimate with each pose's
1-sigma position ellipse from its marginal covariance (2D) or the trajectory's x-y projection
(3D) into a PNG.

    python3 docs/examples/replay_and_plot.py data/manhattan_2d.g2o manhattan.png

With the module in the build tree: PYTHONPATH=build/python; installed: nothing to set for a
system prefix, else PYTHONPATH=PREFIX/lib/python3/dist-packages (docs/python.md).
"""
import sys

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402

import arbor_slam  # noqa: E402


def replay(graph):
    smoother: arbor_slam.OnlineSmoother2 | arbor_slam.OnlineSmoother3 = (
        arbor_slam.OnlineSmoother2() if graph.dimension == 2 else arbor_slam.OnlineSmoother3())
    index = {int(i): k for k, i in enumerate(graph.ids)}
    edges, z, omega = graph.edges, graph.measurements, graph.information
    order = sorted(range(len(edges)),
                   key=lambda e: max(index[int(edges[e, 0])], index[int(edges[e, 1])]))
    for e in order:
        smoother.add_edge(int(edges[e, 0]), int(edges[e, 1]), z[e], omega[e])
        smoother.update()
    smoother.finalize()
    return smoother


def main(path, png):
    graph = arbor_slam.read(path)
    smoother = replay(graph)
    ids, poses = smoother.estimates()
    fig, ax = plt.subplots(figsize=(7, 7))
    for a, b in graph.edges:  # edges as thin lines between the estimated positions
        pa, pb = smoother.estimate(int(a)), smoother.estimate(int(b))
        ax.plot([pa[0], pb[0]], [pa[1], pb[1]], color="0.8", linewidth=0.3, zorder=1)
    ax.plot(poses[:, 0], poses[:, 1], color="tab:blue", linewidth=0.8, zorder=2)
    if graph.dimension == 2:
        # The covariance is of the tangent [v; ω] with x ⊞ τ = (t + R v, θ + ω): the position's
        # covariance in the world frame is R Σ_vv Rᵀ.
        for i, x in list(zip(ids, poses))[:: max(1, len(ids) // 60)]:
            c, s = np.cos(x[2]), np.sin(x[2])
            R = np.array([[c, -s], [s, c]])
            values, vectors = np.linalg.eigh(R @ smoother.marginal_covariance(int(i))[:2, :2] @ R.T)
            angle = np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1]))
            ax.add_patch(Ellipse(x[:2], 2 * np.sqrt(values[1]), 2 * np.sqrt(values[0]),
                                 angle=angle, fill=False, color="tab:red", linewidth=0.6))
    ax.set_aspect("equal")
    ax.set_title(f"{path}: {len(ids)} poses, F = {smoother.objective():.6g}")
    fig.savefig(png, dpi=120)
    print(f"F {smoother.objective():.10g}, wrote {png}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: replay_and_plot.py FILE OUT.png")
    main(sys.argv[1], sys.argv[2])
