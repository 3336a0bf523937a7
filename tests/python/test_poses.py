"""arbor_slam.SE2 / arbor_slam.SE3 against plain numpy homogeneous matrices: compose is the matrix
product, inverse the matrix inverse, between = inverse · other, exp(log(x)) = x; pickling and
the constructors' checks."""
import copy
import math
import pickle

import numpy as np
import pytest

import arbor_slam


def se2_matrix(x, y, theta):
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0, 0, 1.0]])


def quat_matrix(w, x, y, z):
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def random_se2(rng):
    x, y = rng.uniform(-5, 5, 2)
    theta = rng.uniform(-math.pi, math.pi)
    return arbor_slam.SE2(x, y, theta), se2_matrix(x, y, theta)


def random_se3(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    t = rng.uniform(-5, 5, 3)
    m = np.eye(4)
    m[:3, :3] = quat_matrix(*q)
    m[:3, 3] = t
    return arbor_slam.SE3(t, q), m


@pytest.mark.parametrize("make", [random_se2, random_se3])
def test_algebra_matches_matrices(make):
    rng = np.random.default_rng(5)
    for _ in range(50):
        a, ma = make(rng)
        b, mb = make(rng)
        np.testing.assert_allclose(a.matrix(), ma, atol=1e-12)
        np.testing.assert_allclose(a.compose(b).matrix(), ma @ mb, atol=1e-12)
        np.testing.assert_allclose((a * b).matrix(), ma @ mb, atol=1e-12)
        np.testing.assert_allclose(a.inverse().matrix(), np.linalg.inv(ma), atol=1e-12)
        np.testing.assert_allclose(a.between(b).matrix(), np.linalg.inv(ma) @ mb, atol=1e-12)
        assert type(a).exp(a.log()).isclose(a, atol=1e-12)
        d = ma.shape[0] - 1
        np.testing.assert_allclose(a.translation(), ma[:d, d], atol=1e-12)
        np.testing.assert_allclose(a.rotation(), ma[:d, :d], atol=1e-12)
        assert type(a).from_matrix(ma).isclose(a, atol=1e-12)
        assert type(a).from_array(a.to_array()).isclose(a, atol=1e-12)


def test_exp_order_translation_first():
    # A pure translation tangent: the rotation part is last.
    np.testing.assert_allclose(arbor_slam.SE2.exp([1.0, 2.0, 0.0]).translation(), [1, 2])
    assert arbor_slam.SE2.exp([0.0, 0.0, 0.3]).theta == pytest.approx(0.3)
    x = arbor_slam.SE3.exp([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(x.translation(), [1, 2, 3])
    np.testing.assert_allclose(x.rotation(), np.eye(3))
    y = arbor_slam.SE3.exp([0, 0, 0, 0, 0, 0.5])
    np.testing.assert_allclose(y.rotation(), quat_matrix(math.cos(0.25), 0, 0, math.sin(0.25)),
                               atol=1e-15)


def test_quaternion_order_is_wxyz():
    q = [math.cos(0.2), 0.0, 0.0, math.sin(0.2)]  # 0.4 rad about z
    x = arbor_slam.SE3([0, 0, 0], q)
    np.testing.assert_allclose(x.quaternion(), q, atol=1e-15)
    np.testing.assert_allclose(x.to_array()[3:], [0, 0, q[3], q[0]], atol=1e-15)
    assert arbor_slam.SE3().isclose(arbor_slam.SE3.identity(), atol=0)


@pytest.mark.parametrize("pose", [arbor_slam.SE2(1.5, -2.25, 0.7),
                                  arbor_slam.SE3([1, 2, 3], [0.5, 0.5, -0.5, 0.5])])
def test_pickle_and_copy(pose):
    for other in (pickle.loads(pickle.dumps(pose)), copy.copy(pose), copy.deepcopy(pose)):
        assert type(other) is type(pose)
        assert other.isclose(pose, atol=1e-15)
    assert repr(pose).startswith(type(pose).__name__ + "(")


def test_isclose_tolerance():
    a = arbor_slam.SE2(1, 2, 0.5)
    assert a.isclose(arbor_slam.SE2(1 + 1e-10, 2, 0.5))
    assert not a.isclose(arbor_slam.SE2(1 + 1e-6, 2, 0.5))
    assert a.isclose(arbor_slam.SE2(1 + 1e-6, 2, 0.5), atol=1e-5)


def test_bad_input():
    with pytest.raises(ValueError, match="quaternion norm"):
        arbor_slam.SE3([0, 0, 0], [1, 1, 0, 0])
    with pytest.raises(ValueError, match="translation"):
        arbor_slam.SE3([0, 0], [1, 0, 0, 0])
    with pytest.raises(ValueError, match="finite"):
        arbor_slam.SE2(float("nan"), 0, 0)
    with pytest.raises(ValueError, match="expected 3 finite"):
        arbor_slam.SE2.exp([1.0, 2.0])
    with pytest.raises(ValueError, match="not a rotation"):
        arbor_slam.SE3.from_matrix(np.diag([1.0, 1.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="last row"):
        arbor_slam.SE2.from_matrix(np.ones((3, 3)))
    with pytest.raises(ValueError, match="expected 4x4"):
        arbor_slam.SE3.from_matrix(np.eye(3))
