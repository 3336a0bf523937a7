# A data/ file replayed through arbor_slam.OnlineSmoother2/3 reaches the F `arbor replay` prints.
import os

import numpy as np
import pytest

import arbor_slam
from replay import replay


@pytest.mark.parametrize("name", ["manhattan_2d.g2o", "sphere_3d.g2o"])
def test_replay_matches_the_cli(name, data_dir, arbor_cli):
    path = os.path.join(data_dir, name)
    graph = arbor_slam.read(path)
    smoother, F = replay(graph)
    expected = arbor_cli("replay", path)
    assert F == pytest.approx(expected["F_final"], rel=1e-9)
    assert smoother.objective() == pytest.approx(F, rel=1e-9)
    stats = smoother.stats()
    assert stats.poses == graph.num_poses == expected["nodes"]
    assert stats.edges_accepted == graph.num_edges
    assert stats.updates == graph.num_edges + 1  # one per edge, then finalize


def test_estimate_rows(data_dir):
    graph = arbor_slam.read(os.path.join(data_dir, "sphere_3d.g2o"))
    smoother, _ = replay(graph)
    ids, poses = smoother.estimates()
    assert poses.shape == (graph.num_poses, 7)
    assert np.array_equal(ids, np.sort(ids))
    assert np.allclose(np.linalg.norm(poses[:, 3:], axis=1), 1.0)
    assert np.array_equal(smoother.estimate(int(ids[5])), poses[5])
    # The anchor (the first pose seen) stays at the identity.
    assert np.allclose(smoother.estimate(int(graph.edges[0, 0])), [0, 0, 0, 0, 0, 0, 1])


def test_robust_replay_rejects_false_closures(data_dir):
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d_group_0.1.g2o"))
    smoother, _ = replay(graph, robust=arbor_slam.RobustOptions(kernel="tls", threshold=2.0))
    closures = smoother.closures()
    assert closures
    statuses = {c.status for c in closures}
    assert statuses <= {"inlier", "outlier", "trusted", "excluded"}
    assert smoother.stats().closures_outlier == sum(c.status == "outlier" for c in closures)


def test_robust_stats_match_the_cli(data_dir, arbor_cli):
    """The robust counters of stats() are those `arbor replay --robust --json` reports."""
    path = os.path.join(data_dir, "manhattan_2d_group_0.1.g2o")
    smoother, _ = replay(arbor_slam.read(path), robust=arbor_slam.RobustOptions(kernel="tls", threshold=2.0))
    expected = arbor_cli("replay", path, "--robust", "--inlier-threshold", "2")["robust"]
    stats = smoother.stats()
    for key in ["closures_inlier", "closures_outlier", "closures_unconfirmed",
                "graduation_steps",
                "graduation_updates", "warm_up_relinearizations", "noise_samples",
                "noise_scale_estimated"]:
        assert getattr(stats, key) == expected[key], key
    assert stats.graduation_steps > 0
    assert stats.noise_scale == pytest.approx(expected["noise_scale"], rel=1e-12)
    assert stats.closure_threshold == pytest.approx(expected["threshold_in_use"], rel=1e-12)
    assert stats.closure_threshold_at_end == pytest.approx(expected["threshold_at_end"],
                                                              rel=1e-12)


def test_online_robust_options_match_the_cli(data_dir, arbor_cli):
    """RobustOptions' online keywords reach the smoother as `arbor replay`'s flags of the same
    names do: Ω at its word (noise_scale="given"), no corroboration, two rules off."""
    path = os.path.join(data_dir, "manhattan_2d_group_0.1.g2o")
    options = arbor_slam.RobustOptions(noise_scale="given", corroboration_window=0,
                                  rules_off="final-confirm,scale-start")
    assert (options.noise_scale, options.corroboration_window) == ("given", 0)
    assert options.rules_off == "scale-start,final-confirm"
    assert arbor_slam.RobustOptions().rules_off == ""
    assert arbor_slam.RobustOptions().noise_scale == "estimated"
    smoother, F = replay(arbor_slam.read(path), robust=options)
    expected = arbor_cli("replay", path, "--robust", "--noise-scale", "given",
                         "--corroboration-window", "0", "--rules-off", "final-confirm,scale-start")
    assert F == pytest.approx(expected["F_final"], rel=1e-9)
    stats = smoother.stats()
    for key in ["closures_inlier", "closures_outlier", "noise_scale_estimated"]:
        assert getattr(stats, key) == expected["robust"][key], key
    # Ω at its word: no scale is estimated, where the default estimates one.
    assert not stats.noise_scale_estimated and stats.noise_scale == 1.0
    default, _ = replay(arbor_slam.read(path), robust=arbor_slam.RobustOptions())
    assert default.stats().noise_scale_estimated


