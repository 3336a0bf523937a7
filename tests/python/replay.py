"""A file replayed through the online smoother as `arbor replay` feeds it (one update per edge,
edges in order of max(i, j) of their dense indices, then file order; the final
relinearise-all pass), for graphs without priors."""
import numpy as np

import arbor_slam


def replay(graph, **smoother_options):
    """Returns (smoother, F) with F over the graph at the final estimate (as `arbor replay`'s
    F_final)."""
    smoother = (arbor_slam.OnlineSmoother2 if graph.dimension == 2 else arbor_slam.OnlineSmoother3)(
        **smoother_options)
    index = {int(i): k for k, i in enumerate(graph.ids)}
    edges = graph.edges
    last = [max(index[int(a)], index[int(b)]) for a, b in edges]
    order = sorted(range(len(edges)), key=lambda e: last[e])  # stable: file order among ties
    measurements, information = graph.measurements, graph.information
    for e in order:
        smoother.add_edge(int(edges[e, 0]), int(edges[e, 1]), measurements[e], information[e])
        smoother.update()
    smoother.finalize()
    ids, poses = smoother.estimates()
    full = graph.poses.copy()  # poses never reached keep the file's value
    for i, row in zip(ids, poses):
        full[index[int(i)]] = row
    return smoother, graph.objective(full)
