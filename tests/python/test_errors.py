# Bad input raises a Python exception carrying the C++ message (the one `arbor` prints).
import os
import subprocess

import numpy as np
import pytest

import arbor_slam


def test_malformed_file(tmp_path, arbor_cli):
    path = tmp_path / "bad.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 nan 0 1\n")
    with pytest.raises(arbor_slam.FileError) as error:
        arbor_slam.read(str(path))
    message = str(error.value)
    assert message.startswith(f"{path}:3: ")
    assert isinstance(error.value, RuntimeError)
    cli = subprocess.run([arbor_cli.path, "batch", str(path)], capture_output=True, text=True)
    assert cli.returncode != 0
    assert message in cli.stderr


def test_missing_file(tmp_path):
    with pytest.raises(arbor_slam.FileError, match="cannot open"):
        arbor_slam.read(str(tmp_path / "none.g2o"))


def test_bad_options(data_dir):
    graph = arbor_slam.read(os.path.join(data_dir, "manhattan_2d.g2o"))
    with pytest.raises(ValueError, match="solver must be lm, gn, dogleg or rtr, not 'foo'"):
        arbor_slam.solve(graph, solver="foo")
    with pytest.raises(ValueError, match="'sideways'"):
        arbor_slam.solve(graph, init="sideways")
    with pytest.raises(ValueError, match="information must be refuse, repair or isotropic"):
        arbor_slam.read(os.path.join(data_dir, "manhattan_2d.g2o"), information="maybe")
    with pytest.raises(ValueError, match="kernel"):
        arbor_slam.RobustOptions(kernel="none")
    with pytest.raises(ValueError, match="estimate_scale"):
        arbor_slam.OnlineSmoother2(robust=arbor_slam.RobustOptions(estimate_scale=True))
    # The online keywords: a bad name, type or value is refused naming it, and solve() refuses
    # them all (they are the online smoother's).
    with pytest.raises(ValueError, match="noise_scale must be estimated or given, not 'sometimes'"):
        arbor_slam.RobustOptions(noise_scale="sometimes")
    with pytest.raises(ValueError, match="rules_off must be warm-up, .* or end-word, not 'end'"):
        arbor_slam.RobustOptions(rules_off="end")
    with pytest.raises(TypeError, match="unexpected keyword 'scale_start'"):
        arbor_slam.RobustOptions(scale_start="median")
    with pytest.raises(TypeError, match="unexpected keyword 'noise'"):
        arbor_slam.RobustOptions(noise="given")
    with pytest.raises(TypeError, match="finalize_rounds must be an int, not float"):
        arbor_slam.RobustOptions(finalize_rounds=2.5)
    with pytest.raises(ValueError, match="corroboration_window"):
        arbor_slam.RobustOptions(corroboration_window=-4)
    with pytest.raises(ValueError, match="online options"):
        arbor_slam.solve(graph, robust=arbor_slam.RobustOptions(noise_scale="given"))
    arbor_slam.solve(graph, robust=arbor_slam.RobustOptions(noise_scale="estimated"))  # the default: taken


def test_bad_edges_and_ids():
    s = arbor_slam.OnlineSmoother2()
    with pytest.raises(ValueError, match="bad information: not positive definite"):
        s.add_edge(0, 1, [1, 0, 0], -np.eye(3))
    with pytest.raises(ValueError, match="expected 3 numbers"):
        s.add_edge(0, 1, [1, 0], np.eye(3))
    with pytest.raises(ValueError, match="expected a 3x3 matrix"):
        s.add_edge(0, 1, [1, 0, 0], np.eye(6))
    assert s.add_edge(0, 1, [1, 0, 0], np.eye(3)) == "accepted"
    assert s.add_edge(0, 1, [1, 0, 0], np.eye(3)) == "duplicate"
    s.update()
    with pytest.raises(ValueError, match="7"):
        s.estimate(7)
    with pytest.raises(ValueError, match="7"):
        s.marginal_covariance(7)
    with pytest.raises(ValueError):
        s.disable_edge(0, 1)  # a bridge: refused with the reason
    s3 = arbor_slam.OnlineSmoother3()
    with pytest.raises(ValueError, match="quaternion norm"):
        s3.add_edge(0, 1, [1, 0, 0, 0, 0, 0, 2], np.eye(6))


def test_smoother_keywords_come_from_the_table():
    # Each keyword is a row of the smoother table, checked by the row's rule and named.
    with pytest.raises(ValueError, match="OnlineSmoother: threads must be >= 0, not '-1'"):
        arbor_slam.OnlineSmoother2(threads=-1)
    with pytest.raises(ValueError, match="relinearize_skip must be >= 1, not '0'"):
        arbor_slam.OnlineSmoother3(relinearize_skip=0)
    with pytest.raises(TypeError, match="unexpected keyword 'thread'"):
        arbor_slam.OnlineSmoother2(thread=2)
    with pytest.raises(TypeError, match="relinearize_skip must be an int, not float"):
        arbor_slam.OnlineSmoother2(relinearize_skip=2.5)
    doc = arbor_slam.OnlineSmoother2.__init__.__doc__
    for keyword in ("threads (an int, default 0)", "wildfire_threshold (a number, default 0.001)",
                    "dogleg (a bool, default False)", "solve_budget_mb (a number, default 0)"):
        assert keyword in doc, keyword
    arbor_slam.OnlineSmoother2(threads=2, wildfire_threshold=0.01, dogleg=True,
                          relinearize_threshold_translation=0.2)
