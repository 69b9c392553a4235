"""The three phases: cvxpy vs closed form, the sparse square root W of P_z⁻¹ (eqs. 9–11) against the
dense covariance, Theorem 1 (eqs. 15–17) and the marginal covariances."""

import numpy as np
import pytest
import scipy.linalg as sla

from lago_cvx import lago
from lago_cvx import phases as P
from lago_cvx.graph import free_poses, reduced_incidence
from lago_cvx.metrics import relative_difference
from lago_cvx.posegraph import rot2
from lago_cvx.synthetic import manhattan_world, random_graph
from lago_cvx.uncertainty import edge_uncertainty

S = np.array([[0.0, -1.0], [1.0, 0.0]])


@pytest.fixture(scope="module", params=[("diagonal", 0), ("full", 1), ("full", 2)])
def small(request):
    info, seed = request.param
    w = random_graph(25, 45, seed=seed, information=info, sigma_xy=0.1, sigma_theta=0.05)
    return w.graph, lago(w.graph, anchor=0, information="marginal", positions="phase3")  # the seed's eqs. (9)–(15)


def dense_pz(graph, res):
    """P_z from its definition (eq. 10) with explicit dense blocks — an independent construction."""
    unc, th = res.uncertainty, res.phase1.theta
    m, n = graph.n_edges, graph.n_poses
    free = free_poses(n, 0)
    A2 = reduced_incidence(graph, 0).toarray()
    P_theta = np.linalg.inv(A2 @ np.diag(1 / unc.var_delta) @ A2.T)
    R = sla.block_diag(*[rot2(th[graph.tails[k]]) for k in range(m)])
    J = np.zeros((2 * m, n - 1))
    for k in range(m):
        i = graph.tails[k]
        if i != 0:
            J[2 * k:2 * k + 2, np.flatnonzero(free == i)[0]] = S @ rot2(th[i]) @ graph.delta_l[k]
    P_dl = sla.block_diag(*unc.cov_delta_l)
    top = R @ P_dl @ R.T + J @ P_theta @ J.T
    return np.block([[top, J @ P_theta], [P_theta @ J.T, P_theta]]), J, P_theta


def test_phase1_cvxpy_equals_closed_form(small):
    g, res = small
    ph1, prob = P.phase1_from_problem(g, res.regularization.delta_reg, res.uncertainty)
    assert relative_difference(ph1.theta_free, res.phase1.theta_free) < 1e-9
    assert "sum_squares" in str(prob.objective) or "quad_over_lin" in str(prob.objective)


def test_phase2_sparse_square_root_is_inverse_of_dense_covariance(small):
    g, res = small
    Pz, J, _ = dense_pz(g, res)
    W = res.phase2.W.toarray()
    np.testing.assert_allclose(W.T @ W @ Pz, np.eye(Pz.shape[0]), atol=1e-8)
    np.testing.assert_allclose(res.phase2.jac.toarray(), J, atol=1e-12)
    # z = [R(θ̂_i)Δˡ; θ̂]
    dg = np.einsum("kab,kb->ka", rot2(res.phase1.theta[g.tails]), g.delta_l)
    np.testing.assert_allclose(res.phase2.z[:2 * g.n_edges], dg.ravel())


def test_phase3_cvxpy_equals_closed_form(small):
    g, res = small
    ph3, prob = P.phase3_from_problem(g, res.phase2)
    assert relative_difference(ph3.x_star, res.phase3.x_star) < 1e-9
    assert len(prob.variables()) == 1 and prob.variables()[0].shape == (3 * g.n_poses,)  # every pose by index


def test_phase3_is_the_blue_of_eq15(small):
    """x* = (B P_z⁻¹ Bᵀ)⁻¹ B P_z⁻¹ z with the dense P_z."""
    g, res = small
    Pz, _, _ = dense_pz(g, res)
    Bt = P.design_matrix(g).toarray()
    Pinv = np.linalg.inv(Pz)
    x = np.linalg.solve(Bt.T @ Pinv @ Bt, Bt.T @ Pinv @ res.phase2.z)
    np.testing.assert_allclose(res.phase3.x_star, x, rtol=1e-9, atol=1e-9)


