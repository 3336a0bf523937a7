"""Factors of your own in Python (arbor_slam.CustomFactor2 / CustomFactor3, docs/python.md): a range
factor to a known anchor gives the analytic optimum in batch and online, Python Jacobians agree
with the central differences, online equals batch with odometry and ranges, an exception in the
error function is raised by the solve or update, and bad input is a ValueError."""
import pickle
import threading

import numpy as np
import pytest

import arbor_slam


def range_error(anchor, rho):
    anchor = np.asarray(anchor, dtype=float)
    return lambda x: np.array([np.linalg.norm(x.translation() - anchor) - rho])


def range_jacobian(anchor):
    """∂e/∂v = uᵀR, ∂e/∂ω = 0 with u = (t − a)/‖t − a‖ (core/example_factors.h)."""
    anchor = np.asarray(anchor, dtype=float)

    def jacobian(x):
        t = x.translation()
        u = (t - anchor) / np.linalg.norm(t - anchor)
        rot = np.zeros(1 if len(t) == 2 else 3)
        return [np.concatenate([u @ x.rotation(), rot]).reshape(1, -1)]

    return jacobian


def relative_position_error(p):
    """e = Rᵢᵀ(tⱼ − tᵢ) − p (core/example_factors.h), 2D."""
    return lambda xi, xj: xi.rotation().T @ (xj.translation() - xi.translation()) - p


def relative_position_jacobian(xi, xj):
    q = xi.rotation().T @ (xj.translation() - xi.translation())
    ji = np.hstack([-np.eye(2), np.array([[q[1]], [-q[0]]])])
    jj = np.hstack([xi.rotation().T @ xj.rotation(), np.zeros((2, 1))])
    return [ji, jj]


@pytest.mark.parametrize("with_jacobian", [False, True])
def test_range_to_an_anchor_reaches_the_analytic_optimum(with_jacobian):
    # A pose prior at (2, 0, 0) and a range of 3 to the origin, both of weight 1: by symmetry
    # y = θ = 0 and x minimises (x − 2)² + (x − 3)², x = 2.5, F = 0.5.
    anchor = [0.0, 0.0]
    factor = arbor_slam.CustomFactor2(
        7, range_error(anchor, 3.0), np.eye(1),
        jacobian=range_jacobian(anchor) if with_jacobian else None, name="range")
    graph = arbor_slam.Graph2()
    graph.add_pose(7, arbor_slam.SE2(2.0, 0.0, 0.0))
    graph.add_pose_prior(7, arbor_slam.SE2(2.0, 0.0, 0.0), np.eye(3))
    graph.add_factor(factor)
    assert graph.num_custom_factors == 1
    for solver in ("lm", "gn"):
        result = arbor_slam.solve(graph, solver=solver)
        np.testing.assert_allclose(result.estimate[0], [2.5, 0.0, 0.0], atol=1e-8)
        assert result.F_final == pytest.approx(0.5, rel=1e-9)

    smoother = arbor_slam.OnlineSmoother2()
    smoother.add_pose_prior(7, [2.0, 0.0, 0.0], np.eye(3))
    assert smoother.add_factor(factor) == "accepted"
    smoother.update()
    smoother.finalize()
    np.testing.assert_allclose(smoother.estimate(7), [2.5, 0.0, 0.0], atol=1e-8)
    assert smoother.objective() == pytest.approx(0.5, rel=1e-9)


