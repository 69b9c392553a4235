r"""LAGO's three phases (the seed's Section IV-B–D), each as an explicit cvxpy problem *and* a sparse
closed form, side by side so a reader sees they are the same least-squares problem.

Sizes: n = ``graph.n_poses`` poses (one of them the anchor, fixed at the origin of its own frame),
m edges, d = n − 1 free poses. Free poses are ordered as the rows of A2 (``graph.free_poses``).

Edge uncertainty (the seed assumes P_ij = blkdiag(P_Δ, P_δ); real files carry a full 3×3 information
Ω_ij with x–θ and y–θ cross terms). We use the **marginal covariances** of the full matrix:
Σ = Ω⁻¹, P_Δ,ij = Σ[0:2, 0:2], P_δ,ij = Σ[2, 2]. This keeps each measurement's own accuracy exactly
and drops only the Δˡ–δ correlation, which the seed's phase-3 model (z = [Δᵍ; θ̂], P_z from independent
Δˡ and δ) does not carry. Known consequence (tests/test_properties.py, strict xfails): with strongly
correlated information — full 3×3 matrices, or edges reversed (which turns diagonal information into
a correlated one) — the estimate is not first-order optimal and depends on edge direction (χ² up to
2.3× the optimum on random full-information graphs; on the real files the effect is ≤ 1 %). A phase 3
that keeps each edge's full information in one joint linear step removes it (prototyped; not yet here). P_Δ is expressed in the
frame of the tail (as Δˡ is) and rotated into the global frame by R(θ̂_i) exactly as eq. (10) says.

Phase 1 — eqs. (8), (13). Orientations: minimise ‖P_δ^{-1/2}(A2ᵀθ − δ_reg)‖², θ ∈ ℝ^d.
    θ̂ = (A2 P_δ⁻¹ A2ᵀ)⁻¹ A2 P_δ⁻¹ δ_reg,    information Ω_θ = P_θ⁻¹ = A2 P_δ⁻¹ A2ᵀ (d × d, sparse).

Phase 2 — eqs. (9)–(11). Rotate each relative position into the global frame,
    Δᵍ_ij = R(θ̂_i) Δˡ_ij,     z = [Δᵍ; θ̂] ∈ ℝ^{2m+d},
and propagate to first order: with J = ∂Δᵍ/∂θ̂ (eq. (11); row block of edge ij, column of pose i:
S R(θ̂_i) Δˡ_ij = S Δᵍ_ij, S = [[0, −1], [1, 0]]),
    P_z = G blkdiag(P_Δ, P_θ) Gᵀ,   G = [[R, J], [0, I]],   R = blkdiag_k R(θ̂_{i_k}).
P_z is dense (it contains P_θ), but its inverse is not: since G⁻¹ = [[Rᵀ, −RᵀJ], [0, I]] and
P_θ⁻¹ = (P_δ^{-1/2}A2ᵀ)ᵀ(P_δ^{-1/2}A2ᵀ),
    P_z⁻¹ = WᵀW,   W = [[P_Δ^{-1/2} Rᵀ, −P_Δ^{-1/2} Rᵀ J], [0, P_δ^{-1/2} A2ᵀ]]   (3m × (2m+d), sparse),
where RᵀJ has the blocks R(θ̂_i)ᵀ S R(θ̂_i) Δˡ_ij = S Δˡ_ij (rotations commute with S), and
P_Δ^{-1/2} is any square root with (P_Δ^{-1/2})ᵀP_Δ^{-1/2} = P_Δ⁻¹ (upper Cholesky factor here).

Phase 3 — eqs. (12), (15). Joint WLS for x = [p; θ] ∈ ℝ^{3d} (p interleaved x₁, y₁, x₂, y₂, …):
    z = Bᵀx + noise,   Bᵀ = blkdiag(A2ᵀ ⊗ I₂, I_d)   ((2m+d) × 3d),
    x* = (B P_z⁻¹ Bᵀ)⁻¹ B P_z⁻¹ z = argmin ‖W (z − Bᵀx)‖²,     information Ω* = B P_z⁻¹ Bᵀ.
Written out, the first 2m rows of W(z − Bᵀx) are P_Δ^{-1/2}R(θ̂_i)ᵀ[R(θ̂_i)Δˡ − (p_j − p_i) − SR(θ̂_i)Δˡ(θ̂_i − θ_i)]:
the *global-frame* relative-position error p_j − p_i − R(θ_i)Δˡ linearised in θ at θ̂ and weighted by
(R(θ̂_i)P_ΔR(θ̂_i)ᵀ)⁻¹. Phase 3 is therefore exactly one Gauss–Newton step, from (any p, θ̂), of the cost
written with that global-frame residual (plus the phase-1 orientation term); it is linear in p, so the
starting p does not matter (Remark 1, verified in lecture 04). With the local-frame residual
R(θ_i)ᵀ(p_j − p_i) − Δˡ of ``lago_cvx.cost`` (equivalent at the solution, not in its linearization) a
GN step depends on the starting p.

cvxpy objectives are written ``cp.sum_squares(W @ r)`` with sparse whitening W (never ``quad_form``)
and solved with Clarabel using ``CLARABEL_SETTINGS``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from .graph import free_poses, reduced_incidence
from .linalg import Factor, block_diagonal_inverse, factorize, solve_least_squares, whitening_2x2
from .posegraph import PoseGraph, rot2

__all__ = [
    "CLARABEL_SETTINGS", "EdgeUncertainty", "edge_uncertainty",
    "Phase1", "phase1_problem", "phase1_closed_form", "phase1_from_problem",
    "Phase2", "phase2",
    "Phase3", "design_matrix", "phase3_problem", "phase3_closed_form", "phase3_from_problem",
    "solve_problem",
]

log = logging.getLogger(__name__)

#: Clarabel settings used by every cvxpy phase. The defaults (static regularization 1e-8, gaps 1e-8)
#: leave ~1e-7 relative disagreement with the closed form on large graphs; a tiny static
#: regularization plus iterative refinement and tight tolerances give ~1e-12 agreement.
CLARABEL_SETTINGS = {
    "static_regularization_constant": 1e-11,
    "iterative_refinement_enable": True,
    "iterative_refinement_reltol": 1e-15,
    "iterative_refinement_abstol": 1e-15,
    "iterative_refinement_max_iter": 50,
    "tol_gap_abs": 1e-12,
    "tol_gap_rel": 1e-12,
    "tol_feas": 1e-12,
    "max_iter": 100,
}

_S = np.array([[0.0, -1.0], [1.0, 0.0]])


def solve_problem(problem: cp.Problem, *, settings: dict | None = None, verbose: bool = False) -> float:
    """Solve a cvxpy problem with Clarabel (``settings`` override ``CLARABEL_SETTINGS``); raise
    ``RuntimeError`` naming the status if it is not optimal. Returns the optimal value."""
    opts = dict(CLARABEL_SETTINGS)
    opts.update(settings or {})
    value = problem.solve(solver=cp.CLARABEL, verbose=verbose, **opts)
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise RuntimeError(f"Clarabel did not solve the problem: status {problem.status!r}")
    if problem.status == cp.OPTIMAL_INACCURATE:
        log.warning("Clarabel reports an inaccurate solution (status %s)", problem.status)
    return value


# --------------------------------------------------------------------------- uncertainty
@dataclass(frozen=True, eq=False)
class EdgeUncertainty:
    """Per-edge marginal uncertainties (see the module docstring).

    ``cov_delta_l`` (m, 2, 2) P_Δ,ij in the tail's frame; ``var_delta`` (m,) P_δ,ij;
    ``sqrt_info_delta_l`` (m, 2, 2) upper-triangular U with UᵀU = P_Δ,ij⁻¹;
    ``sqrt_info_delta`` (m,) 1/√P_δ,ij."""

    cov_delta_l: np.ndarray
    var_delta: np.ndarray
    sqrt_info_delta_l: np.ndarray
    sqrt_info_delta: np.ndarray


def edge_uncertainty(graph: PoseGraph) -> EdgeUncertainty:
    """Marginal covariances of Δˡ and δ from each edge's full information matrix (shapes above)."""
    cov = graph.covariance
    cov_l = cov[:, :2, :2]
    var_d = cov[:, 2, 2].copy()
    info_l = np.linalg.inv(cov_l) if graph.n_edges else np.zeros((0, 2, 2))
    info_l = 0.5 * (info_l + np.swapaxes(info_l, 1, 2))
    return EdgeUncertainty(cov_delta_l=cov_l, var_delta=var_d, sqrt_info_delta_l=whitening_2x2(info_l),
                           sqrt_info_delta=1.0 / np.sqrt(var_d))


