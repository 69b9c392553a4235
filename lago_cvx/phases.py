r"""LAGO's three phases (the seed's Section IV-B–D), each as an explicit cvxpy problem *and* a sparse
closed form, side by side so a reader sees they are the same least-squares problem.

Sizes: n = ``graph.n_poses`` poses (one of them the anchor, fixed at the origin of its own frame),
m edges, d = n − 1 free poses. Free poses are ordered as the rows of A2 (``graph.free_poses``).

Edge uncertainty: ``lago_cvx.uncertainty`` (the marginal P_Δ, P_δ of each edge's information and its full
square root; P_Δ is expressed in the frame of the tail, as Δˡ is, and rotated into the global frame by
R(θ̂_i) exactly as eq. (10) says).

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
Written out, the first 2m rows of W(z − Bᵀx) are −P_Δ^{-1/2}R(θ̂_i)ᵀ d_k with
    d_k = p_j − p_i − R(θ̂_i)Δˡ − SR(θ̂_i)Δˡ(θ_i − θ̂_i),                                             (L)
the *global-frame* relative-position error p_j − p_i − R(θ_i)Δˡ linearised in θ at θ̂ and weighted by
(R(θ̂_i)P_ΔR(θ̂_i)ᵀ)⁻¹; the last d rows are ‖P_δ^{-1/2}A2ᵀ(θ − θ̂)‖², which differs from phase 1's cost
‖P_δ^{-1/2}(A2ᵀθ − δ_reg)‖² by a constant (θ̂ is its minimiser). Phase 3 is therefore exactly one
Gauss–Newton step, from (any p, θ̂), of the cost written with the global-frame residual — the
first-order expansion of eq. (18) whose minimiser gives the corrections of eqs. (16)–(17) — and it is
linear in p, so the starting p does not matter.

Full information (``information="full"``, beyond the seed). The split above weighs positions and
orientations separately, which is exact only for block-diagonal Ω (Remark 2). For any Ω the same
Gauss–Newton step uses each edge's *joint* residual
    r_k(x) = [d_k ;  θ_j − θ_i − δ_reg,k]   weighted by   Ω_g,k = T_k Ω_k T_kᵀ,   T_k = blkdiag(R(θ̂_i), 1),
since eᵀΩe = [d; e_θ]ᵀ T Ω Tᵀ [d; e_θ] with e = Tᵀ[d; e_θ] at θ_i = θ̂_i. In the same form as eq. (15),
    minimise ‖W_f (B_fᵀx − z_f)‖²,  W_f = blkdiag_k(U_k T_kᵀ)  (3m × 3m, U_kᵀU_k = Ω_k),
    B_fᵀ: rows of edge k = [[A2ᵀ⊗I₂]_k, −J_k; 0, (A2ᵀ)_k],   z_f,k = [Δᵍ_k − J_k θ̂ ; δ_reg,k]   (3m × 3d).
With block-diagonal Ω its cost differs from ‖W(z − Bᵀx)‖² by a constant, so x* and Ω* are the seed's
exactly (tests/test_phases.py); for any Ω it is one Gauss–Newton step of the full cost from a point
O(σ) away, so x* is O(σ²) from the optimum and χ²(LAGO)/χ²(min) → 1 as the noise vanishes
(tests/test_properties.py). The seed's form with the marginal P_Δ, P_δ (``information="marginal"``)
is not: its weights ignore the Δˡ–δ correlation, so its error stays O(σ) relative.

cvxpy objectives are written ``cp.sum_squares(W @ r)`` with sparse whitening W (never ``quad_form``)
and solved with Clarabel by ``lago_cvx.solvers.solve`` (preset ``LEAST_SQUARES``). cvxpy is imported
only when a ``*_problem`` function runs.

Anchors: every function takes ``anchor`` as a pose **id** (default the smallest); the results keep the
anchor's index in ``anchor_index`` (the row deleted from A2).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import partial

import numpy as np
import scipy.sparse as sp

from .sparse import EdgeSystem, Factor, GraphElimination, marginal_blocks, RenumberedFactor, solve_least_squares
from .stacks import rotate, row_blocks
from .graph import _reduced_incidence, free_poses
from .posegraph import PoseGraph, rot2
from .errors import OptionError, check_choice
from .solvers import ClarabelSettings, named_constant, parameter, solve
from .uncertainty import INFORMATION_MODES, EdgeUncertainty

__all__ = [
    "Phase1", "phase1_problem", "phase1_closed_form", "phase1_from_problem",
    "Phase2", "phase2", "global_relative_positions", "phase2_blocks", "edge_whitening", "phase1_system",
    "phase3_edge_system", "Lazy",
    "Phase3", "design_matrix", "phase3_problem", "phase3_closed_form", "phase3_from_problem",
]

log = logging.getLogger(__name__)

_S = np.array([[0.0, -1.0], [1.0, 0.0]])


def _full(n: int, a: int, free_values: np.ndarray, anchor_value=0.0) -> np.ndarray:
    """Values (n,) with ``anchor_value`` at index ``a`` and ``free_values`` (n − 1,) elsewhere."""
    out = np.empty(n)
    out[a] = anchor_value
    out[free_poses(n, a)] = free_values
    return out


class Lazy:
    """A dataclass field computed on first access: the stored value, or — when it is a zero-argument
    callable (or None with a ``_build`` method on the instance) — what that returns, cached. The closed
    forms never need the sparse matrices (``info``, and phase 2's ``z``, ``W``, ``jac``, ``Bt``) that the
    cvxpy builders and the lectures read; they are built only when read."""

    def __set_name__(self, owner, name):
        self.public, self.private = name, "_" + name

    def __get__(self, obj, objtype=None):
        if obj is None:
            return None  # the field's default
        v = obj.__dict__.get(self.private)
        if v is None and hasattr(obj, "_build"):
            v = obj._build(self.public)
            obj.__dict__[self.private] = v
        elif callable(v) and not isinstance(v, (np.ndarray, sp.spmatrix, sp.sparray)):
            v = v()
            obj.__dict__[self.private] = v
        return v

    def __set__(self, obj, value):
        obj.__dict__[self.private] = value


# ------------------------------------------------------------------------------ phase 1
@dataclass(frozen=True, eq=False)
class Phase1:
    """Phase-1 result: the orientations of eq. (13) and their information."""

    #: θ̂ (n,), the anchor at 0.
    theta: np.ndarray
    #: θ̂ of the free poses (d,), the anchor's entry deleted.
    theta_free: np.ndarray
    #: Ω_θ = A2 P_δ⁻¹ A2ᵀ, sparse (d, d) (built on first access).
    info: sp.csr_matrix = Lazy()
    #: The anchor's index.
    anchor_index: int = 0
    #: The factorization of ``info`` (closed form only).
    factor: Factor | None = None
    #: The solver's refinement statistics (closed form only).
    stats: dict | None = None

    def variances(self) -> np.ndarray:
        """Marginal variances of θ̂ (n,), diag(P_θ) with 0 at the anchor, by selected inversion of Ω_θ
        (eq. (T) of ``lago_cvx.sparse.multifrontal``) — never P_θ itself."""
        d = self.theta_free.size
        if d == 0:
            return np.zeros(1)
        var = marginal_blocks(self.info, np.arange(d)[:, None], factor=self.factor)[:, 0, 0]
        return _full(d + 1, self.anchor_index, var)


def _phase1_terms(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, a: int):
    """A2 (d, m), W = P_δ^{-1/2} (m, m) and δ_reg (m,) of eq. (13), anchor index ``a``."""
    A2 = _reduced_incidence(graph, a)
    W = sp.diags(unc.sqrt_info_delta)
    return A2, W, np.asarray(delta_reg, dtype=float)


def phase1_problem(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, *, anchor=None):
    """Phase 1 as a cvxpy problem (eq. (13)): minimise ‖P_δ^(-1/2)(Aᵀθ − δ_reg)‖² over θ ∈ ℝⁿ subject to
    θ_a = 0 (the anchor a, the gauge), A the incidence matrix with the anchor's row multiplied by 0 (so Aᵀθ =
    A2ᵀθ_free, A2 the reduced one of the closed form) and P_δ = diag of the δ variances.

    θ covers all n poses by index in graph order (``theta[v]`` is pose v's orientation), as in phase 3's
    problem and the variants' (``lago_cvx.variants.PoseVariables``). ``print(problem)`` reads
    ``minimize quad_over_lin(P_δ^(-1/2) @ (Aᵀ @ θ + -δ_reg), 1.0, …)`` (cvxpy's spelling of ‖·‖²) subject to
    the anchor equality. δ_reg is a ``cp.Parameter`` (``problem.param_dict["δ_reg"]``): set its ``.value``
    and re-solve without rebuilding. Returns ``(problem, theta)``; add constraints with
    ``cp.Problem(problem.objective, problem.constraints + [...])``."""
    import cvxpy as cp

    a = graph.anchor_index(anchor)
    A2, W, d_reg = _phase1_terms(graph, delta_reg, unc, a)
    At = named_constant(sp.csc_matrix(A2.T @ _free_selector(graph.n_poses, a, 1)), "Aᵀ")
    P_inv_sqrt = named_constant(sp.csc_matrix(W), "P_δ^(-1/2)")
    delta = parameter(d_reg, "δ_reg")
    theta = cp.Variable(graph.n_poses, name="θ")
    return cp.Problem(cp.Minimize(cp.sum_squares(P_inv_sqrt @ (At @ theta - delta))), [theta[a] == 0.0]), theta


def _free_selector(n: int, a: int, per_pose: int) -> sp.csr_matrix:
    """S (b·(n−1) × b·n) from the coordinates of all poses to the reduced ones of the closed forms: b = 1
    θ_free = S θ; b = 3 [p_free (interleaved); θ_free] = S [p; θ] (p interleaved over all n poses)."""
    free = free_poses(n, a)
    d = free.size
    if per_pose == 1:
        cols = free
    else:
        cols = np.concatenate([np.stack([2 * free, 2 * free + 1], 1).reshape(-1), 2 * n + free])
    return sp.csr_matrix((np.ones(cols.size), (np.arange(cols.size), cols)), shape=(per_pose * d, per_pose * n))


def phase1_system(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, elim: GraphElimination) -> EdgeSystem:
    """Eq. (13) as the edge system (E) of ``lago_cvx.sparse.normal_equations``: per edge k = (i → j),
    √(1/P_δ,k) (θ_j − θ_i − δ_reg,k), b = q = 1."""
    w = unc.sqrt_info_delta
    m = graph.n_edges
    return EdgeSystem(elim.tails, elim.heads, (-w).reshape(m, 1, 1), w.reshape(m, 1, 1),
                      (w * np.asarray(delta_reg, dtype=float)).reshape(m, 1), elim.d)


def phase1_closed_form(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, *, anchor=None,
                       backend: str = "auto", elimination: GraphElimination | None = None) -> Phase1:
    """Phase 1 in closed form (eq. (13)): θ̂ = (A2 P_δ⁻¹ A2ᵀ)⁻¹ A2 P_δ⁻¹ δ_reg by a sparse factorization
    with corrected semi-normal refinement (``lago_cvx.sparse.linalg.refine_normal_equations``).

    ``backend="auto"``: the pose-level elimination of the graph (``elimination``, a
    ``normal_equations.GraphElimination`` built with weights 1/P_δ, is reused when given: its QDLDL
    factorization *is* Ω_θ's); another backend: ``linalg.solve_least_squares`` on the sparse design."""
    a = graph.anchor_index(anchor)
    if backend != "auto":
        A2, W, d_reg = _phase1_terms(graph, delta_reg, unc, a)
        M = (W @ A2.T).tocsc()  # whitened design, (m, d)
        theta_free, info, factor, stats = solve_least_squares(M, unc.sqrt_info_delta * d_reg, backend=backend)
        return Phase1(_full(graph.n_poses, a, theta_free), theta_free, info.tocsr(), a, factor, stats)
    elim = elimination if elimination is not None and elimination.anchor_index == a else GraphElimination(graph, a)
    system = phase1_system(graph, delta_reg, unc, elim)
    x, factor, stats = elim.solve(system, stage="phase 1")  # by Ω_θ's factorization, made with the elimination
    info = partial(_normal_matrix, system)
    theta_free = np.asarray(x, dtype=float).reshape(-1)
    return Phase1(_full(graph.n_poses, a, theta_free), theta_free, info, a, factor, stats)


def _normal_matrix(system: EdgeSystem) -> sp.csr_matrix:
    """MᵀM (d·b × d·b) of an edge system (E), pose-major."""
    M = system.sparse()
    return (M.T @ M).tocsr()


def phase1_from_problem(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, *, anchor=None,
                        settings: ClarabelSettings | None = None):
    """Build and solve the phase-1 cvxpy problem with Clarabel; returns (Phase1, problem)."""
    problem, theta = phase1_problem(graph, delta_reg, unc, anchor=anchor)
    if graph.n_poses == 1:  # a single pose: nothing to estimate
        return phase1_closed_form(graph, delta_reg, unc, anchor=anchor), problem
    solve(problem, settings, what="phase 1")
    a = graph.anchor_index(anchor)
    A2, W, _ = _phase1_terms(graph, delta_reg, unc, a)
    M = W @ A2.T
    tf = _free_selector(graph.n_poses, a, 1) @ np.asarray(theta.value, dtype=float)
    return Phase1(_full(graph.n_poses, a, tf), tf, (M.T @ M).tocsr(), a), problem


# ------------------------------------------------------------------------------ phase 2
@dataclass(frozen=True, eq=False)
class Phase2:
    """Phase-2 quantities and the system phase 3 solves, argmin ‖W (z − Bᵀx)‖².

    ``delta_g`` (m, 2) Δᵍ = R(θ̂_i)Δˡ (eq. (9)); ``jac`` sparse (2m, d) J of eq. (11); ``anchor_index``;
    ``information`` ``"marginal"`` — the seed's ``z`` (2m + d,) = [Δᵍ (interleaved); θ̂_free], ``W``
    sparse (3m, 2m + d) with WᵀW = P_z⁻¹ (eqs. (10)–(11)) and ``Bt`` = Bᵀ of eq. (12) ((2m + d) × 3d);
    or ``"full"`` — ``z`` (3m,) = [Δᵍ − Jθ̂; δ_reg], ``W`` (3m × 3m) with 3×3 blocks U_k T_kᵀ on the rows
    (2k, 2k + 1, 2m + k) and ``Bt`` = [[A2ᵀ⊗I₂, −J], [0, A2ᵀ]] (3m × 3d) (module docstring)."""

    delta_g: np.ndarray
    z: np.ndarray = Lazy()
    W: sp.csr_matrix = Lazy()
    jac: sp.csr_matrix = Lazy()
    anchor_index: int = 0
    Bt: sp.csr_matrix = Lazy()
    information: str = "marginal"
    edges: EdgeSystem | None = None
    builder: object = None

    def _build(self, name: str):
        """Build ``z``, ``W``, ``jac``, ``Bt`` (sparse, for the cvxpy problem) on first access."""
        if self.builder is None:
            return None
        built = self.builder()
        for k, v in built.items():
            self.__dict__["_" + k] = v
        return built[name]

    def covariance_z(self) -> np.ndarray:
        """Dense (WᵀW)⁻¹: P_z of eq. (10) for the seed's form, blkdiag(T_k Σ_k T_kᵀ) for the full one —
        for small-graph checks and lectures only."""
        return np.linalg.inv((self.W.T @ self.W).toarray())


def global_relative_positions(graph: PoseGraph, theta: np.ndarray) -> np.ndarray:
    """Eq. (9): Δᵍ_ij = R(θ̂_i) Δˡ_ij, each edge's measured relative position rotated into the global frame
    by its tail's orientation; ``theta`` (n,) → (m, 2). (The engine's ``rotate`` kernel: the same numbers
    as ``einsum("kab,kb->ka", rot2(θ_i), Δˡ)``.)"""
    return rotate(np.asarray(theta, dtype=float)[graph.tails], graph.delta_l)


def phase2_blocks(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, tail_col: np.ndarray, d: int):
    """The edge part of phase 2 (eqs. (9)–(11)) for orientations θ̂ = ``theta`` (n,) whose free entries
    are numbered by ``tail_col`` (n,) (−1 for a known orientation; d free in all):

    Δᵍ = R(θ̂_i)Δˡ (m, 2); J (2m × d, sparse) of eq. (11), block of edge k in the column of its tail,
    S Δᵍ; and the first block row of the seed's W, [P_Δ^{-1/2} Rᵀ, −P_Δ^{-1/2} S Δˡ e_iᵀ]
    (2m × (2m + d), sparse). Used by ``phase2`` and by the anchored variants."""
    m = graph.n_edges
    Ri = rot2(theta[graph.tails])  # (m, 2, 2)
    delta_g = global_relative_positions(graph, theta)  # eq. (9)
    k = np.arange(m)
    col = tail_col[graph.tails]
    has = col >= 0
    r2 = np.stack([2 * k[has], 2 * k[has] + 1], 1).reshape(-1)
    c2 = np.repeat(col[has], 2)
    jac = sp.csr_matrix(((delta_g @ _S.T)[has].reshape(-1), (r2, c2)), shape=(2 * m, d))
    U = unc.sqrt_info_delta_l  # (m, 2, 2)
    URt = U @ np.swapaxes(Ri, 1, 2)  # (m, 2, 2)
    rows_a = np.repeat(np.stack([2 * k, 2 * k + 1], 1), 2, axis=1).reshape(-1)  # (4m,)
    cols_a = np.tile(np.stack([2 * k, 2 * k + 1], 1), (1, 2)).reshape(-1)
    USdl = -np.einsum("kab,kb->ka", U, graph.delta_l @ _S.T)  # −U S Δˡ = −P_Δ^{-1/2} Rᵀ J-block, (m, 2)
    top = sp.csr_matrix((np.concatenate([URt.reshape(-1), USdl[has].reshape(-1)]),
                         (np.concatenate([rows_a, r2]), np.concatenate([cols_a, 2 * m + c2]))),
                        shape=(2 * m, 2 * m + d))
    return delta_g, jac, top


def edge_whitening(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty) -> sp.csr_matrix:
    """W_f (3m × 3m): on the rows (2k, 2k + 1, 2m + k) of edge k the block U_k T_kᵀ,
    T_k = blkdiag(R(θ̂_i), 1), so that ‖W_f r‖² = Σ_k r_kᵀ T_k Ω_k T_kᵀ r_k (full information)."""
    m = graph.n_edges
    T = np.zeros((m, 3, 3))
    T[:, :2, :2] = rot2(theta[graph.tails])
    T[:, 2, 2] = 1.0
    blocks = unc.sqrt_info @ np.swapaxes(T, 1, 2)  # (m, 3, 3)
    idx = np.stack([2 * np.arange(m), 2 * np.arange(m) + 1, 2 * m + np.arange(m)], 1)  # (m, 3)
    rows = np.repeat(idx, 3, axis=1).reshape(-1)
    cols = np.tile(idx, (1, 3)).reshape(-1)
    return sp.csr_matrix((blocks.reshape(-1), (rows, cols)), shape=(3 * m, 3 * m))


def phase2(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, *, anchor=None, information: str = "full",
           delta_reg=None, elimination: GraphElimination | None = None) -> Phase2:
    """Phase 2 (eqs. (9)–(11)): Δᵍ, J, and the system phase 3 solves (module docstring).

    ``theta`` (n,) the phase-1 orientations (anchor at 0). ``information`` ``"full"`` (each edge's whole
    3×3 information; needs ``delta_reg`` (m,), the regularized δ phase 1 used) or ``"marginal"`` (the
    seed's z and P_z⁻¹ = WᵀW with the marginal P_Δ, P_δ). No optimisation happens here; the same code
    serves both the closed form and the cvxpy route. The phase-3 system is kept edge by edge
    (``edges``, ``phase3_edge_system``); the sparse ``z``, ``W``, ``jac``, ``Bt`` of eq. (15) are built
    when first read."""
    check_choice("information", information, INFORMATION_MODES)
    a = graph.anchor_index(anchor)
    if information == "full" and delta_reg is None:
        raise OptionError("phase2(information='full') needs delta_reg, the regularized δ of phase 1")
    theta = np.asarray(theta, dtype=float)
    delta_g = global_relative_positions(graph, theta)  # eq. (9)
    free_of = np.full(graph.n_poses, -1, np.int64)
    free_of[free_poses(graph.n_poses, a)] = np.arange(graph.n_poses - 1)
    tails = free_of[graph.tails] if elimination is None else elimination.tails
    heads = free_of[graph.heads] if elimination is None else elimination.heads
    edges = phase3_edge_system(graph, theta, unc, delta_g, tails, heads, information=information,
                               delta_reg=delta_reg)
    return Phase2(delta_g, anchor_index=a, information=information, edges=edges,
                  builder=partial(_phase2_sparse, graph, theta, unc, a, information, delta_reg))


def _phase2_sparse(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, a: int, information: str,
                   delta_reg) -> dict:
    """z, W, jac, Bt of eq. (15) as sparse matrices (the cvxpy problem's data; module docstring)."""
    n, m = graph.n_poses, graph.n_edges
    free = free_poses(n, a)
    col_of = np.full(n, -1, np.int64)
    col_of[free] = np.arange(n - 1)
    _, jac, top = phase2_blocks(graph, theta, unc, col_of, n - 1)
    A2t = _reduced_incidence(graph, a).T  # (m, d)
    delta_g = global_relative_positions(graph, theta)  # eq. (9)
    if information == "marginal":
        z = np.concatenate([delta_g.reshape(-1), theta[free]])
        L = sp.diags(unc.sqrt_info_delta) @ A2t  # second block row: [0, P_δ^{-1/2} A2ᵀ]
        W = sp.vstack([top, sp.hstack([sp.csr_matrix((m, 2 * m)), L])], format="csr")
        return {"z": z, "W": W, "jac": jac, "Bt": design_matrix(graph, anchor=int(graph.ids[a]))}
    z = np.concatenate([delta_g.reshape(-1) - jac @ theta[free], np.asarray(delta_reg, dtype=float)])
    Bt = sp.bmat([[sp.kron(A2t, sp.identity(2)), -jac], [None, A2t]], format="csr")
    return {"z": z, "W": edge_whitening(graph, theta, unc), "jac": jac, "Bt": Bt}


def phase3_edge_system(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, delta_g: np.ndarray,
                       tails: np.ndarray, heads: np.ndarray, *, information: str, delta_reg=None) -> EdgeSystem:
    """Phase 3's least-squares problem ‖W(Bᵀx − z)‖² (eq. (15)) written edge by edge, (E) of
    ``lago_cvx.sparse.normal_equations`` with b = q = 3 and pose variables x_i = (p_x, p_y, θ)_i:

    full — W_k = U_k T_kᵀ (T_k = blkdiag(R(θ̂_i), 1)), A_k = W_k [[−I₂, −SΔᵍ_k], [0, −1]], B_k = W_k,
    c_k = W_k [Δᵍ_k − SΔᵍ_k θ̂_i; δ_reg,k] (module docstring);
    marginal (the seed's eqs. (10)–(12)) — A_k = [[−U_Δ R(θ̂_i)ᵀ, −U_Δ SΔˡ_k], [0, −w_δ]],
    B_k = [[U_Δ R(θ̂_i)ᵀ, 0], [0, w_δ]], c_k = [U_Δ (R(θ̂_i)ᵀΔᵍ_k − SΔˡ_k θ̂_i); w_δ (θ̂_j − θ̂_i)]
    (U_Δ = P_Δ^{-1/2}, w_δ = P_δ^{-1/2}). ``tails``/``heads`` (m,) free-pose indices (−1: the anchor)."""
    m = graph.n_edges
    A = np.zeros((m, 3, 3))
    B = np.zeros((m, 3, 3))
    c = np.empty((m, 3))
    full = information == "full"
    if full:
        delta_reg = np.asarray(delta_reg, dtype=float)
    for k in row_blocks(m):  # (stacks.row_blocks: temporaries a block long, recycled)
        th_i = theta[graph.tails[k]]
        if full:  # the 3×3 products written out (NumPy's stacked matmul is slow on 3×3): U upper triangular
            U = unc.sqrt_info[k]
            cs, sn = np.cos(th_i), np.sin(th_i)
            gx, gy = delta_g[k, 0], delta_g[k, 1]
            W = [[U[:, 0, 0] * cs - U[:, 0, 1] * sn, U[:, 0, 0] * sn + U[:, 0, 1] * cs, U[:, 0, 2]],  # U Tᵀ
                 [-(U[:, 1, 1] * sn), U[:, 1, 1] * cs, U[:, 1, 2]],
                 [None, None, U[:, 2, 2]]]
            cu = (gx + gy * th_i, gy - gx * th_i, delta_reg[k])  # Δᵍ − SΔᵍ θ̂_i, δ_reg
            Ak, Bk, ck = A[k], B[k], c[k]
            for r in range(3):
                w0, w1, w2 = W[r]
                Bk[:, r, 2] = w2
                if w0 is None:  # the third row of U Tᵀ is (0, 0, u22)
                    np.negative(w2, out=Ak[:, r, 2])
                    ck[:, r] = w2 * cu[2]
                    continue
                Bk[:, r, 0], Bk[:, r, 1] = w0, w1
                np.negative(w0, out=Ak[:, r, 0])
                np.negative(w1, out=Ak[:, r, 1])
                Ak[:, r, 2] = w0 * gy - w1 * gx - w2  # W [[−I₂, −SΔᵍ], [0, −1]], S Δᵍ = (−gy, gx)
                ck[:, r] = w0 * cu[0] + w1 * cu[1] + w2 * cu[2]
        else:  # the 2×2 products written out: U_Δ R(θ̂_i)ᵀ, U_Δ SΔˡ (NumPy's stacked matmul is slow on 2×2)
            U = unc.sqrt_info_delta_l[k]
            u00, u01, u10, u11 = U[:, 0, 0], U[:, 0, 1], U[:, 1, 0], U[:, 1, 1]
            cs, sn = np.cos(th_i), np.sin(th_i)
            URt = [[u00 * cs - u01 * sn, u00 * sn + u01 * cs], [u10 * cs - u11 * sn, u10 * sn + u11 * cs]]
            lx, ly = graph.delta_l[k, 0], graph.delta_l[k, 1]
            USdl = [u01 * lx - u00 * ly, u11 * lx - u10 * ly]  # U S Δˡ, S = [[0, −1], [1, 0]]
            gx, gy = delta_g[k, 0], delta_g[k, 1]
            w = unc.sqrt_info_delta[k]
            Ak, Bk, ck = A[k], B[k], c[k]
            for a in range(2):
                for b in range(2):
                    Bk[:, a, b] = URt[a][b]
                    np.negative(URt[a][b], out=Ak[:, a, b])
                np.negative(USdl[a], out=Ak[:, a, 2])
                ck[:, a] = URt[a][0] * gx + URt[a][1] * gy - USdl[a] * th_i
            Bk[:, 2, 2] = w
            np.negative(w, out=Ak[:, 2, 2])
            ck[:, 2] = w * (theta[graph.heads[k]] - th_i)
    return EdgeSystem(tails, heads, A, B, c, graph.n_poses - 1)


# ------------------------------------------------------------------------------ phase 3
@dataclass(frozen=True, eq=False)
class Phase3:
    """Phase-3 result: the poses of eq. (12) and their information (eq. (15))."""

    #: x* (3d,) = [p (interleaved); θ] of the free poses.
    x_star: np.ndarray
    #: The poses (n, 3), the anchor at the origin.
    poses: np.ndarray
    #: Ω* = B WᵀW Bᵀ (= B P_z⁻¹ Bᵀ of eq. (15)), sparse (3d, 3d) (built on first access).
    info: sp.csr_matrix = Lazy()
    #: The anchor's index.
    anchor_index: int = 0
    #: The factorization of ``info`` (closed form only).
    factor: Factor | None = None
    #: The solver's refinement statistics (closed form only).
    stats: dict | None = None

    def pose_covariances(self, *, progress=None) -> np.ndarray:
        """Marginal 3×3 covariance of every pose (n, 3, 3), order (x, y, θ), zeros at the anchor: the
        diagonal pose blocks of (Ω*)⁻¹ by selected inversion (Takahashi's recurrences, eq. (T) of
        ``lago_cvx.sparse.multifrontal``) on the factor phase 3 used — no dense inverse, no column solves.
        ``progress`` an optional ``lago_cvx.progress.ProgressCallback``."""
        n = self.poses.shape[0]
        d = n - 1
        out = np.zeros((n, 3, 3))
        if d == 0:
            return out
        r = np.arange(d)
        var3 = np.stack([2 * r, 2 * r + 1, 2 * d + r], 1)
        from .progress import Progress

        with Progress("pose covariances", callback=progress, logger=log) as tracker:
            blocks = marginal_blocks(lambda: self.info, var3, factor=self.factor,
                                     progress=lambda i, k: tracker.update(i, k))
        out[free_poses(n, self.anchor_index)] = blocks
        return out


def design_matrix(graph: PoseGraph, *, anchor=None) -> sp.csr_matrix:
    """Bᵀ = blkdiag(A2ᵀ ⊗ I₂, I_d), shape (2m + d, 3d) (eq. (12)): maps x = [p; θ] to [Δp; θ]."""
    A2 = _reduced_incidence(graph, graph.anchor_index(anchor))
    d = A2.shape[0]
    return sp.block_diag([sp.kron(A2.T, sp.identity(2)), sp.identity(d)], format="csr")


def phase3_problem(graph: PoseGraph, ph2: Phase2):
    """Phase 3 as a cvxpy problem (eqs. (12), (15)): minimise ‖W (z − Bᵀρ)‖² over ρ = [p; θ] ∈ ℝ³ⁿ subject to
    the anchor's coordinates = 0 (where phase 2 was anchored; WᵀW = P_z⁻¹, and W, z, Bᵀ of the paper's or
    the full-information form, ``ph2.information``, with zero columns at the anchor).

    ρ covers all n poses by index in graph order, as in phase 1's problem and the variants': positions
    interleaved, ``rho[2v]``, ``rho[2v + 1]`` = x_v, y_v, orientations ``rho[2n + v]`` = θ_v.
    ``print(problem)`` reads ``minimize quad_over_lin(W @ (z + -(Bᵀ @ ρ)), 1.0, …)`` subject to the anchor
    equality. z is a ``cp.Parameter`` (``problem.param_dict["z"]``). Returns ``(problem, rho)``."""
    import cvxpy as cp

    n, a = graph.n_poses, ph2.anchor_index
    rho = cp.Variable(3 * n, name="ρ")
    W = named_constant(sp.csc_matrix(ph2.W), "W")
    Bt = named_constant(sp.csc_matrix(ph2.Bt @ _free_selector(n, a, 3)), "Bᵀ")
    z = parameter(ph2.z, "z")
    gauge = np.array([2 * a, 2 * a + 1, 2 * n + a])
    return cp.Problem(cp.Minimize(cp.sum_squares(W @ (z - Bt @ rho))), [rho[gauge] == 0.0]), rho


def _poses_from_x(n: int, a: int, x: np.ndarray) -> np.ndarray:
    d = n - 1
    poses = np.zeros((n, 3))
    free = free_poses(n, a)
    poses[free, :2] = x[:2 * d].reshape(d, 2)
    poses[free, 2] = x[2 * d:]
    return poses


def phase3_closed_form(graph: PoseGraph, ph2: Phase2, *, backend: str = "auto",
                       elimination: GraphElimination | None = None, progress=None) -> Phase3:
    """Phase 3 in closed form: x* = (B WᵀW Bᵀ)⁻¹ B WᵀW z, the least-squares solution of M x ≈ W z with
    M = W Bᵀ, by a sparse factorization of MᵀM with corrected semi-normal refinement. Anchored where
    phase 2 was.

    ``backend="auto"``: the edge system ``ph2.edges`` through the pose-level multifrontal elimination
    (``lago_cvx.sparse.normal_equations``; ``elimination`` reused when given), whose factor also serves
    ``Phase3.pose_covariances``; another backend: ``linalg.solve_least_squares`` on the sparse M.
    ``progress`` an optional ``lago_cvx.progress.ProgressCallback``."""
    n, a = graph.n_poses, ph2.anchor_index
    if backend == "auto" and ph2.edges is not None:
        elim = elimination if elimination is not None and elimination.anchor_index == a else \
            GraphElimination(graph, a)
        x, factor, stats = elim.solve(ph2.edges, stage="phase 3", progress=progress)
        d = n - 1
        x_star = np.concatenate([x[:, :2].reshape(-1), x[:, 2]])
        if factor is not None:  # number its variables as x_star: (2i, 2i + 1, 2d + i)
            r = np.arange(d)
            factor = RenumberedFactor(factor, np.stack([2 * r, 2 * r + 1, 2 * d + r], 1))
        edges = ph2.edges
        info = partial(_phase3_info, edges, d)
        return Phase3(x_star, _poses_from_x(n, a, x_star), info, a, factor, stats)
    M = (ph2.W @ ph2.Bt).tocsc()
    x, info, factor, stats = solve_least_squares(M, ph2.W @ ph2.z, backend=backend)
    return Phase3(x, _poses_from_x(n, a, x), info.tocsr(), a, factor, stats)


def _phase3_info(edges: EdgeSystem, d: int) -> sp.csr_matrix:
    """Ω* = MᵀM (3d × 3d) in x_star's variable order, from the edge system."""
    r = np.arange(d)
    M = edges.sparse(np.stack([2 * r, 2 * r + 1, 2 * d + r], 1))
    return (M.T @ M).tocsr()


def phase3_from_problem(graph: PoseGraph, ph2: Phase2, *, settings: ClarabelSettings | None = None):
    """Build and solve the phase-3 cvxpy problem with Clarabel; returns (Phase3, problem)."""
    problem, x = phase3_problem(graph, ph2)
    if graph.n_poses == 1:  # a single pose
        return phase3_closed_form(graph, ph2), problem
    solve(problem, settings, what="phase 3")
    xv = _free_selector(graph.n_poses, ph2.anchor_index, 3) @ np.asarray(x.value, dtype=float)
    M = ph2.W @ ph2.Bt
    return Phase3(xv, _poses_from_x(graph.n_poses, ph2.anchor_index, xv), (M.T @ M).tocsr(), ph2.anchor_index), \
        problem
