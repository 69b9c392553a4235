r"""Gauss–Newton and Levenberg–Marquardt on SE(3), with a right retraction (the 3-D refinement).

The cost is the graph's χ² = Σ e_ijᵀ Ω_ij e_ij, e_ij the error of its ``cost`` (:mod:`lago_cvx.posegraph3d`:
g2o's [t_E ; q_v] or GTSAM's Log(E), E = T̃_ij⁻¹ T_i⁻¹ T_j). A step δ = (δ_1, …, δ_n), δ_i = (δv_i, δφ_i) ∈ ℝ⁶,
moves each pose on the right:

    R_i ← R_i Exp(δφ_i),   t_i ← t_i + R_i δv_i        (= T_i Exp(δ_i) to first order)

A step of the head moves E to E·Exp(δ_j); a step of the tail moves it to Z⁻¹ Exp(−δ_i) T_i⁻¹T_j =
E·Exp(−Ad(T_j⁻¹T_i) δ_i). So with D = ∂e(E·Exp(η))/∂η at η = 0,

    ∂e/∂δ_j = D,     ∂e/∂δ_i = −D Ad(T_j⁻¹ T_i),

where D = J_r⁻¹(e), the inverse right Jacobian of SE(3) (``lago_cvx.so3.right_jacobian_inverse``), for GTSAM's
Log error, and D = blkdiag(R_E, ½(w I + [q_v]×)) for g2o's (``posegraph3d.g2o_error_derivative``).

Each iteration whitens the errors by Ω = LᵀL and solves the normal equations (JᵀΩJ + λ diag(JᵀΩJ)) δ = −JᵀΩe for
the free poses (the anchor stays put): the Gauss–Newton step (λ = 0) on the closed forms' pose-level elimination
(``normal_equations``; ``blocks.factor``), Levenberg–Marquardt's damped ones (λ > 0) through ``linalg.factorize``
when the Gauss–Newton step does not decrease χ² (the iterations, with anchors, priors and rotation constraints:
``space.refine``).
"""

from __future__ import annotations

import numpy as np

from ..posegraph3d import g2o_errors_and_derivative, log_errors
from ..so3 import adjoint, exp_so3, right_jacobian_inverse
from .blocks import edge_matrix, factor, free_index, per_graph

__all__ = ["jacobians", "normal_equations", "retract", "gauss_newton_step", "error_derivative", "whitening"]


def error_derivative(graph, t, R):
    """(e (m, 6), D (m, 6, 6)): the errors of the graph's cost and D = ∂e(E·Exp(η))/∂η at η = 0 (module
    docstring)."""
    if graph.cost == "gtsam":
        e = log_errors(graph, t, R)
        return e, right_jacobian_inverse(e)
    return g2o_errors_and_derivative(graph, t, R)


def jacobians(graph, t, R):
    """(e (m, 6), J_i (m, 6, 6), J_j (m, 6, 6)): the errors of the graph's cost and their Jacobians in the tail's
    and head's steps (module docstring)."""
    t, R = np.asarray(t, dtype=float), np.asarray(R, dtype=float)
    e, Jinv = error_derivative(graph, t, R)
    Ri, Rj = R[graph.tails], R[graph.heads]
    RjT = np.swapaxes(Rj, 1, 2)
    Rji = RjT @ Ri                                     # T_j⁻¹ T_i = (R_jᵀR_i, R_jᵀ(t_i − t_j))
    tji = np.einsum("kij,kj->ki", RjT, t[graph.tails] - t[graph.heads])
    return e, -Jinv @ adjoint(Rji, tji), Jinv


def whitening(graph) -> np.ndarray:
    """L (m, 6, 6) with LᵀL = Ω (upper triangular), computed once per graph (``blocks.per_graph``), read-only."""
    return per_graph(graph, "whitening", lambda g: np.swapaxes(np.linalg.cholesky(g.information), 1, 2))


def normal_equations(graph, t, R, L, anchor_index: int):
    """(N = JᵀΩJ, g = JᵀΩe) in the free poses' steps (sparse (6(n−1))², (6(n−1),)) and the errors e."""
    e, Ji, Jj = jacobians(graph, t, R)
    M = edge_matrix(graph.tails, graph.heads, L @ Jj, L @ Ji, graph.n_poses)
    M = M[:, free_index(graph.n_poses, 6, anchor_index)]
    r = np.einsum("kij,kj->ki", L, e).ravel()
    return (M.T @ M).tocsc(), M.T @ r, e


def retract(t, R, delta: np.ndarray, anchor_index: int):
    """Poses moved by the step ``delta`` (6(n−1),) of the free poses: R_i Exp(δφ_i), t_i + R_i δv_i."""
    n = t.shape[0]
    d = np.zeros((n, 6))
    d[free_index(n, 6, anchor_index)[::6] // 6] = delta.reshape(-1, 6)
    return t + np.einsum("kij,kj->ki", R, d[:, :3]), R @ exp_so3(d[:, 3:])


def gauss_newton_step(graph, t, R, *, anchor_index: int = 0, L=None, elimination=None) -> np.ndarray:
    """The Gauss–Newton step δ (6(n−1),) at (t, R): min ‖L (e + J δ)‖², i.e. (JᵀΩJ) δ = −JᵀΩe, on the pose-level
    elimination shared by the closed forms (``normal_equations.GraphElimination``; ``elimination`` one built
    already for this graph and anchor)."""
    from ..sparse import EdgeSystem, GraphElimination

    L = whitening(graph) if L is None else L
    el = GraphElimination(graph, anchor_index) if elimination is None else elimination
    e, Ji, Jj = jacobians(graph, t, R)
    system = EdgeSystem(el.tails, el.heads, L @ Ji, L @ Jj, -np.einsum("kij,kj->ki", L, e), el.d)
    # One factorization and one solve of the normal equations: a step needs no refinement to rounding (near a
    # minimum the gradient, hence the step, is tiny, and a correction relative to it would look untrustworthy).
    return factor(el, system).solve(system.rmatvec(system.c).ravel())
