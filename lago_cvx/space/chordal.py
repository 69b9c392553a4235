r"""Rotations by the chordal relaxation (Carlone, Tron, Daniilidis, Dellaert, ICRA 2015, eq. (9)).

The problem
===========
With the anchor's rotation fixed (R_a = I), find the rotations minimizing

    Σ_ij ‖(R_j − R_i R̃_ij) S_ij‖²_F                                                   (C)

over **all 3×3 matrices** R_i — the constraint R_i ∈ SO(3) is dropped (relaxed), so (C) is a linear least-squares
problem — and project each solution onto SO(3) (``lago_cvx.so3.project_so3``: the SVD, determinant fixed). In 3-D
there is no 2kπ to regularize: a rotation *matrix* does not wrap, so the chordal distance ‖R_j − R_iR̃_ij‖ needs no
integer, unlike the planar angle differences of LAGO's phase 1.

Rows of R: one system, three right-hand sides
---------------------------------------------
Right multiplication by S_ij mixes columns only, so row k of R_j − R_iR̃_ij, (r_j^k − r_i^k R̃_ij) S_ij, involves row k
of every rotation and nothing else: with x_i = (r_i^k)ᵀ the residual is S_ij (x_j − R̃_ijᵀ x_i). The three rows are
three least-squares problems with **the same matrix**: M X = B in the stacked transposes X = [R_1ᵀ; …; R_nᵀ]
(3n × 3, the anchor's block moved to B), factored once, solved for three right-hand sides.

The weights
===========
Near the optimum R_j = R_iR̃_ij Exp(φ_ij), φ the rotational Log error, weighed by the rotation block Ω_rr of the
edge's information in Log coordinates (``posegraph3d.information_in_log_coordinates``: Ω itself for GTSAM's cost,
¼ of the file's block for g2o's, whose rotational error is q_v ≈ φ/2), and R_j − R_iR̃_ij ≈ R_iR̃_ij [φ]×. For
symmetric W = S²,

    ‖[φ]× S‖²_F = tr(S [φ]×ᵀ[φ]× S) = φᵀ (tr(W) I − W) φ,          since [φ]×ᵀ[φ]× = ‖φ‖²I − φφᵀ.

* ``"isotropic"`` (SE-Sync's κ, Rosen et al. IJRR 2019, §6): S = √κ I with κ = 3 / (2 tr(Ω_rr⁻¹)). Then (C) ≈
  ω‖φ‖² with ω = 3/tr(Ω_rr⁻¹): the isotropic Gaussian closest (in KL divergence) to N(0, Ω_rr⁻¹) has variance
  tr(Ω_rr⁻¹)/3 per axis.
* ``"anisotropic"``: W = ½ tr(Ω_rr) I − Ω_rr, so that tr(W) I − W = Ω_rr and (C) ≈ φᵀ Ω_rr φ exactly to second order.
  W is positive semidefinite only while Ω_rr's largest eigenvalue is at most the sum of the other two; beyond, its
  negative eigenvalues are raised to :data:`ANISOTROPIC_FLOOR` times ½ tr(Ω_rr) (the edge then weighs its stiffest
  axis less than Ω_rr says). Right multiplication keeps rows separable; a weight that mixed rows (S R) would couple
  the three systems.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import check_choice
from ..posegraph3d import information_in_log_coordinates
from ..so3 import project_so3
from ..stacks import spd_inverse
from .blocks import block_diagonal, edge_matrix, free_index, solve, without_anchor

__all__ = ["WEIGHTINGS", "ANISOTROPIC_FLOOR", "rotation_weights", "chordal_system", "edge_system", "chordal_closed_form",
           "chordal_problem", "chordal_cvxpy", "Chordal", "relaxed_cost"]

WEIGHTINGS = ("isotropic", "anisotropic")
#: Where ½tr(Ω_rr) I − Ω_rr has negative eigenvalues, they are raised to this fraction of ½tr(Ω_rr).
ANISOTROPIC_FLOOR = 0.05


def rotation_weights(graph, weighting: str = "isotropic") -> np.ndarray:
    """S_ij (m, 3, 3), the square roots of the weights of (C) (module docstring)."""
    check_choice("weighting", weighting, WEIGHTINGS)
    Orr = information_in_log_coordinates(graph)[:, 3:, 3:]
    if weighting == "isotropic":
        kappa = 3.0 / (2.0 * np.trace(spd_inverse(Orr), axis1=1, axis2=2))
        return np.sqrt(kappa)[:, None, None] * np.eye(3)
    half = 0.5 * np.trace(Orr, axis1=1, axis2=2)
    lam, U = np.linalg.eigh(half[:, None, None] * np.eye(3) - Orr)
    lam = np.maximum(lam, ANISOTROPIC_FLOOR * half[:, None])
    return (U * np.sqrt(lam)[:, None, :]) @ np.swapaxes(U, 1, 2)


def chordal_system(graph, *, weighting: str = "isotropic", anchor_index: int = 0):
    """(A, W, B): (C) as min ‖W (A X − B)‖²_F over X = [R_iᵀ] of the free poses, shape (3(n−1), 3).

    A (3m × 3(n−1)): block row ij has I at column block j and −R̃_ijᵀ at i; W (3m × 3m) block diagonal with the
    S_ij; B (3m × 3): the anchor's columns times R_aᵀ = I, moved to the right-hand side."""
    n, m = graph.n_poses, graph.n_edges
    eye = np.broadcast_to(np.eye(3), (m, 3, 3))
    A = edge_matrix(graph.tails, graph.heads, eye, -np.swapaxes(graph.delta_R, 1, 2), n)
    A, B = without_anchor(A, np.zeros((3 * m, 3)), anchor_index, 3, np.eye(3))
    S = rotation_weights(graph, weighting)
    W = block_diagonal(S)
    return A.tocsc(), W, np.asarray(B)


