"""Graph2 / Graph3 built in memory: equal to the same graph read from its file (same arrays,
same batch F, same online F), written and read back, pickled, and refused with ValueError
naming the value on bad input."""
import os
import pickle

import numpy as np
import pytest

import arbor_slam

FILES = ["manhattan_2d.g2o", "sphere_3d.g2o"]


def rebuilt(graph, order=None):
    """The graph `graph` (read from a file) built again in memory, poses in `order`."""
    pose_type = arbor_slam.SE2 if graph.dimension == 2 else arbor_slam.SE3
    out = (arbor_slam.Graph2 if graph.dimension == 2 else arbor_slam.Graph3)()
    ids, poses = graph.ids, graph.poses
    for k in (range(len(ids)) if order is None else order):
        out.add_pose(int(ids[k]), pose_type.from_array(poses[k]))
    for (a, b), z, omega in zip(graph.edges, graph.measurements, graph.information):
        out.add_edge(int(a), int(b), pose_type.from_array(z), omega)
    return out


def assert_same(a, b):
    assert a.dimension == b.dimension
    assert np.array_equal(a.ids, b.ids)
    assert np.array_equal(a.edges, b.edges)
    np.testing.assert_allclose(a.poses, b.poses, rtol=0, atol=1e-14)
    np.testing.assert_allclose(a.measurements, b.measurements, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(a.information, b.information)
    assert np.array_equal(a.fixed, b.fixed)
    assert a.num_priors == b.num_priors


@pytest.mark.parametrize("name", FILES)
def test_in_memory_equals_the_file(name, data_dir):
    read = arbor_slam.read(os.path.join(data_dir, name))
    shuffled = np.random.default_rng(3).permutation(read.num_poses)
    for built in (rebuilt(read), rebuilt(read, shuffled)):
        assert_same(built, read)
        assert built.has_initial_estimate and built.path == ""
        assert arbor_slam.solve(built).F_final == pytest.approx(arbor_slam.solve(read).F_final, rel=1e-12)
        assert built.objective(read.poses) == pytest.approx(read.objective(read.poses), rel=1e-12)


@pytest.mark.parametrize("name", FILES)
def test_online_smoother_takes_a_graph(name, data_dir):
    read = arbor_slam.read(os.path.join(data_dir, name))
    results = []
    for graph in (read, rebuilt(read)):
        smoother = (arbor_slam.OnlineSmoother2 if graph.dimension == 2 else arbor_slam.OnlineSmoother3)()
        counts = smoother.add_graph(graph)
        assert (counts.accepted, counts.duplicate) == (graph.num_edges, 0)
        smoother.update()
        smoother.finalize()
        ids, poses = smoother.estimates()
        assert np.array_equal(ids, graph.ids)
        results.append(graph.objective(poses))
    # The rebuilt poses went through their rows (an SE2 angle to an ulp): equal to 1e-12.
    assert results[0] == pytest.approx(results[1], rel=1e-12)
    assert results[0] == pytest.approx(arbor_slam.solve(read).F_final, rel=1e-6)


@pytest.mark.parametrize("name", FILES)
def test_write_then_read_back(name, data_dir, tmp_path):
    read = arbor_slam.read(os.path.join(data_dir, name))
    built = rebuilt(read)
    out = str(tmp_path / "out.g2o")
    built.write(out)
    again = arbor_slam.read(out)
    assert_same(again, built)
    assert arbor_slam.solve(again).F_final == pytest.approx(arbor_slam.solve(built).F_final, rel=1e-12)
    # An estimate written as TUM and KITTI: one line per pose, in ascending id order.
    estimate = arbor_slam.solve(built).estimate
    built.write(str(tmp_path / "out.tum"), poses=estimate)
    built.write(str(tmp_path / "est.txt"), format="kitti", poses=estimate)
    tum = np.loadtxt(tmp_path / "out.tum")
    kitti = np.loadtxt(tmp_path / "est.txt")
    assert tum.shape == (built.num_poses, 8) and kitti.shape == (built.num_poses, 12)
    np.testing.assert_array_equal(tum[:, 0], built.ids)
    d = built.dimension
    np.testing.assert_allclose(tum[:, 1:1 + d], estimate[:, :d], atol=1e-12)
    np.testing.assert_allclose(kitti[:, [3, 7]], estimate[:, :2], atol=1e-12)


def test_priors_fix_and_pose(tmp_path):
    g = arbor_slam.Graph3()
    g.add_pose(10, arbor_slam.SE3([1, 0, 0], [1, 0, 0, 0]))
    g.add_pose(11, [2, 0, 0, 0, 0, 0, 1])
    g.add_edge(10, 11, arbor_slam.SE3([1, 0, 0], [1, 0, 0, 0]), np.eye(6))
    g.add_pose_prior(10, arbor_slam.SE3([1, 0, 0], [1, 0, 0, 0]), 4 * np.eye(6))
    g.add_position_prior(11, [2.1, 0, 0], np.eye(3))
    assert g.num_priors == 2 and len(g.fixed) == 0  # the priors anchor the graph
    assert g.pose(11).isclose(arbor_slam.SE3([2, 0, 0], [1, 0, 0, 0]))
    out = str(tmp_path / "priors.g2o")
    g.write(out)
    again = arbor_slam.read(out)
    assert_same(again, g)
    assert arbor_slam.solve(again).F_final == pytest.approx(arbor_slam.solve(g).F_final, rel=1e-12)
    smoother = arbor_slam.OnlineSmoother3()
    assert smoother.add_graph(g).to_dict() == {"accepted": 3, "duplicate": 0}  # the edge and both priors
    smoother.update()
    smoother.finalize()
    assert smoother.objective() == pytest.approx(arbor_slam.solve(g).F_final, rel=1e-9)
    g.fix(10)
    assert list(g.fixed) == [10]


@pytest.mark.parametrize("name", FILES)
def test_pickle_round_trip(name, data_dir):
    read = arbor_slam.read(os.path.join(data_dir, name))
    for graph in (read, rebuilt(read)):
        back = pickle.loads(pickle.dumps(graph))
        assert type(back) is type(graph) and back.path == graph.path
        assert_same(back, graph)
        assert arbor_slam.solve(back).F_final == pytest.approx(arbor_slam.solve(graph).F_final, rel=1e-12)
    empty = pickle.loads(pickle.dumps(arbor_slam.Graph2()))
    assert empty.num_poses == 0 and repr(empty).startswith("<arbor_slam.Graph2 (in memory)")


def test_bad_input_names_the_value(tmp_path):
    g = arbor_slam.Graph2()
    g.add_pose(0, arbor_slam.SE2())
    g.add_pose(1, arbor_slam.SE2(1, 0, 0))
    with pytest.raises(ValueError, match="add_pose: id 1 is already a pose"):
        g.add_pose(1, arbor_slam.SE2())
    with pytest.raises(ValueError, match="add_edge 0 -> 7: unknown pose id 7"):
        g.add_edge(0, 7, arbor_slam.SE2(), np.eye(3))
    with pytest.raises(ValueError, match="add_edge 1 -> 1: a self-loop"):
        g.add_edge(1, 1, arbor_slam.SE2(), np.eye(3))
    with pytest.raises(ValueError, match="add_edge 0 -> 1: information matrix not positive "
                                         "definite"):
        g.add_edge(0, 1, arbor_slam.SE2(1, 0, 0), -np.eye(3))
    with pytest.raises(ValueError, match="add_edge 0 -> 1: information matrix not symmetric"):
        g.add_edge(0, 1, arbor_slam.SE2(1, 0, 0), np.array([[1, 0.5, 0], [0, 1, 0], [0, 0, 1.0]]))
    with pytest.raises(ValueError, match="information: expected a 3x3 matrix, got 2x2"):
        g.add_edge(0, 1, arbor_slam.SE2(1, 0, 0), np.eye(2))
    with pytest.raises(ValueError, match="measurement: expected 3 numbers"):
        g.add_edge(0, 1, [1.0, 0.0], np.eye(3))
    with pytest.raises(TypeError, match="add_edge 0 -> 1: measurement: expected an SE2"):
        g.add_edge(0, 1, arbor_slam.SE3(), np.eye(3))
    with pytest.raises(ValueError, match="add_pose_prior 5: unknown pose id 5"):
        g.add_pose_prior(5, arbor_slam.SE2(), np.eye(3))
    assert g.num_edges == 0 and g.num_priors == 0  # nothing refused was kept
    with pytest.raises(ValueError, match="give format='tum' or 'kitti'"):
        g.write(str(tmp_path / "out.txt"))
    with pytest.raises(ValueError, match="disagrees"):
        g.write(str(tmp_path / "out.tum"), format="kitti")
    with pytest.raises(ValueError, match="poses: expected a 2x3 array"):
        g.write(str(tmp_path / "out.g2o"), poses=np.zeros((3, 3)))
    with pytest.raises(arbor_slam.FileError, match="cannot open"):
        g.write(str(tmp_path / "missing" / "out.g2o"))
