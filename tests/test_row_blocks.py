"""Per-edge arithmetic done a block of edges at a time (``lago_cvx.stacks.row_blocks``): the lazily
computed edge uncertainties equal NumPy's dense linear algebra, and the phase-3 edge system, the errors
and χ² are the same whether the edges come in one block or in many (blocks of 7 here)."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx import phases as P
from lago_cvx import stacks
from lago_cvx.metrics import chi2, edge_errors
from lago_cvx.posegraph import PoseGraph, rot2
from lago_cvx.uncertainty import edge_uncertainty


def _full_info_graph(n=60, seed=3) -> PoseGraph:
    """A world whose edges carry full 3×3 information (x–θ, y–θ terms), each a different SPD matrix."""
    g = lc.manhattan_world(n, seed=seed).graph
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((g.n_edges, 3, 3))
    info = G @ np.swapaxes(G, 1, 2) + 0.5 * np.eye(3)
    return PoseGraph(n_poses=g.n_poses, tails=g.tails, heads=g.heads, delta_l=g.delta_l, delta=g.delta,
                     information=info, ids=g.ids)


def test_row_blocks_cover_the_rows_in_order():
    assert [(s.start, s.stop) for s in stacks.row_blocks(10, 4)] == [(0, 4), (4, 8), (8, 10)]
    assert list(stacks.row_blocks(0)) == []


@pytest.mark.parametrize("block", [7, None])
def test_edge_uncertainty_equals_dense_algebra(block, monkeypatch):
    """Every form of ``EdgeUncertainty`` (each computed when first read, a block at a time) against
    numpy.linalg on each edge's Ω: Σ = Ω⁻¹, P_Δ = Σ[:2, :2], P_δ = Σ[2, 2], UᵀU = P_Δ⁻¹, UᵀU = Ω,
    UᵀU = Ω_pp, h = Ω_pp⁻¹Ω_pθ — to 1e-12 relative."""
    if block is not None:
        monkeypatch.setattr(stacks, "BLOCK", block)
    g = _full_info_graph()
    unc = edge_uncertainty(g)
    om = g.information
    cov = np.linalg.inv(om)

    def close(a, b):
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()

    close(unc.var_delta, cov[:, 2, 2])
    close(unc.cov_delta_l, cov[:, :2, :2])
    close(unc.sqrt_info_delta, 1 / np.sqrt(cov[:, 2, 2]))
    U = unc.sqrt_info_delta_l
    close(np.swapaxes(U, 1, 2) @ U, np.linalg.inv(cov[:, :2, :2]))
    assert np.all(U[:, 1, 0] == 0)
    U = unc.sqrt_info
    close(np.swapaxes(U, 1, 2) @ U, om)
    assert np.all(np.tril(U, -1) == 0)
    U = unc.sqrt_info_pp
    close(np.swapaxes(U, 1, 2) @ U, om[:, :2, :2])
    close(unc.shift, np.linalg.solve(om[:, :2, :2], om[:, :2, 2:])[..., 0])
    assert not unc.block_diagonal.any()


@pytest.mark.parametrize("information", ["marginal", "full"])
def test_phase3_edge_system_is_the_same_in_blocks(information, monkeypatch):
    """The phase-3 edge system built in blocks of 7 edges equals the one built in one block, bit for bit,
    and its marginal form equals the products of eqs. (10)–(12) written as 2×2 matrix products."""
    g = _full_info_graph(80, seed=5)
    theta = np.random.default_rng(1).uniform(-3, 3, g.n_poses)
    theta[0] = 0.0
    delta_reg = g.delta + 0.01

    def build():
        unc = edge_uncertainty(g)
        dg = np.einsum("kab,kb->ka", rot2(theta[g.tails]), g.delta_l)
        return P.phase3_edge_system(g, theta, unc, dg, g.tails - 1, g.heads - 1, information=information,
                                    delta_reg=delta_reg), unc, dg

    one, unc, dg = build()
    monkeypatch.setattr(stacks, "BLOCK", 7)
    many, _, _ = build()
    for name in ("A", "B", "c"):
        assert np.array_equal(getattr(one, name), getattr(many, name)), name
    if information == "marginal":
        S = np.array([[0.0, -1.0], [1.0, 0.0]])
        U = unc.sqrt_info_delta_l
        URt = U @ np.swapaxes(rot2(theta[g.tails]), 1, 2)
        USdl = np.einsum("kab,kb->ka", U, g.delta_l @ S.T)
        th_i = theta[g.tails]
        scale = np.abs(one.A).max()
        assert np.abs(one.B[:, :2, :2] - URt).max() <= 1e-14 * scale
        assert np.abs(one.A[:, :2, 2] + USdl).max() <= 1e-14 * scale
        c_ref = np.einsum("kab,kb->ka", URt, dg) - USdl * th_i[:, None]
        assert np.abs(one.c[:, :2] - c_ref).max() <= 1e-13 * np.abs(c_ref).max()


def test_errors_and_chi2_are_the_same_in_blocks(monkeypatch):
    """Edge errors (eq. (3)) and χ² over blocks of 7 edges equal those over one block (χ² to 1e-13: the
    sum is taken block by block)."""
    g = _full_info_graph(70, seed=2)
    poses = np.random.default_rng(0).standard_normal((g.n_poses, 3))
    e1, c1 = edge_errors(g, poses), chi2(g, poses)
    monkeypatch.setattr(stacks, "BLOCK", 7)
    e2, c2 = edge_errors(g, poses), chi2(g, poses)
    assert np.array_equal(e1, e2)
    assert c2 == pytest.approx(c1, rel=1e-13)
    assert c1 == pytest.approx(float(np.einsum("ka,kab,kb->", e1, g.information, e1)), rel=1e-13)