def _full(n: int, anchor: int, free_values: np.ndarray, anchor_value=0.0) -> np.ndarray:
    out = np.empty(n)
    out[anchor] = anchor_value
    out[free_poses(n, anchor)] = free_values
    return out


# ------------------------------------------------------------------------------ phase 1
@dataclass(frozen=True, eq=False)
class Phase1:
    """Phase-1 result. ``theta`` (n,) with the anchor at 0; ``theta_free`` (d,);
    ``info`` (d, d) sparse Ω_θ = A2 P_δ⁻¹ A2ᵀ; ``factor`` its factorization and ``stats`` the solver's
    refinement statistics (closed form only)."""

    theta: np.ndarray
    theta_free: np.ndarray
    info: sp.csr_matrix
    anchor: int
    factor: Factor | None = None
    stats: dict | None = None

    def variances(self) -> np.ndarray:
        """Marginal variances of θ̂ (n,), diag(P_θ) with 0 at the anchor, without forming P_θ."""
        f = self.factor or factorize(self.info)
        d = self.theta_free.size
        var = block_diagonal_inverse(f, np.arange(d)[:, None])[:, 0, 0]
        return _full(d + 1, self.anchor, var)


def _phase1_terms(graph: PoseGraph, delta_reg: np.ndarray, unc: EdgeUncertainty, anchor: int):
    A2 = reduced_incidence(graph, anchor)  # (d, m)
    W = sp.diags(unc.sqrt_info_delta)  # P_δ^{-1/2}, (m, m)
    return A2, W, np.asarray(delta_reg, dtype=float)


