# arbor_slam.solve with every solver and initialisation, against `arbor batch --json`.
import os

import numpy as np
import pytest

import arbor_slam


@pytest.mark.parametrize("solver", ["lm", "gn", "dogleg", "rtr"])
@pytest.mark.parametrize("name", ["manhattan_2d.g2o", "sphere_3d.g2o"])
def test_solvers_match_the_cli(solver, name, data_dir, arbor_cli):
    path = os.path.join(data_dir, name)
    graph = arbor_slam.read(path)
    result = arbor_slam.solve(graph, solver=solver)
    expected = arbor_cli("batch", path, "--solver", solver)
    assert result.solver == solver
    assert result.F_final == pytest.approx(expected["F_final"], rel=1e-9)
    assert result.iterations == expected["iterations"]
    assert result.termination == expected["termination"]
    assert result.estimate.shape == (graph.num_poses, 3 if graph.dimension == 2 else 7)
    assert np.array_equal(result.ids, graph.ids)
    assert graph.objective(result.estimate) == pytest.approx(result.F_final, rel=1e-9)
    if solver == "rtr":
        assert result.certified is True and result.rank >= 3
        assert result.init == "chordal"
    else:
        assert result.certified is None


@pytest.mark.parametrize("init", ["odometry", "spanning-tree", "chordal", "file"])
def test_initialisations(init, data_dir, arbor_cli):
    path = os.path.join(data_dir, "manhattan_2d.g2o")
    result = arbor_slam.solve(arbor_slam.read(path), solver="lm", init=init)
    expected = arbor_cli("batch", path, "--solver", "lm", "--init", init)
    assert result.init == expected["init"] == init
    assert result.F_initial == pytest.approx(expected["F_initial"], rel=1e-9)
    assert result.F_final == pytest.approx(expected["F_final"], rel=1e-9)


def test_robust_batch_matches_the_cli(data_dir, arbor_cli):
    path = os.path.join(data_dir, "manhattan_2d_group_0.1.g2o")
    result = arbor_slam.solve(arbor_slam.read(path), robust=arbor_slam.RobustOptions(kernel="tls", threshold=2.0))
    # solve() runs GNC from its init, as `arbor batch --robust --init file` (the CLI's default
    # start with --robust is the robust online replay's).
    expected = arbor_cli(
        "batch", path, "--robust", "--init", "file", "--kernel", "tls", "--inlier-threshold", "2"
    )
    assert result.robust
    assert len(result.rejected) == expected["rejected"] > 0
    assert result.F_final == pytest.approx(expected["F_final"], rel=1e-9)
    assert result.F_inliers == pytest.approx(expected["F_inliers"], rel=1e-9)
