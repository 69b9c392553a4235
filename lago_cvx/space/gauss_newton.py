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
when the Gauss–Newton step does not decrease χ² (``refine3d``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import check_choice
from ..sparse import factorize
from ..posegraph3d import chi2_3d, g2o_errors_and_derivative, log_errors
from ..so3 import adjoint, exp_so3, right_jacobian_inverse
from .blocks import edge_matrix, factor, free_index, per_graph

__all__ = ["REFINE_METHODS", "jacobians", "normal_equations", "retract", "gauss_newton_step", "Refined3D",
           "refine3d"]

REFINE_METHODS = ("levenberg-marquardt", "gauss-newton")


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


@dataclass(frozen=True, eq=False)
class Refined3D:
    """A refined 3-D estimate: ``t`` (n, 3), ``R`` (n, 3, 3), ``chi2``, ``iterations``, ``converged`` (relative χ²
    decrease below the tolerance, or a step below it), ``log``: one dict per iteration (chi2, lambda, time)."""

    t: np.ndarray
    R: np.ndarray
    chi2: float
    iterations: int
    converged: bool
    log: tuple


def refine3d(graph, t, R, *, cost: str | None = None, method: str = "levenberg-marquardt", anchor: int | None = None,
             max_iterations: int = 100, tolerance: float = 1e-12, initial_lambda: float = 1e-5) -> Refined3D:
    """Refine poses (t (n, 3), R (n, 3, 3)) on the χ² of ``cost`` (None: the graph's, ``graph.cost``; ``"g2o"`` or
    ``"gtsam"``, module docstring), with that cost's exact errors and Jacobians.

    Every iteration first tries the Gauss–Newton step, solved on the pose-level elimination shared by the closed
    forms (``gauss_newton_step``). ``"gauss-newton"`` takes it when χ² decreases; ``"levenberg-marquardt"`` then
    falls back to damped steps (JᵀΩJ + λ diag(JᵀΩJ)) δ = −JᵀΩe through ``linalg.factorize``, λ from
    ``initial_lambda`` up (×10 per rejected step, ÷10 after an accepted damped one) until χ² decreases. Ends when χ²
    decreases by less than ``tolerance`` relative (or the step moves no pose by more than ``tolerance``), after
    ``max_iterations``, or when no step decreases χ² (λ beyond 1e10): that step is not taken, and the result counts
    as converged if the increase was within 1e-9 relative (rounding at a minimum). ``anchor``: the pose id held
    fixed (default: smallest id)."""
    from ..sparse import GraphElimination

    check_choice("method", method, REFINE_METHODS)
    if cost is not None:
        graph = graph.with_cost(cost)
    a = graph.anchor_index(anchor)
    t, R = graph.check_poses(t, R)
    L = whitening(graph)
    cost = chi2_3d(graph, t, R)
    lam = initial_lambda
    log, converged, it = [], graph.n_poses == 1 or graph.n_edges == 0, 0
    el = None if converged else GraphElimination(graph, a)
    start = time.perf_counter()
    while not converged and it < max_iterations:
        it += 1
        delta = gauss_newton_step(graph, t, R, anchor_index=a, L=L, elimination=el)
        t2, R2 = retract(t, R, delta, a)
        new = chi2_3d(graph, t2, R2)
        used = 0.0
        if not new <= cost and method == "levenberg-marquardt":
            N, g, _ = normal_equations(graph, t, R, L, a)
            damping = sp.diags(N.diagonal(), format="csc")
            while not new <= cost and lam <= 1e10:
                delta = -factorize((N + lam * damping).tocsc()).solve(g)
                t2, R2 = retract(t, R, delta, a)
                new = chi2_3d(graph, t2, R2)
                used = lam
                lam = lam / 10.0 if new <= cost else lam * 10.0
        if not new <= cost:  # no decrease at any damping: a minimum to working precision
            converged = (new - cost) <= 1e-9 * cost
            break
        small = np.abs(delta).max() <= tolerance if delta.size else True
        converged = small or (cost - new) <= tolerance * max(cost, 1e-300)
        t, R, cost = t2, R2, new
        log.append({"iteration": it, "chi2": cost, "lambda": used, "time": time.perf_counter() - start})
    return Refined3D(t, R, float(cost), it, bool(converged), tuple(log))
