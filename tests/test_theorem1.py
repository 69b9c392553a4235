"""Theorem 1 measured (lago_cvx.theorem1): the identity x* = x̂ + [ρ̃; δ̃] of eqs. (16)–(17) holds to
rounding; the claim that phase 3 moves x̂ "towards a minimum of the cost function" does not always."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.theorem1 import theorem1

from conftest import dataset_path


@pytest.mark.parametrize("information", ["diagonal", "full"])
def test_identity_of_eqs_16_17_on_random_graphs(information):
    for seed in range(3):
        g = lc.random_graph(20, 45, seed=seed, information=information, sigma_xy=0.1, sigma_theta=0.05).graph
        t = theorem1(g)
        assert t.identity_error < 1e-9  # x* − x̂ = [ρ̃; δ̃]
        assert t.eq14_error < 1e-9  # p̂ is the exact position solve at θ̂ (eq. (14))
        assert t.chi2_resolved <= t.chi2_phase3 * (1 + 1e-12)


def test_identity_matches_the_seeds_dense_formulas():
    """For block-diagonal information, eq. (16)'s δ̃ = P_θ* Jᵀ P_Δg⁻¹ (A₂ᵀ P_Δp A₂ P_Δg⁻¹ − I) RΔˡ with the
    seed's dense covariances (written with Q = P_Δg⁻¹ − P_Δg⁻¹A(AᵀP_Δg⁻¹A)⁻¹AᵀP_Δg⁻¹, A = A₂ᵀ ⊗ I₂)."""
    g = lc.random_graph(12, 24, seed=7, sigma_xy=0.1, sigma_theta=0.05).graph
    t = theorem1(g, information="marginal", positions="phase3")
    res = t.result
    m, d = g.n_edges, g.n_poses - 1
    A = np.kron(lc.reduced_incidence(g).toarray().T, np.eye(2))
    th = res.phase1.theta
    R = np.zeros((2 * m, 2 * m))
    for k in range(m):
        c, s = np.cos(th[g.tails[k]]), np.sin(th[g.tails[k]])
        R[2 * k:2 * k + 2, 2 * k:2 * k + 2] = [[c, -s], [s, c]]
    Pg_inv = np.linalg.inv(R @ _blk(res.uncertainty.cov_delta_l) @ R.T)  # (R P_Δˡ Rᵀ)⁻¹
    J = res.phase2.jac.toarray()
    P_theta_inv = res.phase1.info.toarray()
    Q = Pg_inv - Pg_inv @ A @ np.linalg.solve(A.T @ Pg_inv @ A, A.T @ Pg_inv)
    dg = res.phase2.delta_g.reshape(-1)
    delta = -np.linalg.solve(P_theta_inv + J.T @ Q @ J, J.T @ Q @ (dg - A @ t.x_hat[:2 * d]))
    np.testing.assert_allclose(t.theta_correction, delta, rtol=1e-8, atol=1e-12)


def _blk(blocks):
    from scipy.linalg import block_diag

    return block_diag(*blocks)


@pytest.mark.parametrize("rel,factor", [("carlone/INTEL_P_toro.graph", 50), ("se-sync/MIT.g2o", 5),
                                        ("carlone/input_INTEL_g2o.g2o", 1000)])
def test_phase3_moves_away_from_the_minimum_on_real_graphs(rel, factor):
    """The claim fails: χ²(x*) ≫ χ²(x̂) on these files in their own costs (INTEL_P 220.0 → 14 531), although the
    identity holds; re-solving the positions for θ* brings χ² back below χ²(x̂)."""
    g = lc.read_graph(dataset_path(rel))
    t = theorem1(g)
    print(f"{rel}: χ²(x̂) {t.chi2_suboptimal:.6g}, χ²(x*) {t.chi2_phase3:.6g}, resolved {t.chi2_resolved:.6g}, "
          f"LAGO {t.chi2_lago:.6g}; identity {t.identity_error:.1e}")
    assert t.identity_error < 1e-9
    assert t.chi2_phase3 > factor * t.chi2_suboptimal
    # LAGO's default route re-solves the positions too, on its own factorization: the same minimum up to the
    # linear solves' rounding (INTEL's information spans eight decades: 7e-11 relative seen), not bit for bit
    assert t.chi2_lago <= min(t.chi2_suboptimal, t.chi2_resolved) * (1 + 1e-9)


@pytest.mark.parametrize("rel,factor", [("se-sync/city10000.g2o", 0.9), ("se-sync/CSAIL.g2o", 1.0),
                                        ("se-sync/intel.g2o", 1.0)])
def test_where_the_claim_holds(rel, factor):
    """χ²(x*) < χ²(x̂). CSAIL in its own cost (g2o's); read as eq. (3)'s (cost "paper", a cost no tool computes for
    this file) the claim failed there too, χ²(x*) > 5 χ²(x̂)."""
    g = lc.read_graph(dataset_path(rel))
    t = theorem1(g)
    assert t.chi2_phase3 < factor * t.chi2_suboptimal and t.identity_error < 1e-9
    if rel == "se-sync/CSAIL.g2o":
        t = theorem1(g.with_cost("paper"))
        assert t.chi2_phase3 > 5 * t.chi2_suboptimal


def test_frozen_and_model_reduce_to_chi2_where_they_must():
    """``frozen_and_model``: at x̂ the linearisation is exact (model = frozen = χ² there); with isotropic
    translational information the weights do not turn, so frozen = χ² at any poses (x* included)."""
    from lago_cvx import chi2, manhattan_world
    from lago_cvx.theorem1 import frozen_and_model, theorem1

    g = manhattan_world(200, seed=5).graph
    assert np.allclose(g.information[:, 0, 0], g.information[:, 1, 1]) and np.all(g.information[:, 0, 1] == 0)
    t = theorem1(g, regularization="tree", information="marginal", positions="phase3")
    hat, star = t.poses(t.x_hat), t.poses(t.x_star)
    frozen_hat, model_hat = frozen_and_model(t.result, hat)
    assert model_hat == pytest.approx(frozen_hat, rel=1e-12)
    assert frozen_hat == pytest.approx(chi2(g, hat), rel=1e-9)
    frozen_star, model_star = frozen_and_model(t.result, star)
    assert frozen_star == pytest.approx(chi2(g, star), rel=1e-9)
    assert model_star != pytest.approx(frozen_star, rel=1e-12)   # away from θ̂ the model is only a model
