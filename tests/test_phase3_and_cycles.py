"""Paper items of lectures 04–05 that no other test checks directly: eq. (18) (the corrections of
eqs. (16)–(17) minimise the first-order expansion around the sub-optimal estimate), Remark 1 (phase 3 has
the size of one Gauss–Newton step), the cycle / circuit definitions on the fundamental circuits, and
Corollary 3 (the loop closures are the chords of the odometric tree)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

import lago_cvx as lc
from lago_cvx.posegraph import rot2
from lago_cvx.refinement import jacobian, odometry_guess
from lago_cvx.regularization import regularize
from lago_cvx.theorem1 import theorem1

PAPER = {"regularization": "tree", "information": "marginal", "positions": "phase3"}


def test_eq18_minimiser_is_the_phase3_correction():
    """Eq. (18): the quadratic (A₂ᵀp̂ + A₂ᵀδ_p − RΔˡ − Jδ_θ)ᵀ(RP_ΔRᵀ)⁻¹(…) + (Aᵀθ̂ + Aᵀδ_θ − δ)ᵀP_δ⁻¹(…)
    is minimised by (δ_p, δ_θ) = (p̃, θ̃), the corrections of eqs. (16)–(17)."""
    g = lc.random_graph(15, 32, seed=5, sigma_xy=0.1, sigma_theta=0.05).graph
    t = theorem1(g, **PAPER)
    res = t.result
    n, m = g.n_poses - 1, g.n_edges
    A = lc.reduced_incidence(g).toarray()
    A2 = np.kron(A, np.eye(2))
    R = sla.block_diag(*rot2(res.phase1.theta[g.tails]))
    J = res.phase2.jac.toarray()
    W_pos = np.linalg.inv(R @ sla.block_diag(*res.uncertainty.cov_delta_l) @ R.T)
    W_rot = np.diag(1.0 / res.uncertainty.var_delta)
    p_hat, th_hat = t.x_hat[:2 * n], t.x_hat[2 * n:]
    r_pos = A2.T @ p_hat - R @ g.delta_l.ravel()
    r_rot = A.T @ th_hat - res.regularization.delta_reg
    D_pos = np.hstack([A2.T, -J])                          # ∂/∂(δ_p, δ_θ) of the position residual
    D_rot = np.hstack([np.zeros((m, 2 * n)), A.T])
    H = D_pos.T @ W_pos @ D_pos + D_rot.T @ W_rot @ D_rot
    step = np.linalg.solve(H, -(D_pos.T @ W_pos @ r_pos + D_rot.T @ W_rot @ r_rot))
    np.testing.assert_allclose(step, np.concatenate([t.position_correction, t.theta_correction]), rtol=1e-8,
                               atol=1e-10)
    np.testing.assert_allclose(H, res.phase3.info.toarray(), rtol=1e-9, atol=1e-9 * np.abs(H).max())


def test_remark1_phase3_has_the_size_of_one_gauss_newton_step():
    """Remark 1: phase 1 solves a problem of size n, phase 3 one of size 3n — the size of one step of an
    iterative method, which needs several such steps (fewer from LAGO than from dead reckoning)."""
    g = lc.manhattan_world(400, seed=2, sigma_xy=0.05, sigma_theta=0.02).graph
    res = lc.lago(g, route="seed")
    n = g.n_poses - 1
    Jac = jacobian(g, res.poses)
    assert res.phase1.info.shape == (n, n)
    assert res.phase3.info.shape == (Jac.T @ Jac).shape == (3 * n, 3 * n)
    from_dead_reckoning = lc.refine(g, odometry_guess(g), max_iterations=100)
    from_lago = lc.refine(g, res.poses, max_iterations=100)
    assert from_lago.iterations < from_dead_reckoning.iterations
    assert abs(from_lago.chi2 - from_dead_reckoning.chi2) <= 1e-6 * from_lago.chi2


@pytest.mark.parametrize("kind", ["bfs", "odometry", "mst"])
def test_fundamental_circuits_are_circuits_and_their_union_a_cycle(kind):
    """Section IV-E: a cycle has every node of even degree, a circuit every node of degree exactly two.
    Each fundamental circuit (a row of C) is a circuit; the union of two edge-disjoint ones sharing a
    pose is a cycle that is not a circuit."""
    g = lc.manhattan_world(300, seed=4).graph
    tree = lc.spanning_tree(g, kind)
    C = lc.cycle_basis(g, tree).toarray()

    def degrees(c):
        used = c != 0
        return np.bincount(np.concatenate([g.tails[used], g.heads[used]]), minlength=g.n_poses)

    for row in C:
        d = degrees(row)
        assert set(d[d > 0]) == {2}
    found = False
    for a in range(len(C)):
        for b in range(a + 1, len(C)):
            if np.any((C[a] != 0) & (C[b] != 0)):
                continue
            shared = (degrees(C[a]) > 0) & (degrees(C[b]) > 0)
            if shared.sum() == 1:
                d = degrees(C[a] + C[b])
                assert np.all(d % 2 == 0) and d.max() == 4
                found = True
                break
        if found:
            break
    assert found, "no pair of edge-disjoint fundamental circuits sharing one pose in this world"


@pytest.mark.parametrize("world", ["manhattan", "circle"])
def test_corollary3_loop_closures_are_the_chords_of_the_odometric_tree(world):
    """Proposition 2 and Corollary 3: the odometric edges are a spanning tree, the loop closures its chords,
    so the paper's regularization corrects loop closures only, by the full turns between the two poses."""
    w = (lc.manhattan_world(300, seed=1, sigma_theta=0.0) if world == "manhattan"
         else lc.circle_world(90, laps=3, seed=0, sigma_xy=0.0, sigma_theta=0.0))
    g = w.graph
    tree = lc.spanning_tree(g, "odometry")
    np.testing.assert_array_equal(np.sort(tree.tree_edges), np.flatnonzero(g.is_odometric))
    np.testing.assert_array_equal(tree.chords, np.flatnonzero(~g.is_odometric))
    reg = regularize(g, tree)
    turns = np.rint((w.truth[g.heads, 2] - w.truth[g.tails, 2] - g.delta) / (2 * np.pi)).astype(int)
    np.testing.assert_array_equal(reg.k, turns)
    assert np.all(reg.k[g.is_odometric] == 0)