@pytest.mark.parametrize("name", ["manhattan_2d.g2o", "sphere_3d.g2o"])
def test_replay_covariances_and_tum_output(name, data_dir, arbor_cli, tmp_path):
    """`arbor replay --covariances OUT -o OUT --format tum` writes what the module computes."""
    path = os.path.join(data_dir, name)
    covariances, tum = tmp_path / "cov.txt", tmp_path / "estimate.tum"
    report = arbor_cli("replay", path, "--covariances", str(covariances), "-o", str(tum),
                       "--format", "tum")
    assert report["covariances"] == str(covariances)
    assert report["output"] == {"path": str(tum), "format": "tum"}
    graph = arbor_slam.read(path)
    smoother, _ = replay(graph)
    k = 3 if graph.dimension == 2 else 6
    upper = np.triu_indices(k)
    lines = covariances.read_text().splitlines()
    assert len(lines) == graph.num_poses
    ids = []
    for line in lines:
        fields = line.split()
        ids.append(int(fields[0]))
        # The module's measurements went through numpy rows ([x y θ], quaternions), so the two
        # replays agree to rounding, not bit for bit.
        expected = smoother.marginal_covariance(ids[-1])[upper]
        got = np.array([float(x) for x in fields[1:]])
        assert np.abs(got - expected).max() <= 1e-8 * max(np.abs(expected).max(), 1e-300), ids[-1]
    assert ids == sorted(ids)
    rows = np.loadtxt(tum)
    estimate_ids, poses = smoother.estimates()
    assert np.array_equal(rows[:, 0], estimate_ids)
    if graph.dimension == 3:
        assert np.allclose(rows[:, 1:], poses, rtol=0, atol=1e-9)
    else:
        assert np.allclose(rows[:, 1:3], poses[:, :2], rtol=0, atol=1e-9)


def test_solve_budget_defers_and_solve_deferred_catches_up(data_dir):
    """solve_budget_mb bounds each update's back-substitution; solve_deferred() solves the
    backlog, and the final pass ends where the unbounded replay does."""
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d.g2o"))
    _, F = replay(graph)
    smoother = arbor_slam.OnlineSmoother2(solve_budget_mb=0.0002)
    index = {int(i): k for k, i in enumerate(graph.ids)}
    edges = graph.edges
    order = sorted(range(len(edges)),
                   key=lambda e: max(index[int(edges[e, 0])], index[int(edges[e, 1])]))
    deferring = 0
    for e in order:
        smoother.add_edge(int(edges[e, 0]), int(edges[e, 1]), graph.measurements[e],
                          graph.information[e])
        stats = smoother.update()
        assert stats.cliques_deferred == smoother.cliques_deferred
        deferring += stats.cliques_deferred > 0
    assert deferring > len(order) // 4
    assert smoother.cliques_deferred > 0
    drained = smoother.solve_deferred()
    assert drained.cliques_solved > 0
    assert drained.cliques_deferred == smoother.cliques_deferred == 0
    smoother.finalize()
    assert smoother.objective() == pytest.approx(F, rel=1e-7)


def test_solve_budget_refuses_what_needs_every_delta():
    with pytest.raises(ValueError, match="solve_budget_mb"):
        arbor_slam.OnlineSmoother2(solve_budget_mb=-1)
    with pytest.raises(ValueError, match="solve_budget_mb"):
        arbor_slam.OnlineSmoother2(solve_budget_mb=1, dogleg=True)
    with pytest.raises(ValueError, match="solve_budget_mb"):
        arbor_slam.OnlineSmoother3(solve_budget_mb=1, robust=arbor_slam.RobustOptions(kernel="tls"))


