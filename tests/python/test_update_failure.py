# An update in which a factor of your own fails applies nothing (docs/python.md, "When an update
# raises"): the exception its function raised comes out of update() with a note naming the
# factor, its poses and their values (a non-finite or misshapen result: arbor_slam.FactorError);
# the failing queued factor is taken out, and the updates after it give the estimate of a
# smoother that never saw it. add_graph checks the whole graph before adding anything.
import numpy as np
import pytest

import arbor_slam


class Boom(Exception):
    pass


ANCHOR = np.array([3.0, 4.0])


def walk(n):
    """Odometry along a bent line and a range to ANCHOR every third pose."""
    edges, ranges = [], []
    for k in range(1, n):
        edges.append((k - 1, k, [1.0, 0.02 * (k % 3), 0.1]))
    for k in range(0, n, 3):
        x = k * 0.9
        ranges.append((k, float(np.hypot(x - ANCHOR[0], ANCHOR[1])) + 0.05 * (k % 2)))
    return edges, ranges


def range_factor(k, r, state=None):
    def error(x):
        if state is not None and state["mode"] == "raise":
            raise Boom("no range today")
        e = np.linalg.norm(x.translation() - ANCHOR) - r
        if state is not None and state["mode"] == "nan":
            e = float("nan")
        return np.array([e])

    return arbor_slam.CustomFactor2(k, error, np.eye(1) * 4.0, name="range")


class Bad:
    def __init__(self, k, mode):
        self.state = {"mode": "ok"}
        self.mode = mode
        self.factor = range_factor(k, 1.0, self.state)


@pytest.mark.parametrize("mode", ["raise", "nan"])
def test_a_failing_update_applies_nothing_and_the_next_ones_match(mode):
    n, bad_at = 30, 12
    bad = Bad(bad_at - 2, mode)
    a = arbor_slam.OnlineSmoother2(threads=2)
    edges, ranges = walk(n)
    a.add_pose_prior(0, [0, 0, 0], np.eye(3) * 100)
    b = arbor_slam.OnlineSmoother2(threads=2)
    b.add_pose_prior(0, [0, 0, 0], np.eye(3) * 100)
    by_pose = dict(ranges)
    for (i, j, z) in edges:
        for s in (a, b):
            s.add_edge(i, j, z, np.eye(3) * 50)
            if j in by_pose:
                s.add_factor(range_factor(j, by_pose[j]))
        if j == bad_at:
            a.add_factor(bad.factor)  # evaluated once here: fine
            before = [np.asarray(a.estimate(k)) for k in range(j)]
            F_before, stats_before = a.objective(), a.stats()
            bad.state["mode"] = mode
            expected = Boom if mode == "raise" else arbor_slam.FactorError
            with pytest.raises(expected) as raised:
                a.update()
            text = str(raised.value) + " ".join(getattr(raised.value, "__notes__", []))
            assert "'range'" in text and "t = (" in text, text
            assert "taken out of the queue" in text, text
            if mode == "nan":
                assert "finite" in text
            # Nothing applied: the same estimate, objective and counts.
            assert a.objective() == F_before
            for k in range(j):
                np.testing.assert_array_equal(np.asarray(a.estimate(k)), before[k])
            assert a.stats().updates == stats_before.updates
        a.update()
        b.update()
        assert a.objective() == pytest.approx(b.objective(), rel=1e-12, abs=0)
    for k in range(n):
        np.testing.assert_allclose(np.asarray(a.estimate(k)), np.asarray(b.estimate(k)),
                                   rtol=0, atol=1e-12)
    a.finalize()
    b.finalize()
    assert a.objective() == pytest.approx(b.objective(), rel=1e-12, abs=0)


def graph_with(n, custom=None):
    g = arbor_slam.Graph2()
    edges, ranges = walk(n)
    for k in range(n):
        g.add_pose(k, arbor_slam.SE2(0.9 * k, 0, 0))
    for (i, j, z) in edges:
        g.add_edge(i, j, arbor_slam.SE2(*z), np.eye(3) * 50)
    if custom is not None:
        g.add_factor(custom)
    return g


def test_add_graph_is_all_or_nothing_for_a_refused_element():
    s = arbor_slam.OnlineSmoother2()
    s.add_pose_prior(0, [0, 0, 0], np.eye(3) * 100)
    s.update()
    # A second chain, not joined to the first, and a factor between the two: the online
    # smoother refuses it (two components), after the edges had made 15 poses.
    g = graph_with(10)
    for k in range(20, 25):
        g.add_pose(k, arbor_slam.SE2(k, 5, 0))
        if k > 20:
            g.add_edge(k - 1, k, arbor_slam.SE2(1, 0, 0), np.eye(3))
    g.add_factor(arbor_slam.CustomFactor2(
        [2, 22], lambda a, b: a.translation() - b.translation(), np.eye(2), name="between"))
    with pytest.raises(ValueError, match="'between' on 2: its poses are in two components.*nothing added"):
        s.add_graph(g)
    assert s.num_poses == 1 and not s.has_pose(3)
    # A custom factor on a pose nothing creates.
    g = graph_with(10, custom=range_factor(0, 5.0))
    g.add_pose(42, arbor_slam.SE2())
    g.add_factor(range_factor(42, 1.0))
    with pytest.raises(ValueError, match="unknown pose id 42.*nothing added"):
        s.add_graph(g)
    assert s.num_poses == 1
    # A custom factor whose function raises at the graph's poses.
    state = {"mode": "raise"}
    g = graph_with(10, custom=range_factor(4, 2.0, state))
    with pytest.raises(Boom) as raised:
        s.add_graph(g)
    assert "nothing added" in " ".join(raised.value.__notes__)
    assert s.num_poses == 1
    state["mode"] = "ok"
    result = s.add_graph(g)
    assert result.accepted == 10
    s.update()
    assert s.num_poses == 10
