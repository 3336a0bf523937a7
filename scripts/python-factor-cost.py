#!/usr/bin/env python3
"""The cost of one linearisation of a Python factor (docs/python.md, "Factors of your own"):
a 2D range-to-anchor arbor_slam.CustomFactor2 with a Python Jacobian and without one (central
differences: 1 + 2·3 calls of error()), against one call of the bare error function. Prints
microseconds per call, the median of 7 rounds. PYTHONPATH=BUILD/python python3 THIS."""
import statistics
import timeit

import numpy as np

import arbor_slam

anchor = np.array([3.0, 4.0])


def error(x):
    return np.array([np.linalg.norm(x.translation() - anchor) - 5.0])


def jacobian(x):
    t = x.translation()
    u = (t - anchor) / np.linalg.norm(t - anchor)
    return [np.concatenate([u @ x.rotation(), [0.0]]).reshape(1, 3)]


def per_call_us(stmt, number=2000):
    return statistics.median(timeit.repeat(stmt, number=number, repeat=7)) / number * 1e6


x = arbor_slam.SE2(1.0, 2.0, 0.3)
with_j = arbor_slam.CustomFactor2(0, error, np.eye(1), jacobian=jacobian)
numeric = arbor_slam.CustomFactor2(0, error, np.eye(1))
print(f"error(x) alone:                    {per_call_us(lambda: error(x)):7.1f} us")
print(f"jacobian(x) alone:                 {per_call_us(lambda: jacobian(x)):7.1f} us")
print(f"linearize, Python Jacobian:        {per_call_us(lambda: with_j.linearize([x])):7.1f} us")
print(f"linearize, central differences:    {per_call_us(lambda: numeric.linearize([x])):7.1f} us")

# In a solve: 1000 poses on a line, odometry, and a range on each (the factors' share).
graph = arbor_slam.Graph2()
for k in range(1000):
    graph.add_pose(k, arbor_slam.SE2(0.01 * k, 0, 0))
for k in range(999):
    graph.add_edge(k, k + 1, arbor_slam.SE2(0.01, 0, 0), np.eye(3) * 100)
plain = arbor_slam.solve(graph, solver="gn", max_iterations=5, relative_tolerance=0)
for with_jacobian in (True, False):
    g = arbor_slam.Graph2()
    for k in range(1000):
        g.add_pose(k, arbor_slam.SE2(0.01 * k, 0, 0))
    for k in range(999):
        g.add_edge(k, k + 1, arbor_slam.SE2(0.01, 0, 0), np.eye(3) * 100)
    for k in range(1000):
        g.add_factor(arbor_slam.CustomFactor2(k, error, np.eye(1),
                                         jacobian=jacobian if with_jacobian else None))
    r = arbor_slam.solve(g, solver="gn", max_iterations=5, relative_tolerance=0)
    print(f"GN, 1000 poses + 1000 ranges ({'Python Jacobian' if with_jacobian else 'differences'}):"
          f" {r.time_s * 1e3:.0f} ms for {r.iterations} iterations"
          f" (without the ranges: {plain.time_s * 1e3:.1f} ms)")
