r"""The positions at fixed rotations, exactly: the 3-D counterpart of ``lago_cvx.positions``.

At fixed rotations R_i the error of edge ij (:mod:`lago_cvx.posegraph3d`), e = (e_v, r), has a fixed rotational part
r_ij and a translational part **affine** in the positions. With E = T̃_ij⁻¹T_i⁻¹T_j, G = R_iR̃_ij and
t_E = Gᵀ(t_j − t_i) − R̃_ijᵀ t̃_ij:

* g2o's cost: e_v = t_E and r = q_v(R̃ᵀR_iᵀR_j), the quaternion's vector part (w ≥ 0);
* GTSAM's cost: e_v = V(φ)⁻¹ t_E and r = φ = Log(R̃ᵀR_iᵀR_j)                     (lago_cvx.so3: Log of SE(3)).

So e_v = U (Gᵀ(t_j − t_i) − R̃ᵀt̃) with U = I (g2o) or V(φ)⁻¹ (GTSAM). With the full 6×6 information
Ω = [[Ω_tt, Ω_tr], [Ω_rt, Ω_rr]],

    eᵀΩe = (e_v + Ω_tt⁻¹Ω_tr r)ᵀ Ω_tt (e_v + Ω_tt⁻¹Ω_tr r) + rᵀ(Ω_rr − Ω_rtΩ_tt⁻¹Ω_tr)r,

so χ² over the positions is the linear least-squares problem

    min_t Σ_ij ‖L_ij (B_ij (t_j − t_i) − c_ij)‖²                                                       (P)

with B = U Gᵀ, c = U R̃ᵀt̃ − Ω_tt⁻¹Ω_tr r and LᵀL = Ω_tt, the anchor's position fixed: its solution is the exact
minimizer of the graph's χ² at these rotations (χ² itself, in either cost, not an approximation of it).
"""

from __future__ import annotations

import numpy as np

from ..posegraph3d import edge_rotations
from ..so3 import apply, entries, log_rotations, matrices, product, quaternions, transposed, v_inverse_entries
from .blocks import edge_matrix, free_index, per_graph, solve, without_anchor

__all__ = ["position_system", "positions_closed_form", "position_problem", "positions_cvxpy"]


def _edge_constants(graph):
    """(L with LᵀL = Ω_tt, upper triangular; Ω_tt⁻¹Ω_tr), each as its (9, m) rows (``so3.entries``): what (P) takes
    from the information at any rotations, computed once per graph (``blocks.per_graph``; the route solves (P) at
    least twice)."""
    def compute(graph):
        O = graph.information
        Ott = O[:, :3, :3]
        L, K = np.swapaxes(np.linalg.cholesky(Ott), 1, 2), np.linalg.solve(Ott, O[:, :3, 3:])
        return np.ascontiguousarray(L.reshape(-1, 9).T), np.ascontiguousarray(K.reshape(-1, 9).T)

    return per_graph(graph, "positions", compute)


def _whitened_edges(graph, R):
    """(L B (m, 3, 3), L c (m, 3)) of (P) at rotations R (n, 3, 3), entry by entry over the edges
    (``so3.entries``): with G = R_i R̃, E = Gᵀ R_j (``posegraph3d.edge_rotations``), B = U Gᵀ and
    c = U R̃ᵀ t̃ − Ω_tt⁻¹Ω_tr r; g2o's cost: U = I, r = q_v(E); GTSAM's: U = V(φ)⁻¹, r = φ = Log E."""
    GT, E = edge_rotations(graph, R)
    L, K = (entries(rows) for rows in _edge_constants(graph))
    Mt_t = apply(transposed(entries(graph.delta_R)), np.ascontiguousarray(graph.delta_t.T))
    if graph.cost == "g2o":
        r = list(quaternions(E)[:3])
        B, Ut = GT, Mt_t
    else:
        r = log_rotations(E)
        Vi = v_inverse_entries(r)
        B, Ut = product(Vi, GT), apply(Vi, Mt_t)
    c = [a - b for a, b in zip(Ut, apply(K, r))]
    return matrices(product(L, B)), np.ascontiguousarray(np.array(apply(L, c)).T)


def position_system(graph, R, *, anchor_index: int = 0, anchor_position=(0.0, 0.0, 0.0)):
    """(M, b) of (P) whitened, in the free positions: M (3m × 3(n−1)), b (3m,)."""
    LB, Lc = _whitened_edges(graph, R)
    M = edge_matrix(graph.tails, graph.heads, LB, -LB, graph.n_poses)
    M, b = without_anchor(M, Lc.ravel(), anchor_index, 3, np.asarray(anchor_position, dtype=float))
    return M.tocsc(), np.asarray(b)


def _assemble(graph, x, anchor_index, anchor_position) -> np.ndarray:
    t = np.empty((graph.n_poses, 3))
    t[anchor_index] = anchor_position
    t[free_index(graph.n_poses, 3, anchor_index)[::3] // 3] = x.reshape(-1, 3)
    return t


def positions_closed_form(graph, R, *, anchor_index: int = 0, anchor_position=(0.0, 0.0, 0.0), elimination=None):
    """(t (n, 3), stats): (P) on the pose-level elimination shared by the closed forms
    (``normal_equations.GraphElimination``, as ``chordal.chordal_closed_form``); ``elimination`` one built already
    for this graph and anchor."""
    from ..sparse import EdgeSystem, GraphElimination

    if graph.n_poses == 1:
        return np.array([anchor_position], dtype=float), {"method": "trivial"}
    el = GraphElimination(graph, anchor_index) if elimination is None else elimination
    LB, Lc = _whitened_edges(graph, R)
    p = np.asarray(anchor_position, dtype=float)
    ta, he = el.tails < 0, el.heads < 0
    Lc[ta] += LB[ta] @ p  # residual −LB t_i + LB t_j − Lc: the anchor's known term moves to the right
    Lc[he] -= LB[he] @ p
    x, _, stats = solve(el, EdgeSystem(el.tails, el.heads, -LB, np.ascontiguousarray(LB), Lc, el.d))
    return _assemble(graph, x, anchor_index, anchor_position), stats


def position_problem(graph, R, *, anchor_index: int = 0, anchor_position=(0.0, 0.0, 0.0)):
    """(P) as a cvxpy problem, ``minimize quad_over_lin(M @ t + -b, 1.0)``, and its variable t."""
    import cvxpy as cp

    from ..solvers import named_constant

    M, b = position_system(graph, R, anchor_index=anchor_index, anchor_position=anchor_position)
    t = cp.Variable(M.shape[1], name="t")
    return cp.Problem(cp.Minimize(cp.sum_squares(named_constant(M, "M") @ t - named_constant(b, "b")))), t


def positions_cvxpy(graph, R, *, anchor_index: int = 0, anchor_position=(0.0, 0.0, 0.0), settings=None):
    """(t (n, 3), stats): (P) solved by Clarabel (``solvers.solve``)."""
    from ..solvers import solve

    if graph.n_poses == 1:
        return np.array([anchor_position], dtype=float), {"method": "trivial"}
    problem, t = position_problem(graph, R, anchor_index=anchor_index, anchor_position=anchor_position)
    status = solve(problem, settings, what="the 3-D positions")
    return _assemble(graph, np.asarray(t.value), anchor_index, anchor_position), {"method": "cvxpy", "status": status}