def test_theorem1_suboptimal_estimate_plus_first_order_correction(small):
    """Theorem 1 (eqs. (15)–(17)): x* = [p̂; θ̂] + correction, with p̂ the positions given θ̂ (eq. (14))
    and the corrections d* = −(P_θ⁻¹ + JᵀQJ)⁻¹JᵀQ r (eq. (16)), p* = p̂ + (AᵀP_g⁻¹A)⁻¹AᵀP_g⁻¹J d* (eq. (17)),
    where A = A2ᵀ⊗I₂, P_g = R P_Δ Rᵀ, r = Δᵍ − A p̂, Q = P_g⁻¹ − P_g⁻¹A(AᵀP_g⁻¹A)⁻¹AᵀP_g⁻¹."""
    g, res = small
    unc, th = res.uncertainty, res.phase1.theta
    m = g.n_edges
    A = np.kron(reduced_incidence(g, 0).toarray().T, np.eye(2))
    R = sla.block_diag(*[rot2(th[g.tails[k]]) for k in range(m)])
    Pg_inv = np.linalg.inv(R @ sla.block_diag(*unc.cov_delta_l) @ R.T)
    _, J, P_theta = dense_pz(g, res)
    dg = res.phase2.z[:2 * m]
    H = A.T @ Pg_inv @ A
    p_hat = np.linalg.solve(H, A.T @ Pg_inv @ dg)                       # eq. (14)
    r = dg - A @ p_hat
    Q = Pg_inv - Pg_inv @ A @ np.linalg.solve(H, A.T @ Pg_inv)
    d_star = -np.linalg.solve(np.linalg.inv(P_theta) + J.T @ Q @ J, J.T @ Q @ r)
    p_star = p_hat + np.linalg.solve(H, A.T @ Pg_inv @ J @ d_star)       # eq. (17)
    theta_star = res.phase1.theta_free + d_star
    np.testing.assert_allclose(res.phase3.x_star, np.concatenate([p_star, theta_star]), rtol=1e-9, atol=1e-9)


def test_pose_covariances_are_blocks_of_the_dense_inverse(small):
    g, res = small
    cov = res.phase3.pose_covariances()
    full = np.linalg.inv(res.phase3.info.toarray())
    d = g.n_poses - 1
    for r in (0, 5, d - 1):
        idx = [2 * r, 2 * r + 1, 2 * d + r]
        np.testing.assert_allclose(cov[r + 1], full[np.ix_(idx, idx)], rtol=1e-9, atol=1e-14)
    assert np.all(cov[0] == 0)
    var = res.phase1.variances()
    Pth = np.linalg.inv(res.phase1.info.toarray())
    np.testing.assert_allclose(var[1:], np.diag(Pth), rtol=1e-9)


def test_edge_uncertainty_is_marginal_covariance():
    g = random_graph(10, 20, seed=1, information="full").graph
    unc = edge_uncertainty(g)
    cov = np.linalg.inv(g.information)
    np.testing.assert_allclose(unc.cov_delta_l, cov[:, :2, :2])
    np.testing.assert_allclose(unc.var_delta, cov[:, 2, 2])
    U = unc.sqrt_info_delta_l
    np.testing.assert_allclose(np.swapaxes(U, 1, 2) @ U, np.linalg.inv(cov[:, :2, :2]), rtol=1e-10)


def test_cvxpy_phases_on_a_larger_world():
    g = manhattan_world(2000, seed=7).graph
    res = lago(g, method="cvxpy")
    ref = lago(g)
    assert relative_difference(res.phase1.theta_free, ref.phase1.theta_free) < 1e-9
    assert relative_difference(res.phase3.x_star, ref.phase3.x_star) < 1e-9
    assert set(res.problems) == {"chordal", "phase1", "phase3", "positions"}


def test_printed_problems_read_like_their_equations_and_resolve_by_parameter():
    """``print(problem)`` names the paper's quantities (eqs. (13), (12)/(15), (14), the chordal relaxation)
    instead of dumping matrices, every builder is DPP, and changing a parameter's ``.value`` re-solves the
    same problem object: phase 1 re-solved with a perturbed δ_reg equals a fresh closed form."""
    import cvxpy as cp

    from lago_cvx.positions import position_problem
    from lago_cvx.regularization.chordal import chordal_problem
    from lago_cvx.solvers import solve as clarabel

    w = manhattan_world(60, seed=3)
    g = w.graph
    res = lago(g)
    p1, theta = P.phase1_problem(g, res.regularization.delta_reg, res.uncertainty)
    assert str(p1.objective) == "minimize quad_over_lin(P_δ^(-1/2) @ (Aᵀ @ θ + -δ_reg), 1.0, None, False)"
    assert str(P.phase3_problem(g, res.phase2)[0].objective) == \
        "minimize quad_over_lin(W @ (z + -(Bᵀ @ ρ)), 1.0, None, False)"
    assert theta.size == g.n_poses  # every pose by index, the anchor held by the constraint
    assert "W @ (A₂ᵀ @ p + -g)" in str(position_problem(g, res.poses[:, 2], res.uncertainty)[0])
    assert "M @ r + -b" in str(chordal_problem(g, 1.0 / res.uncertainty.var_delta)[0])
    assert all(pr.is_dpp() for pr in [p1, P.phase3_problem(g, res.phase2)[0]])
    clarabel(p1)
    first = theta.value.copy()
    rng = np.random.default_rng(0)
    shifted = res.regularization.delta_reg + rng.normal(0.0, 0.01, g.n_edges)
    p1.param_dict["δ_reg"].value = shifted  # re-solve the same object
    clarabel(p1)
    fresh = P.phase1_closed_form(g, shifted, res.uncertainty)
    np.testing.assert_allclose(theta.value, fresh.theta, atol=1e-8)
    assert np.abs(theta.value - first).max() > 1e-4
    assert isinstance(p1, cp.Problem)
