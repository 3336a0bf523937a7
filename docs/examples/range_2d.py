"""A 2D graph with a range factor, solved in batch and online, written as TUM and plotted."""
import pickle

import matplotlib.pyplot as plt
import numpy as np

import arbor_slam

plt.switch_backend("Agg")  # no display needed: write a PNG
beacon = np.array([2.0, 3.0])  # a beacon at a known position; pose 2 measures 3 m to it
graph = arbor_slam.Graph2()
for i in range(5):
    graph.add_pose(i, arbor_slam.SE2(1.1 * i, 0.3, 0.1))  # initial guesses off the truth
    if i > 0:
        graph.add_edge(i - 1, i, arbor_slam.SE2(1.0, 0.0, 0.0), 100 * np.eye(3))  # odometry
graph.add_pose_prior(0, arbor_slam.SE2(), 1e4 * np.eye(3))
graph.add_factor(arbor_slam.CustomFactor2(2, lambda x: np.linalg.norm(x.translation() - beacon) - 3,
                                     [[25.0]], name="range"))  # e = ‖t(x) − beacon‖ − 3 m
batch = arbor_slam.solve(graph, solver="gn")
smoother = arbor_slam.OnlineSmoother2()
smoother.add_graph(graph)  # the edges, the prior, then the range factor
smoother.update()
smoother.finalize()
ids, online = smoother.estimates()
assert np.allclose(online, batch.estimate, atol=1e-6)  # online and batch agree
graph.write("range_2d.tum", poses=batch.estimate)  # TUM: the poses, one line each
plt.plot(online[:, 0], online[:, 1], "o-", beacon[0], beacon[1], "r*")
plt.savefig("range_2d.png")
assert pickle.loads(pickle.dumps(batch)) == batch  # the SolveResult pickles, equal
print(f"F batch {batch.F_final:.3g}, online {smoother.objective():.3g}: range_2d.tum, .png")