def phase1_problem(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, *, anchor: int = 0):
    """Phase 1 as a cvxpy problem (eq. (13)): minimise ‖P_δ^{-1/2}(A2ᵀθ − δ_reg)‖² over θ ∈ ℝ^d.

    Returns ``(problem, theta)``; add constraints with ``cp.Problem(problem.objective, [...])``."""
    A2, W, d_reg = _phase1_terms(graph, delta_reg, unc, anchor)
    theta = cp.Variable(A2.shape[0], name="theta")
    residual = A2.T @ theta - d_reg
    return cp.Problem(cp.Minimize(cp.sum_squares(W @ residual))), theta


def phase1_closed_form(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, *, anchor: int = 0,
                       backend: str = "auto") -> Phase1:
    """Phase 1 in closed form (eq. (13)): θ̂ = (A2 P_δ⁻¹ A2ᵀ)⁻¹ A2 P_δ⁻¹ δ_reg by a sparse factorization
    (with corrected semi-normal refinement, see ``lago_cvx.linalg.solve_least_squares``)."""
    A2, W, d_reg = _phase1_terms(graph, delta_reg, unc, anchor)
    M = (W @ A2.T).tocsc()  # whitened design, (m, d)
    theta_free, info, factor, stats = solve_least_squares(M, unc.sqrt_info_delta * d_reg, backend=backend)
    return Phase1(_full(graph.n_poses, anchor, theta_free), theta_free, info.tocsr(), anchor, factor, stats)


def phase1_from_problem(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, *, anchor: int = 0,
                        settings: dict | None = None) -> tuple[Phase1, cp.Problem]:
    """Build and solve the phase-1 cvxpy problem with Clarabel; returns (Phase1, problem)."""
    problem, theta = phase1_problem(graph, delta_reg, unc, anchor=anchor)
    if theta.size == 0:  # a single pose: nothing to estimate (cvxpy cannot build an empty problem)
        return phase1_closed_form(graph, delta_reg, unc, anchor=anchor), problem
    solve_problem(problem, settings=settings)
    A2, W, _ = _phase1_terms(graph, delta_reg, unc, anchor)
    M = W @ A2.T
    tf = np.asarray(theta.value, dtype=float)
    return Phase1(_full(graph.n_poses, anchor, tf), tf, (M.T @ M).tocsr(), anchor), problem