@pytest.mark.parametrize("solver", ["lm", "rtr"])
def test_refine_on_request_matches_the_replays_final_batch(solver, data_dir, arbor_cli):
    """refine() after a robust replay is `arbor replay --robust --batch SOLVER`'s final run: GNC
    from the smoother's classification (its rejected closures held out), for rtr certified."""
    path = os.path.join(data_dir, "manhattan_2d_group_0.1.g2o")
    graph = arbor_slam.read(path)
    smoother, _ = replay(graph, robust=arbor_slam.RobustOptions(kernel="tls", threshold=2.0))
    run = smoother.refine(solver=solver)
    expected = arbor_cli("replay", path, "--robust", "--inlier-threshold", "2",
                         "--batch", solver)["batches"][-1]
    assert expected["final"]
    for key in ["poses", "edges", "judged", "rejected", "winner"]:
        assert getattr(run, key) == expected[key], key
    for key in ["F_incremental", "F_batch", "inlier_threshold"]:
        assert getattr(run, key) == pytest.approx(expected[key], rel=1e-9), key
    assert run.robust
    assert run.rejected >= smoother.stats().closures_outlier  # none taken back here
    assert run.estimate.shape == (graph.num_poses, 3)
    assert sorted(run.ids) == sorted(graph.ids)
    if solver == "rtr":
        assert run.certified is True and run.rank >= 2
    else:
        assert run.certified is None
    assert not run.reseeded  # not asked


def test_refine_reseeds_only_when_the_cost_falls(data_dir):
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d.g2o"))
    smoother = arbor_slam.OnlineSmoother2()
    index = {int(i): k for k, i in enumerate(graph.ids)}
    # Half the file, no finalize: the incremental estimate is not the optimum yet.
    order = sorted(range(graph.num_edges),
                   key=lambda e: max(index[int(graph.edges[e, 0])], index[int(graph.edges[e, 1])]))
    for e in order[: graph.num_edges // 2]:
        smoother.add_edge(int(graph.edges[e, 0]), int(graph.edges[e, 1]), graph.measurements[e],
                          graph.information[e])
        smoother.update()
    before = smoother.objective()
    run = smoother.refine(solver="lm", reseed=True)
    assert not run.robust
    assert run.F_incremental == pytest.approx(before, rel=1e-9)
    if run.reseeded:
        assert smoother.objective() < before
    else:
        assert smoother.objective() == before


def test_refine_refuses_what_it_cannot_run():
    smoother = arbor_slam.OnlineSmoother2()
    with pytest.raises(ValueError, match="nothing to solve"):
        smoother.refine()
    smoother.add_edge(0, 1, [1, 0, 0], np.eye(3))
    smoother.update()
    with pytest.raises(ValueError, match="lm"):
        smoother.refine(solver="gn")  # not a refining solver


def test_refine_starts_from_the_classification_only_once_finalized(data_dir):
    """Before finalize() the robust batch is a correction at the c² in use; after it, GNC runs at
    the bound the smoother keeps a settled inlier within (recheck_margin, 2, times that c²)."""
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d_group_0.1.g2o"))
    smoother = arbor_slam.OnlineSmoother2(robust=arbor_slam.RobustOptions(kernel="tls", threshold=2.0))
    index = {int(i): k for k, i in enumerate(graph.ids)}
    order = sorted(range(graph.num_edges),
                   key=lambda e: max(index[int(graph.edges[e, 0])], index[int(graph.edges[e, 1])]))
    for e in order:
        smoother.add_edge(int(graph.edges[e, 0]), int(graph.edges[e, 1]), graph.measurements[e],
                          graph.information[e])
        smoother.update()
    before = smoother.refine()
    assert before.inlier_threshold == pytest.approx(smoother.stats().closure_threshold)
    smoother.finalize()
    after = smoother.refine()
    assert after.inlier_threshold == pytest.approx(2 * smoother.stats().closure_threshold)
    assert after.rejected >= smoother.stats().closures_outlier
