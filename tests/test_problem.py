"""The problem of the paper's Section III, eqs. (1)–(7), against the package's primitives: pose compounding,
the cost as a Gaussian log-likelihood, the split residual with block-diagonal noise in incidence-matrix form,
and the reduced system with pose 0 fixed. (Lecture 1 derives each; these are the unit checks it cites.)"""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.phases import design_matrix
from lago_cvx.posegraph import between, compose, rot2


def _random_poses(rng, k):
    return np.column_stack([rng.uniform(-50, 50, (k, 2)), rng.uniform(-3 * np.pi, 3 * np.pi, k)])


def test_eq1_compounding_and_its_identities():
    rng = np.random.default_rng(0)
    a, b, c, t = (_random_poses(rng, 500) for _ in range(4))
    eq1 = np.column_stack([np.einsum("kba,kb->ka", rot2(a[:, 2]), b[:, :2] - a[:, :2]), b[:, 2] - a[:, 2]])
    np.testing.assert_allclose(between(a, b), eq1, atol=1e-12)
    np.testing.assert_allclose(between(a, compose(a, t)), t, atol=1e-9)
    np.testing.assert_allclose(compose(a, between(a, b)), b, atol=1e-9)
    np.testing.assert_allclose(between(a, c), compose(between(a, b), between(b, c)), atol=1e-9)


def test_eq2_eq3_cost_is_minus_twice_the_gaussian_log_likelihood():
    stats = pytest.importorskip("scipy.stats")
    w = lc.random_graph(15, 30, seed=1, information="full")
    g = w.graph
    e = lc.edge_errors(g, w.truth)
    cov = g.covariance
    log_l = sum(stats.multivariate_normal(np.zeros(3), cov[k]).logpdf(e[k]) for k in range(g.n_edges))
    logdet = np.linalg.slogdet(2 * np.pi * cov)[1].sum()
    assert -2 * log_l == pytest.approx(lc.chi2(g, w.truth) + logdet, rel=1e-10)


def _dense_eq5(g, x):
    """Eq. (5) (full incidence, block-diagonal noise) with dense matrices; angular residual lifted to (−π, π]."""
    A = lc.incidence_matrix(g).toarray()
    A2 = np.kron(A, np.eye(2))
    m = g.n_edges
    R = np.zeros((2 * m, 2 * m))
    P_dl = np.zeros((2 * m, 2 * m))
    cov = g.covariance
    for k, i in enumerate(g.tails):
        R[2 * k:2 * k + 2, 2 * k:2 * k + 2] = rot2(x[i, 2])
        P_dl[2 * k:2 * k + 2, 2 * k:2 * k + 2] = cov[k, :2, :2]
    r_pos = A2.T @ x[:, :2].ravel() - R @ g.delta_l.ravel()
    r_rot = A.T @ x[:, 2] - g.delta
    r_rot -= 2 * np.pi * np.round(r_rot / (2 * np.pi))
    return r_pos @ np.linalg.solve(R @ P_dl @ R.T, r_pos) + np.sum(r_rot**2 / cov[:, 2, 2])


def test_eq4_eq5_split_cost_with_block_diagonal_noise_is_chi2():
    w = lc.random_graph(12, 20, seed=3, sigma_xy=0.05, sigma_theta=0.03)
    g = w.graph
    assert np.all(g.information[:, :2, 2] == 0)
    x = w.truth + 0.05 * np.random.default_rng(1).standard_normal(w.truth.shape)
    e = lc.edge_errors(g, x)
    eq4 = np.column_stack([between(x[g.tails], x[g.heads])[:, :2] - g.delta_l, e[:, 2]])
    np.testing.assert_allclose(e, eq4, atol=1e-12)
    assert _dense_eq5(g, x) == pytest.approx(lc.chi2(g, x), rel=1e-10)


def test_eq5_needs_block_diagonal_noise():
    w = lc.random_graph(12, 20, seed=3, information="full")
    g = w.graph
    x = w.truth + 0.05 * np.random.default_rng(1).standard_normal(w.truth.shape)
    marginal = g.covariance.copy()
    marginal[:, :2, 2] = marginal[:, 2, :2] = 0.0
    split = lc.PoseGraph(g.n_poses, g.tails, g.heads, g.delta_l, g.delta, np.linalg.inv(marginal))
    assert _dense_eq5(g, x) == pytest.approx(lc.chi2(split, x), rel=1e-10)   # eq. (5) sees the marginals only
    assert abs(lc.chi2(g, x) - lc.chi2(split, x)) > 1e-3 * lc.chi2(g, x)       # … which differ from eq. (3)


def test_eq6_eq7_reduced_system_with_pose0_fixed():
    w = lc.random_graph(10, 16, seed=5)
    g = w.graph
    A = lc.reduced_incidence(g).toarray()
    n = g.n_poses - 1
    A2 = np.kron(A, np.eye(2))
    np.testing.assert_array_equal(design_matrix(g).toarray()[:2 * g.n_edges, :2 * n], A2.T)
    x = w.truth - w.truth[0]
    x[:, :2] = (w.truth[:, :2] - w.truth[0, :2]) @ rot2(w.truth[0, 2])   # pose 0 at the origin
    # with pose 0 at the origin the full form (5) equals the reduced form (6) of the system (7)
    theta = x[:, 2]
    r_pos = A2.T @ x[1:, :2].ravel() - np.einsum("kab,kb->ka", rot2(theta[g.tails]), g.delta_l).ravel()
    r_rot = A.T @ theta[1:] - g.delta
    r_rot -= 2 * np.pi * np.round(r_rot / (2 * np.pi))
    cov = g.covariance
    Rb = [rot2(theta[i]) for i in g.tails]
    eq6 = sum(r_pos[2 * k:2 * k + 2] @ np.linalg.solve(Rb[k] @ cov[k, :2, :2] @ Rb[k].T, r_pos[2 * k:2 * k + 2])
              for k in range(g.n_edges)) + np.sum(r_rot**2 / cov[:, 2, 2])
    assert eq6 == pytest.approx(lc.chi2(g, x), rel=1e-9, abs=1e-9)