# ------------------------------------------------------------------------------ phase 2
@dataclass(frozen=True, eq=False)
class Phase2:
    """Phase-2 quantities. ``delta_g`` (m, 2) Δᵍ = R(θ̂_i)Δˡ; ``z`` (2m + d,) = [Δᵍ (interleaved); θ̂_free];
    ``W`` sparse (3m, 2m + d) with WᵀW = P_z⁻¹; ``jac`` sparse (2m, d) J of eq. (11)."""

    delta_g: np.ndarray
    z: np.ndarray
    W: sp.csr_matrix
    jac: sp.csr_matrix
    anchor: int

    def covariance_z(self) -> np.ndarray:
        """Dense P_z = (WᵀW)⁻¹ — for small-graph checks and lectures only."""
        return np.linalg.inv((self.W.T @ self.W).toarray())


def phase2(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, *, anchor: int = 0) -> Phase2:
    """Phase 2 (eqs. (9)–(11)): z and the sparse square-root information W of P_z (module docstring).

    ``theta`` (n,) the phase-1 orientations (anchor at 0). No optimisation happens here; the same
    code serves both the closed form and the cvxpy route."""
    n, m = graph.n_poses, graph.n_edges
    d = n - 1
    free = free_poses(n, anchor)
    col_of = np.full(n, -1, np.int64)
    col_of[free] = np.arange(d)
    Ri = rot2(theta[graph.tails])  # (m, 2, 2)
    delta_g = np.einsum("kab,kb->ka", Ri, graph.delta_l)  # eq. (9)
    z = np.concatenate([delta_g.reshape(-1), theta[free]])

    # J (eq. (11)): rows 2k, 2k+1; column of the tail (absent when the tail is the anchor).
    k = np.arange(m)
    tail_col = col_of[graph.tails]
    has = tail_col >= 0
    Sdg = delta_g @ _S.T  # S Δᵍ, (m, 2)
    jac = sp.csr_matrix((Sdg[has].reshape(-1),
                         (np.stack([2 * k[has], 2 * k[has] + 1], 1).reshape(-1), np.repeat(tail_col[has], 2))),
                        shape=(2 * m, d))

    # W, first block row: [P_Δ^{-1/2} Rᵀ, −P_Δ^{-1/2} S Δˡ e_iᵀ]
    U = unc.sqrt_info_delta_l  # (m, 2, 2)
    URt = U @ np.swapaxes(Ri, 1, 2)  # (m, 2, 2)
    rows_a = np.repeat(np.stack([2 * k, 2 * k + 1], 1), 2, axis=1).reshape(-1)  # (4m,)
    cols_a = np.tile(np.stack([2 * k, 2 * k + 1], 1), (1, 2)).reshape(-1)
    USdl = -np.einsum("kab,kb->ka", U, graph.delta_l @ _S.T)  # −U S Δˡ, (m, 2)
    rows_b = np.stack([2 * k[has], 2 * k[has] + 1], 1).reshape(-1)
    cols_b = 2 * m + np.repeat(tail_col[has], 2)
    # second block row: P_δ^{-1/2} A2ᵀ
    A2 = reduced_incidence(graph, anchor)
    Lt = (sp.diags(unc.sqrt_info_delta) @ A2.T).tocoo()
    rows = np.concatenate([rows_a, rows_b, 2 * m + Lt.row])
    cols = np.concatenate([cols_a, cols_b, 2 * m + Lt.col])
    vals = np.concatenate([URt.reshape(-1), USdl[has].reshape(-1), Lt.data])
    W = sp.csr_matrix((vals, (rows, cols)), shape=(3 * m, 2 * m + d))
    return Phase2(delta_g=delta_g, z=z, W=W, jac=jac, anchor=anchor)


