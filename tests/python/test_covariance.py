# Marginal and joint covariances from the Bayes tree against a dense numpy inverse of the
# information matrix JᵀΩJ, on a small 2D graph with exact measurements (so the linearisation
# point after finalize is the optimum to rounding).
#
# The 2D error (core/relative_pose_factor.h): δ = z⁻¹ (xᵢ⁻¹ xⱼ), e = [t(δ); θ(δ)], under the
# right perturbation x ⊞ (v, ω) = (t + R v, θ + ω); with d = tⱼ − tᵢ and S = [[0, −1], [1, 0]]:
#   ∂t(δ)/∂vᵢ = −R_zᵀ,   ∂t(δ)/∂ωᵢ = −R_zᵀ S Rᵢᵀ d,   ∂t(δ)/∂vⱼ = R_zᵀ Rᵢᵀ Rⱼ,   ∂t(δ)/∂ωⱼ = 0,
#   ∂θ(δ)/∂ωᵢ = −1,      ∂θ(δ)/∂ωⱼ = 1.
import numpy as np
import pytest

import arbor_slam

S = np.array([[0.0, -1.0], [1.0, 0.0]])


def rot(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def between(a, b):
    """a⁻¹ b of rows [x y θ]."""
    t = rot(a[2]).T @ (b[:2] - a[:2])
    return np.array([t[0], t[1], np.arctan2(np.sin(b[2] - a[2]), np.cos(b[2] - a[2]))])


def random_graph(rng, n=8, closures=5):
    truth = np.column_stack([rng.normal(0, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    pairs = [(k, k + 1) for k in range(n - 1)]
    while len(pairs) < n - 1 + closures:
        i, j = sorted(rng.choice(n, 2, replace=False))
        if j - i > 1 and (i, j) not in pairs:
            pairs.append((int(i), int(j)))
    edges = []
    for i, j in pairs:
        A = rng.normal(size=(3, 3))
        edges.append((i, j, between(truth[i], truth[j]), A @ A.T + 3 * np.eye(3)))
    return edges


def dense_information(poses, edges, n):
    H = np.zeros((3 * n, 3 * n))
    for i, j, z, omega in edges:
        Rz, Ri, Rj = rot(z[2]), rot(poses[i, 2]), rot(poses[j, 2])
        d = poses[j, :2] - poses[i, :2]
        Ji, Jj = np.zeros((3, 3)), np.zeros((3, 3))
        Ji[:2, :2] = -Rz.T
        Ji[:2, 2] = -Rz.T @ S @ Ri.T @ d
        Ji[2, 2] = -1.0
        Jj[:2, :2] = Rz.T @ Ri.T @ Rj
        Jj[2, 2] = 1.0
        J = np.zeros((3, 3 * n))
        J[:, 3 * i:3 * i + 3], J[:, 3 * j:3 * j + 3] = Ji, Jj
        H += J.T @ omega @ J
    return H


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_covariances_match_a_dense_inverse(seed):
    rng = np.random.default_rng(seed)
    n = 8
    edges = random_graph(rng, n)
    smoother = arbor_slam.OnlineSmoother2()
    for i, j, z, omega in sorted(edges, key=lambda e: max(e[0], e[1])):
        smoother.add_edge(i, j, z, omega)
        smoother.update()
    smoother.finalize()
    assert smoother.objective() < 1e-18
    ids, poses = smoother.estimates()
    assert list(ids) == list(range(n))
    H = dense_information(poses, edges, n)
    # Pose 0 is the anchor (held fixed): the covariance of the others is the inverse of H
    # without its block; the anchor's own is zero.
    sigma = np.zeros_like(H)
    sigma[3:, 3:] = np.linalg.inv(H[3:, 3:])

    def close(a, b):
        scale = np.abs(b).max()
        return np.abs(a - b).max() <= 1e-8 * scale

    assert np.array_equal(smoother.marginal_covariance(0), np.zeros((3, 3)))
    for v in range(1, n):
        got = smoother.marginal_covariance(v)
        assert close(got, sigma[3 * v:3 * v + 3, 3 * v:3 * v + 3]), (v, got)
    for a, b in [(1, n - 1), (2, 5), (n - 1, 3), (0, 4), (6, 6)]:
        idx = list(range(3 * a, 3 * a + 3)) + list(range(3 * b, 3 * b + 3))
        got = smoother.joint_marginal_covariance(a, b)
        assert got.shape == (6, 6)
        expected = sigma[np.ix_(idx, idx)]
        if a == 0:
            assert np.array_equal(got[:3], np.zeros((3, 6)))
            expected = expected.copy()
            expected[:3] = 0
            expected[:, :3] = 0
        assert close(got, expected), (a, b)


def test_covariance_before_update_raises():
    s = arbor_slam.OnlineSmoother2()
    s.add_edge(0, 1, [1, 0, 0], np.eye(3))
    with pytest.raises(RuntimeError):
        s.marginal_covariance(1)
    s.update()
    assert s.marginal_covariance(1) == pytest.approx(np.linalg.inv(np.eye(3)))
