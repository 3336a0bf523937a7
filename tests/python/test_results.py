# The typed results (python/record.h, docs/python.md "Results"): attributes, to_dict() in the
# old dict form, ==, repr, pickle; and RobustOptions' pickle, == and repr.
import copy
import os
import pickle

import numpy as np
import pytest

import arbor_slam
from replay import replay


@pytest.fixture(scope="module")
def manhattan(data_dir):
    return arbor_slam.read(os.path.join(data_dir, "manhattan_2d.g2o"))


@pytest.fixture(scope="module")
def robust_smoother(data_dir):
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d_group_0.1.g2o"))
    smoother, _ = replay(graph, robust=arbor_slam.RobustOptions(kernel="tls", threshold=2.0))
    return smoother


def test_solve_result_fields_dict_repr_and_pickle(manhattan):
    result = arbor_slam.solve(manhattan, solver="gn")
    d = result.to_dict()
    assert list(d)[:4] == ["solver", "init", "F_initial", "F_final"]
    assert d["F_final"] == result.F_final and d["solver"] == "gn" and d["rank"] is None
    assert np.array_equal(d["estimate"], result.estimate) and d["ids"].dtype == np.int64
    d["estimate"][0, 0] += 1  # to_dict copies
    assert not np.array_equal(d["estimate"], result.estimate)
    with pytest.raises(ValueError):
        result.estimate[0, 0] = 1.0  # the attribute is a read-only view
    text = repr(result)
    assert text.startswith("SolveResult(solver='gn', init='file', F_initial=")
    assert f"F_final={result.F_final!r}" in text and "estimate=<array 1500x3>" in text
    again = pickle.loads(pickle.dumps(result))
    assert again == result and again is not result and copy.deepcopy(result) == result
    assert np.array_equal(again.estimate, result.estimate) and again.rejected == result.rejected
    assert arbor_slam.solve(manhattan, solver="lm") != result
    assert result != result.to_dict() and (result == 1) is False
    with pytest.raises(TypeError):
        hash(result)  # mutable-looking value type: == without a hash


def test_robust_solve_result_pickles(data_dir):
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d_group_0.1.g2o"))
    result = arbor_slam.solve(graph, robust=arbor_slam.RobustOptions(threshold=2.0))
    assert result.robust and result.rejected and isinstance(result.rejected[0], tuple)
    assert pickle.loads(pickle.dumps(result)) == result


def test_update_and_online_stats(manhattan):
    smoother = arbor_slam.OnlineSmoother2()
    added = smoother.add_graph(manhattan)
    assert (added.accepted, added.duplicate) == (manhattan.num_edges, 0)
    assert repr(added) == f"AddGraphResult(accepted={manhattan.num_edges}, duplicate=0)"
    update = smoother.update()
    assert isinstance(update, arbor_slam.UpdateStats) and update.new_factors == manhattan.num_edges
    stats = smoother.stats()
    assert stats.last_update == update and stats.poses == manhattan.num_poses
    d = stats.to_dict()
    assert d["last_update"] == update.to_dict() and d["updates"] == 1
    assert "last_update=UpdateStats(new_factors=" in repr(stats)
    for value in (added, update, stats):
        again = pickle.loads(pickle.dumps(value))
        assert again == value and type(again) is type(value)
    smoother.finalize()
    assert smoother.stats() != stats and smoother.stats().last_update != update


def test_closures_and_refine(robust_smoother):
    closures = robust_smoother.closures()
    assert closures and all(isinstance(c, arbor_slam.Closure) for c in closures)
    assert pickle.loads(pickle.dumps(closures)) == closures
    assert set(closures[0].to_dict()) == {"from_id", "to_id", "weight", "residual", "status",
                                          "graduating"}
    run = robust_smoother.refine()
    assert isinstance(run, arbor_slam.RefineResult) and run.robust and run.certified is None
    assert pickle.loads(pickle.dumps(run)) == run
    assert run.to_dict()["estimate"].shape == (robust_smoother.num_poses, 3)


def test_nan_equals_nan_and_bad_states(manhattan):
    result = arbor_slam.solve(manhattan, solver="gn")
    state = result.to_dict()
    state["F_final"] = float("nan")
    nan = arbor_slam.SolveResult.__new__(arbor_slam.SolveResult)
    nan.__setstate__(state)
    assert nan == pickle.loads(pickle.dumps(nan)) and nan != result
    missing = dict(state)
    del missing["estimate"]
    with pytest.raises(ValueError, match="SolveResult state: no field 'estimate'"):
        arbor_slam.SolveResult.__new__(arbor_slam.SolveResult).__setstate__(missing)
    with pytest.raises(ValueError, match="unknown field 'extra'"):
        arbor_slam.SolveResult.__new__(arbor_slam.SolveResult).__setstate__(dict(state, extra=1))
    with pytest.raises(TypeError, match="field 'iterations' has the wrong type"):
        arbor_slam.SolveResult.__new__(arbor_slam.SolveResult).__setstate__(dict(state, iterations="x"))


def test_robust_options_pickle_compare_and_repr():
    options = arbor_slam.RobustOptions(kernel="cauchy", threshold=3.0, noise_scale="given",
                                  corroboration_window=0)
    assert pickle.loads(pickle.dumps(options)) == options
    assert repr(options) == ("RobustOptions(kernel='cauchy', threshold=3.0, confidence=0.99, "
                             "estimate_scale=False, noise_scale='given', corroboration_window=0)")
    assert eval("arbor_slam." + repr(options)) == options
    assert arbor_slam.RobustOptions(**options.to_dict()) == options
    assert options != arbor_slam.RobustOptions() and arbor_slam.RobustOptions() == arbor_slam.RobustOptions()
    assert options.to_dict()["rules_off"] == arbor_slam.RobustOptions().rules_off == ""
    with pytest.raises(TypeError, match="unexpected keyword 'bogus'"):
        arbor_slam.RobustOptions.__new__(arbor_slam.RobustOptions).__setstate__({"bogus": 1})