def test_range_in_3d_reaches_the_analytic_optimum():
    factor = arbor_slam.CustomFactor3(0, range_error([0.0, 0.0, 0.0], 3.0), np.eye(1),
                                 jacobian=range_jacobian([0.0, 0.0, 0.0]))
    graph = arbor_slam.Graph3()
    graph.add_pose(0, arbor_slam.SE3([0.0, 0.0, 2.0]))
    graph.add_pose_prior(0, arbor_slam.SE3([0.0, 0.0, 2.0]), np.eye(6))
    graph.add_factor(factor)
    result = arbor_slam.solve(graph)
    np.testing.assert_allclose(result.estimate[0], [0, 0, 2.5, 0, 0, 0, 1], atol=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_python_jacobians_equal_central_differences(seed):
    rng = np.random.default_rng(seed)
    anchor = rng.normal(size=2) * 5
    x = arbor_slam.SE2(*rng.normal(size=3))
    analytic = arbor_slam.CustomFactor2(0, range_error(anchor, 2.0), np.eye(1),
                                   jacobian=range_jacobian(anchor))
    numeric = arbor_slam.CustomFactor2(0, range_error(anchor, 2.0), np.eye(1))
    assert analytic.has_jacobian and not numeric.has_jacobian
    (ea, ja), (en, jn) = analytic.linearize([x]), numeric.linearize([x])
    np.testing.assert_array_equal(ea, en)
    np.testing.assert_allclose(ja[0], jn[0], atol=1e-8)

    anchor3 = rng.normal(size=3) * 5
    x3 = arbor_slam.SE3.exp(rng.normal(size=6))
    (_, ja), (_, jn) = (arbor_slam.CustomFactor3(0, range_error(anchor3, 1.0), np.eye(1),
                                            jacobian=j).linearize([x3])
                        for j in (range_jacobian(anchor3), None))
    np.testing.assert_allclose(ja[0], jn[0], atol=1e-8)

    p = rng.normal(size=2)
    xi, xj = arbor_slam.SE2(*rng.normal(size=3)), arbor_slam.SE2(*rng.normal(size=3))
    (ea, ja), (en, jn) = (arbor_slam.CustomFactor2([0, 1], relative_position_error(p), np.eye(2),
                                              jacobian=j).linearize([xi, xj])
                          for j in (relative_position_jacobian, None))
    np.testing.assert_array_equal(ea, en)
    for a, n in zip(ja, jn):
        np.testing.assert_allclose(a, n, atol=1e-8)


def odometry_and_ranges(with_jacobian):
    """A 2D square walk of 12 poses with noisy odometry and ranges to two anchors."""
    rng = np.random.default_rng(5)
    truth = [arbor_slam.SE2(0, 0, 0)]
    for k in range(1, 12):
        truth.append(truth[-1] * arbor_slam.SE2(1.0, 0.0, np.pi / 2 if k % 3 == 0 else 0.0))
    graph = arbor_slam.Graph2()
    for k, x in enumerate(truth):
        graph.add_pose(k, x)
    omega = np.diag([100.0, 100.0, 400.0])
    for k in range(11):
        z = truth[k].between(truth[k + 1]) * arbor_slam.SE2(*(rng.normal(size=3) * 0.05))
        graph.add_edge(k, k + 1, z, omega)
    anchors = [np.array([5.0, -1.0]), np.array([-2.0, 3.0])]
    factors = []
    for k in range(0, 12, 2):
        a = anchors[k // 2 % 2]
        rho = np.linalg.norm(truth[k].translation() - a) + rng.normal() * 0.05
        f = arbor_slam.CustomFactor2(k, range_error(a, rho), np.array([[25.0]]),
                                jacobian=range_jacobian(a) if with_jacobian else None,
                                name="range")
        graph.add_factor(f)
        factors.append(f)
    return graph, factors


@pytest.mark.parametrize("with_jacobian", [False, True])
def test_online_equals_batch_with_odometry_and_ranges(with_jacobian):
    graph, _ = odometry_and_ranges(with_jacobian)
    batch = arbor_slam.solve(graph, solver="gn", max_iterations=50, relative_tolerance=1e-14)
    for feed in ("add_graph", "one_by_one"):
        smoother = arbor_slam.OnlineSmoother2()
        if feed == "add_graph":
            smoother.add_graph(graph)
        else:
            g2, factors = odometry_and_ranges(with_jacobian)
            for (a, b), z, omega in zip(g2.edges, g2.measurements, g2.information):
                smoother.add_edge(int(a), int(b), z, omega)
                smoother.update()
                for f in factors:
                    if f.keys[0] == b or (b == 1 and f.keys[0] == 0):
                        smoother.add_factor(f)
                        smoother.update()
        # Ranges leave residuals (GN converges linearly here, as the batch's 11 iterations):
        # finalize() again until F stops moving.
        previous = np.inf
        for _ in range(20):
            smoother.finalize()
            if abs(previous - smoother.objective()) <= 1e-14 * smoother.objective():
                break
            previous = smoother.objective()
        ids, poses = smoother.estimates()
        assert np.array_equal(ids, batch.ids)
        assert smoother.objective() == pytest.approx(batch.F_final, rel=1e-12)
        for p, q in zip(poses, batch.estimate):
            assert arbor_slam.SE2.from_array(p).isclose(arbor_slam.SE2.from_array(q), atol=1e-6)


class Boom(Exception):
    pass


def test_an_exception_in_error_is_raised_by_the_solve_and_the_update():
    state = {"fail": False}

    def error(x):
        if state["fail"]:
            raise Boom("no range today")
        return np.array([np.linalg.norm(x.translation()) - 3.0])

    graph = arbor_slam.Graph2()
    graph.add_pose(0, arbor_slam.SE2(2, 0, 0))
    graph.add_pose_prior(0, arbor_slam.SE2(2, 0, 0), np.eye(3))
    graph.add_factor(arbor_slam.CustomFactor2(0, error, np.eye(1)))
    state["fail"] = True
    with pytest.raises(Boom, match="no range today"):
        arbor_slam.solve(graph)
    with pytest.raises(Boom, match="no range today"):
        graph.objective(graph.poses)

    # add_factor evaluates the factor before the smoother holds it: nothing changes.
    smoother = arbor_slam.OnlineSmoother2()
    smoother.add_pose_prior(0, [2, 0, 0], np.eye(3))
    with pytest.raises(Boom, match="no range today"):
        smoother.add_factor(arbor_slam.CustomFactor2(0, error, np.eye(1)))
    state["fail"] = False
    smoother.add_factor(arbor_slam.CustomFactor2(0, error, np.eye(1)))
    # From the update's worker threads.
    state["fail"] = True
    with pytest.raises(Boom, match="no range today"):
        smoother.update()
    # The update applied nothing and took the factor out (docs/python.md, "When an update
    # raises"; tests/python/test_update_failure.py); here a fresh smoother goes on.
    state["fail"] = False
    smoother = arbor_slam.OnlineSmoother2()
    smoother.add_pose_prior(0, [2, 0, 0], np.eye(3))
    smoother.add_factor(arbor_slam.CustomFactor2(0, error, np.eye(1)))
    smoother.update()
    state["fail"] = True
    with pytest.raises(Boom, match="no range today"):
        smoother.finalize()

    def not_numbers(x):
        return "far"

    graph = arbor_slam.Graph2()
    graph.add_pose(0, arbor_slam.SE2(2, 0, 0))
    graph.add_factor(arbor_slam.CustomFactor2(0, not_numbers, np.eye(1)))
    with pytest.raises(TypeError, match="error()"):
        arbor_slam.solve(graph)


def test_bad_input_is_a_value_error():
    error = range_error([0, 0], 1.0)
    with pytest.raises(ValueError, match="not symmetric|symmetric"):
        arbor_slam.CustomFactor2(0, error, np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(ValueError, match="positive"):
        arbor_slam.CustomFactor2(0, error, np.array([[-1.0]]))
    with pytest.raises(ValueError, match="4 rows, outside 1..3"):
        arbor_slam.CustomFactor2(0, error, np.eye(4))
    with pytest.raises(ValueError, match="NaN"):
        arbor_slam.CustomFactor2(0, error, np.array([[np.nan]]))
    with pytest.raises(ValueError, match="1 or 2 pose ids"):
        arbor_slam.CustomFactor2([0, 1, 2], error, np.eye(1))
    with pytest.raises(ValueError, match="step"):
        arbor_slam.CustomFactor2(0, error, np.eye(1), step=0.0)

    graph = arbor_slam.Graph2()
    graph.add_pose(0, arbor_slam.SE2(2, 0, 0))
    with pytest.raises(ValueError, match="unknown pose id 5"):
        graph.add_factor(arbor_slam.CustomFactor2(5, error, np.eye(1)))
    smoother = arbor_slam.OnlineSmoother2()
    smoother.add_pose_prior(0, [2, 0, 0], np.eye(3))
    with pytest.raises(ValueError, match="unknown pose id 5"):
        smoother.add_factor(arbor_slam.CustomFactor2(5, error, np.eye(1)))

    # Wrong rows: error() returns 2 numbers for a 1×1 Ω; a jacobian of the wrong shape.
    wrong = arbor_slam.CustomFactor2(0, lambda x: np.zeros(2), np.eye(1))
    with pytest.raises(ValueError, match="expected 1 entries, got shape \\(2\\)"):
        wrong.linearize([arbor_slam.SE2()])
    graph.add_factor(wrong)
    with pytest.raises(ValueError, match="expected 1 entries"):
        arbor_slam.solve(graph)
    bad_j = arbor_slam.CustomFactor2(0, error, np.eye(1), jacobian=lambda x: [np.zeros((1, 2))])
    with pytest.raises(ValueError, match="jacobian\\(\\) matrix 0: expected 1x3"):
        bad_j.linearize([arbor_slam.SE2(1, 1, 0)])
    with pytest.raises(ValueError, match="expected 1 poses"):
        bad_j.linearize([arbor_slam.SE2(), arbor_slam.SE2()])


def test_write_pickle_and_rtr_refuse_a_graph_with_custom_factors(tmp_path):
    graph, _ = odometry_and_ranges(True)
    with pytest.raises(ValueError, match="custom factor"):
        graph.write(str(tmp_path / "out.g2o"))
    with pytest.raises(ValueError, match="custom factor.*not pickled"):
        pickle.dumps(graph)
    with pytest.raises(ValueError, match="certifiable solver takes relative-pose edges only: 6 custom factor"):
        arbor_slam.solve(graph, solver="rtr")
    graph.write(str(tmp_path / "out.tum"))  # poses only
    assert len(open(tmp_path / "out.tum").read().splitlines()) == graph.num_poses


def test_poses_added_after_a_factor_keep_its_keys():
    graph = arbor_slam.Graph2()
    graph.add_pose(10, arbor_slam.SE2(2, 0, 0))
    graph.add_pose_prior(10, arbor_slam.SE2(2, 0, 0), np.eye(3))
    graph.add_factor(arbor_slam.CustomFactor2(10, range_error([0, 0], 3.0), np.eye(1)))
    graph.add_pose(5, arbor_slam.SE2(0, 0, 0))  # before 10: shifts its dense index
    graph.add_edge(5, 10, arbor_slam.SE2(2.5, 0, 0), np.eye(3) * 1e-6)
    result = arbor_slam.solve(graph)
    np.testing.assert_allclose(result.estimate[1], [2.5, 0.0, 0.0], atol=1e-5)


def test_the_smoother_threads_call_python_and_raise_through_update():
    # 700 factors linearised at once are shared by the update's worker threads (chunks of 8,
    # LinearizedFactors::linearizeAllOrNone): error() runs on them under the GIL.
    main, seen = threading.get_ident(), set()
    state = {"fail_off_main": False}
    anchor = np.array([3.0, 4.0])

    def error(x):
        seen.add(threading.get_ident())
        if state["fail_off_main"] and threading.get_ident() != main:
            raise Boom("from a worker")
        return np.array([np.linalg.norm(x.translation() - anchor) - 5.0])

    graph = arbor_slam.Graph2()
    for k in range(700):
        graph.add_pose(k, arbor_slam.SE2(0.01 * k, 0, 0))
    for k in range(699):
        graph.add_edge(k, k + 1, arbor_slam.SE2(0.01, 0, 0), np.eye(3) * 100)
    for k in range(700):
        graph.add_factor(arbor_slam.CustomFactor2(k, error, np.eye(1)))
    smoother = arbor_slam.OnlineSmoother2(threads=2)
    smoother.add_graph(graph)
    smoother.update()
    assert len(seen) == 2
    batch = arbor_slam.solve(graph, solver="gn", relative_tolerance=1e-14)
    for _ in range(10):
        smoother.finalize()
    assert smoother.objective() == pytest.approx(batch.F_final, rel=1e-6)

    state["fail_off_main"] = True
    smoother = arbor_slam.OnlineSmoother2(threads=2)
    smoother.add_graph(graph)
    with pytest.raises(Boom, match="from a worker"):
        smoother.update()