# ------------------------------------------------------------------------------ phase 3
@dataclass(frozen=True, eq=False)
class Phase3:
    """Phase-3 result. ``x_star`` (3d,) = [p (interleaved); θ]; ``poses`` (n, 3) with the anchor at the
    origin; ``info`` sparse (3d, 3d) Ω* = B P_z⁻¹ Bᵀ; ``factor`` its factorization and ``stats`` the
    solver's refinement statistics (closed form only)."""

    x_star: np.ndarray
    poses: np.ndarray
    info: sp.csr_matrix
    anchor: int
    factor: Factor | None = None
    stats: dict | None = None

    def pose_covariances(self) -> np.ndarray:
        """Marginal 3×3 covariance of every pose (n, 3, 3), order (x, y, θ), zeros at the anchor.

        Selected blocks of (Ω*)⁻¹ by batched sparse solves — no dense inverse."""
        n = self.poses.shape[0]
        d = n - 1
        f = self.factor or factorize(self.info)
        r = np.arange(d)
        blocks = block_diagonal_inverse(f, np.stack([2 * r, 2 * r + 1, 2 * d + r], 1))
        out = np.zeros((n, 3, 3))
        out[free_poses(n, self.anchor)] = blocks
        return out


def design_matrix(graph: PoseGraph, *, anchor: int = 0) -> sp.csr_matrix:
    """Bᵀ = blkdiag(A2ᵀ ⊗ I₂, I_d), shape (2m + d, 3d) (eq. (12)): maps x = [p; θ] to [Δp; θ]."""
    A2 = reduced_incidence(graph, anchor)
    d = A2.shape[0]
    return sp.block_diag([sp.kron(A2.T, sp.identity(2)), sp.identity(d)], format="csr")


def phase3_problem(graph: PoseGraph, ph2: Phase2, *, anchor: int = 0):
    """Phase 3 as a cvxpy problem (eq. (15)): minimise ‖W (z − Bᵀx)‖² over x = [p; θ] ∈ ℝ^{3d}.

    Returns ``(problem, x)``; positions are ``x[:2d]`` (interleaved), orientations ``x[2d:]``."""
    Bt = design_matrix(graph, anchor=anchor)
    x = cp.Variable(Bt.shape[1], name="x")
    return cp.Problem(cp.Minimize(cp.sum_squares(ph2.W @ (ph2.z - Bt @ x)))), x


def _poses_from_x(n: int, anchor: int, x: np.ndarray) -> np.ndarray:
    d = n - 1
    poses = np.zeros((n, 3))
    free = free_poses(n, anchor)
    poses[free, :2] = x[:2 * d].reshape(d, 2)
    poses[free, 2] = x[2 * d:]
    return poses


def phase3_closed_form(graph: PoseGraph, ph2: Phase2, *, anchor: int = 0, backend: str = "auto") -> Phase3:
    """Phase 3 in closed form: x* = (B WᵀW Bᵀ)⁻¹ B WᵀW z, the least-squares solution of
    M x ≈ W z with M = W Bᵀ (3m × 3d), by a sparse factorization of MᵀM with corrected semi-normal
    refinement (``lago_cvx.linalg.solve_least_squares``)."""
    M = (ph2.W @ design_matrix(graph, anchor=anchor)).tocsc()  # (3m, 3d)
    x, info, factor, stats = solve_least_squares(M, ph2.W @ ph2.z, backend=backend)
    return Phase3(x, _poses_from_x(graph.n_poses, anchor, x), info.tocsr(), anchor, factor, stats)


def phase3_from_problem(graph: PoseGraph, ph2: Phase2, *, anchor: int = 0,
                        settings: dict | None = None) -> tuple[Phase3, cp.Problem]:
    """Build and solve the phase-3 cvxpy problem with Clarabel; returns (Phase3, problem)."""
    problem, x = phase3_problem(graph, ph2, anchor=anchor)
    if x.size == 0:  # a single pose
        return phase3_closed_form(graph, ph2, anchor=anchor), problem
    solve_problem(problem, settings=settings)
    xv = np.asarray(x.value, dtype=float)
    M = ph2.W @ design_matrix(graph, anchor=anchor)
    return Phase3(xv, _poses_from_x(graph.n_poses, anchor, xv), (M.T @ M).tocsr(), anchor), problem