@dataclass(frozen=True, eq=False)
class Chordal:
    """The chordal relaxation's answer: ``rotations`` (n, 3, 3) projected onto SO(3), ``relaxed`` (n, 3, 3) the
    minimizer of (C) before the projection, ``cost`` (C) at ``relaxed``, ``cost_projected`` (C) at ``rotations``,
    ``accuracy``: the solver's report (closed form: refinement steps and last correction; cvxpy: status)."""

    rotations: np.ndarray
    relaxed: np.ndarray
    cost: float
    cost_projected: float
    accuracy: dict


def relaxed_cost(A, W, B, X) -> float:
    """(C) = ‖W (A X − B)‖²_F at X (3(n−1), 3)."""
    r = W @ (A @ X - B)
    return float(np.sum(r * r))


def _finish(graph, X, anchor_index: int, accuracy: dict, cost) -> Chordal:
    """The rotations from X (3(n−1), 3) = [R_iᵀ] of the free poses; ``cost(X)`` evaluates (C)."""
    n = graph.n_poses
    relaxed = np.empty((n, 3, 3))
    relaxed[anchor_index] = np.eye(3)
    free = free_index(n, 3, anchor_index)[::3] // 3
    relaxed[free] = np.swapaxes(X.reshape(n - 1, 3, 3), 1, 2)
    R = project_so3(relaxed)
    R[anchor_index] = np.eye(3)
    Xp = np.swapaxes(R[free], 1, 2).reshape(-1, 3)
    return Chordal(R, relaxed, cost(X), cost(Xp), accuracy)


def edge_system(graph, elimination, *, weighting: str = "isotropic"):
    """(C) as the engine's ``normal_equations.EdgeSystem`` on ``elimination`` (a ``GraphElimination``): per edge
    the residual A_ij x_i + B_ij x_j − c_ij with A = −S R̃ᵀ, B = S, three right-hand sides c (m, 3, 3) that carry
    the anchor's known block R_aᵀ = I."""
    from ..sparse import EdgeSystem

    S = rotation_weights(graph, weighting)
    A = -S @ np.swapaxes(graph.delta_R, 1, 2)
    B = np.ascontiguousarray(S)
    c = np.zeros((graph.n_edges, 3, 3))
    ta, he = elimination.tails < 0, elimination.heads < 0
    c[ta] -= A[ta]
    c[he] -= B[he]
    return EdgeSystem(elimination.tails, elimination.heads, A, B, c, elimination.d)


def _system_cost(system):
    def cost(X):
        r = system.matvec(X.reshape(system.d, 3, 3)) - system.c
        return float(np.sum(r * r))
    return cost


def chordal_closed_form(graph, *, weighting: str = "isotropic", anchor_index: int = 0, elimination=None) -> Chordal:
    """(C) by one sparse factorization of its normal matrix and three solves, on the pose-level elimination shared
    by the closed forms (``sparse.GraphElimination.solve``: the engine's factorization; corrected semi-normal
    equations). ``elimination``: one built already for
    this graph and anchor."""
    from ..sparse import GraphElimination

    if graph.n_poses == 1:
        return _finish(graph, np.zeros((0, 3)), anchor_index, {"method": "trivial"}, lambda X: 0.0)
    el = GraphElimination(graph, anchor_index) if elimination is None else elimination
    system = edge_system(graph, el, weighting=weighting)
    x, _, stats = solve(el, system)
    return _finish(graph, x.reshape(-1, 3), anchor_index, stats, _system_cost(system))


def chordal_problem(graph, *, weighting: str = "isotropic", anchor_index: int = 0):
    """(C) as a cvxpy problem that prints like its equation, and its variable X:
    ``minimize quad_over_lin(W @ (A @ X + -B), 1.0)`` (cvxpy writes ‖·‖²_F = ``sum_squares`` that way)."""
    import cvxpy as cp

    from ..solvers import named_constant

    A, W, B = chordal_system(graph, weighting=weighting, anchor_index=anchor_index)
    X = cp.Variable((A.shape[1], 3), name="X")
    objective = cp.sum_squares(named_constant(W, "W") @ (named_constant(A, "A") @ X - named_constant(B, "B")))
    return cp.Problem(cp.Minimize(objective)), X, (A, W, B)


def chordal_cvxpy(graph, *, weighting: str = "isotropic", anchor_index: int = 0, settings=None) -> Chordal:
    """(C) solved by Clarabel through :func:`chordal_problem` (``solvers.solve``, preset ``LEAST_SQUARES``)."""
    from ..solvers import solve

    problem, X, (A, W, B) = chordal_problem(graph, weighting=weighting, anchor_index=anchor_index)

    def cost(Y):
        return relaxed_cost(A, W, B, Y)
    if graph.n_poses == 1:
        return _finish(graph, np.zeros((0, 3)), anchor_index, {"method": "trivial"}, lambda Y: 0.0)
    status = solve(problem, settings, what="the chordal relaxation (3-D rotations)")
    return _finish(graph, np.asarray(X.value), anchor_index, {"method": "cvxpy", "status": status}, cost)
