r"""Certifiable planar pose-graph optimization: the SE-Sync cost, a local solver for it, the Lagrangian
dual optimality certificate and the semidefinite relaxation as explicit cvxpy problems (Clarabel).

Reference: Rosen, Carlone, Bandeira, Leonard, *SE-Sync: A certifiably correct algorithm for
synchronization over the special Euclidean group*, IJRR 38(2–3), 2019 (below: "SE-Sync"), specialised
to d = 2 and written with the translations kept in the variable (sparse) instead of eliminated.

1. The cost (SE-Sync's Problem 1, eq. (12); datasets README §4.1) — **not** the g2o χ²
---------------------------------------------------------------------------------------------------
For poses x_i = (t_i, θ_i), R_i = R(θ_i), and an edge i → j with measurement (t̃_ij, R̃_ij = R(δ_ij))
(``graph.delta_l``, ``graph.delta``)::

    f(x) = Σ_(i,j) [ κ_ij ‖R_j − R_i R̃_ij‖_F²  +  τ_ij ‖t_j − t_i − R_i t̃_ij‖² ]          (1)

with **no ½**, and the weights SE-Sync's g2o reader derives from the 3×3 information Ω (order x, y, θ)::

    τ_ij = 2 / tr(Ω_tt⁻¹)   (Ω_tt = Ω[0:2, 0:2], inverted as a 2×2 matrix),   κ_ij = Ω[2, 2].   (2)

The x–θ / y–θ cross terms of Ω are ignored. In 2-D ‖R(a) − R(b)‖_F² = 4(1 − cos(a − b)), so with
e_ij = θ_j − θ_i − δ_ij the rotation term is 4κ(1 − cos e) = 8κ sin²(e/2) ≈ 2κe².

Relation to ``lago_cvx.cost.chi2`` (χ² = Σ eᵀΩe, e = [R_iᵀ(t_j − t_i) − t̃ ; wrap(e)]):
* translation: ‖t_j − t_i − R_i t̃‖ = ‖R_iᵀ(t_j − t_i) − t̃‖ (rotations are isometries), so the term is
  τ‖e_t‖², equal to e_tᵀΩ_tt e_t **only** when Ω_tt = τ·I (isotropic; τ is then the common value);
  otherwise τ is the harmonic mean of Ω_tt's eigenvalues and the two differ;
* rotation: 4κ(1 − cos e) ≈ 2κe², **twice** χ²'s κe² for small residuals, and bounded (≤ 8κ);
* cross terms: dropped by (1).
Hence f* ≠ χ²* (CSAIL: f* = 31.7037, χ²* = 61.143), and the minimisers differ slightly too.

2. Local solver — ``refine_sesync``
----------------------------------
Gauss–Newton on (x, y, θ) per pose (the anchor fixed), with residuals whose squares sum to f::

    r_t = √τ (t_j − t_i − R_i t̃)  (2,),     r_R = √(8κ) sin(e/2),  e = wrap(θ_j − θ_i − δ)        (3)

(r_R² = 4κ(1 − cos e)). Jacobian, with v = R_i t̃ and S = [[0, −1], [1, 0]]:
∂r_t/∂t_j = √τ I, ∂r_t/∂t_i = −√τ I, ∂r_t/∂θ_i = −√τ S v = √τ (v_y, −v_x);
∂r_R/∂θ_j = −∂r_R/∂θ_i = √(2κ) cos(e/2). Eight entries per edge, one sparse J (3m × 3(n−1)),
normal equations JᵀJ dx = −Jᵀr by ``lago_cvx.linalg.factorize``; a backtracking line search makes f
monotone. Reached from the χ²-refined LAGO estimate: manhattan 6431.39, city10000 638.625, CSAIL
31.7037, intel 52.3482 — SE-Sync's Table 1 (4 digits) for city10000, CSAIL and intel; manhattan's
6431.39 prints as 6.431e3 against Table 1's 6.432e3 (one unit of the last digit, 9e-5 relative; certified
optimal for eq. (1) on the file, see benchmarks/certify_datasets.md).

GN converges only linearly here when the neglected curvature Σ r∇²r is not small (intel: rate ≈ 0.74,
25 iterations to a relative decrease of 1e-12). ``method="newton"`` adds it — it has only θ–θ entries::

    ½∇²f = JᵀJ + C,  C[θ_i, θ_i] += τ (t_j − t_i − R_i t̃)·(R_i t̃),
                     C[(θ_i, θ_j)] += −2κ sin²(e/2)·[[1, −1], [−1, 1]]                               (3')

(from ∂²(R_i t̃)/∂θ_i² = −R_i t̃ and ∂²(4κ(1 − cos e)) = 4κ cos e = 2(√(2κ)cos(e/2))² − 4κ sin²(e/2)),
and takes the Newton step whenever it is a descent direction (else the GN step); 3–4 iterations on the
SE-Sync datasets.

3. Quadratic form and certificate — ``data_matrix``, ``certify``
--------------------------------------------------------------
Stack the poses in Y ∈ ℝ^{2×3n}, **per pose one translation column and two rotation columns**::

    Y = [ t_0 | R_0 | t_1 | R_1 | … ],   column 3i = t_i,   columns 3i+1, 3i+2 = R_i.               (4)

Each term of (1) is ‖Y a‖² with a vector or 3n×2 matrix a, so f = Σ‖Y a‖_F² = tr(Y M Yᵀ) with::

    M = Σ_(i,j) [ κ_ij A_ij A_ijᵀ + τ_ij b_ij b_ijᵀ ]   (3n × 3n, sparse, symmetric PSD),          (5)
    A_ij = E_j − E_i R̃_ij   (3n×2; E_i selects columns 3i+1, 3i+2),
    b_ij = e_{3j} − e_{3i} − E_i t̃_ij   (3n),

i.e. per edge, on the indices (3i | 3i+1, 3i+2 | 3j | 3j+1, 3j+2):
M[t_i,t_i] = M[t_j,t_j] += τ, M[t_i,t_j] −= τ, M[t_i,R_i] += τ t̃ᵀ, M[t_j,R_i] −= τ t̃ᵀ,
M[R_i,R_i] += κI + τ t̃t̃ᵀ, M[R_j,R_j] += κI, M[R_i,R_j] −= κR̃ (and the symmetric entries).
M has nnz ≈ 9(n + 2m); the vector 1_t (ones on the translation indices) spans a null space
(the global-translation gauge: M 1_t = 0).

Problem (1) is min tr(M YᵀY) over Y with R_i ∈ SO(2). Lagrangian of the constraints R_iᵀR_i = I₂ with
symmetric multipliers Λ_i (2×2): L = tr(Y M Yᵀ) − Σ tr(Λ_i(R_iᵀR_i − I)); stationarity gives::

    S Yᵀ = 0,   S = M − Λ̂,   Λ̂ = blkdiag(0, Λ_0, 0, Λ_1, …)  (zeros on translations),            (6)
    Λ_i = sym( [M YᵀY]_{R_i R_i} ) = sym( (M Yᵀ)_{R_i} R_i )      (SE-Sync's Λ(Y)).                 (7)

Weak duality: for any Λ with S = M − Λ̂ ⪰ 0 and any feasible Y, f(Y) = tr(S YᵀY) + Σ tr Λ_i ≥ Σ tr Λ_i.
So if Y is a critical point (6) and S ⪰ 0, then Σ tr Λ_i = f(Y) (the translation rows of (MYᵀ) vanish)
and Y is a **global** minimiser (SE-Sync Theorem 7, our S is theirs before translation elimination).

Schur complement. With L_τ = M_tt (the τ-weighted Laplacian, n × n) and
Q = M_RR − M_Rt L_τ⁺ M_tR (2n × 2n, dense — SE-Sync's translation-free data matrix),
S ⪰ 0 ⟺ S_Q = Q − Λ ⪰ 0 (Haynsworth: the translation block of S is L_τ ⪰ 0 and M 1_t = 0).
Grounding the anchor's translation column gives S_g (3n−1) and, for every σ,
In(S_g − σ Î_R) = In(L_g) + In(S_Q − σI) with L_g ≻ 0 the grounded Laplacian (Î_R = identity on rotation
indices, 0 on translations). So **one sparse LDLᵀ of S_g + ηÎ_R (QDLDL, AMD ordering) counts the
eigenvalues of S_Q below −η**: zero negative pivots proves λ_min(S_Q) ≥ −η, i.e. S + ηÎ_R ⪰ 0. The
spectrum of S_Q near its bottom comes from shift-invert Lanczos on b ↦ [(S_g − σÎ_R)⁻¹(0; b)]_R with σ
below λ_min (found by inertia bisection, started from the bound λ_min ≥ −max_i λ_max(Λ_i) since Q ⪰ 0).
At a certified optimum S_Q has exactly the two null vectors Y_Rᵀ (its third eigenvalue is the margin).
The full S has a third, structural null vector 1_t; its λ_min is computed the same way without grounding.

``certify`` first replaces the translations by the optimal ones for the given rotations (one linear
solve, as SE-Sync eliminates them), so Σ tr Λ_i = f exactly and the verdict is about the rotations.

Tolerances. η = ``tol``·‖M‖₂ (‖M‖₂ by Lanczos; default tol = 1e-12): floating-point S is known only
to ~1e-16‖M‖ entrywise and the LDLᵀ is backward stable only to a modest multiple of that, so the
test is "λ_min(S_Q) ≥ −η", and what it proves is f(x) − f* ≤ 2nη (section 3, eq. (8) with
Λ − ηI). The optima of the SE-Sync datasets have λ_min(S_Q) ≈ ±5e-13 (absolute) and still certify at
tol = 1e-15; the rigorous relative bound 2nη/f at the default is 4e-6 (CSAIL) … 1e-7 (city10000).

Lower bound when the certificate fails. With μ = max(0, −λ_min(S_Q)), Λ' = Λ − μI makes
Q − Λ' = S_Q + μI ⪰ 0, i.e. Λ' is dual feasible, so

    f* ≥ d(Λ') = Σ tr Λ_i − 2nμ                                                                       (8)

(made rigorous by using μ + η). At a suboptimal critical point this bound is valid but usually weak
(2n·μ); the SDP optimum (section 4) is the best such bound.

4. The SDP relaxation — ``sdp_relaxation``, ``solve_sdp``
--------------------------------------------------------
Z = YᵀY (3n × 3n) and dropping rank(Z) = 2 gives SE-Sync's relaxation (their Problem 7)::

    primal   f_SDP = min tr(M Z)  s.t.  Z ⪰ 0,  Z_{R_i R_i} = I₂  (i = 0 … n−1)                       (9)
    dual             max Σ tr Λ_i  s.t.  M − Λ̂ ⪰ 0                                                    (10)

f_SDP ≤ f*. Z_{R_i R_i} = I₂ only says R_iᵀR_i = I, i.e. it relaxes SO(2) to **O(2)**: a rank-2 Z
could contain reflections; ``SdpResult.n_reflected`` counts the rotation blocks of the rounded factor
whose determinant has the minority sign. Translation gauge: M 1_t = 0 makes (10) have no strictly
feasible point and (9) an unbounded optimal face, which interior-point methods dislike; we **ground
the anchor's translation** (drop row/column 3a of M and Z; exact, since f is translation invariant),
after which both are strictly feasible (Z = I; Λ_i = −εI) and strong duality holds.
(10) has the sparsity pattern of the pose graph (3×3 blocks), which Clarabel's chordal decomposition
exploits; its dual variable is the (PSD-completed) primal Z. Rounding: Y_R = top-2 eigenpairs of the
rotation block Z_RR, sign-fix the reflection by the majority of det(Y_{R_i}), project each block to
SO(2), then optimal translations by a weighted Laplacian solve; gap = (f(rounded) − f_SDP)/f_SDP.
f(rounded) ≥ f* always (a feasible point); Clarabel's Λ shifted by λ_min(S_Q(Λ)) (eq. (8)) gives a
proven lower bound, so f* is bracketed whatever the solver's accuracy.

Scaling and accuracy (measured). The translation indices are scaled by L = √(mean rotation diagonal
/ mean translation diagonal of M) (an exact congruence; without it Clarabel stalls 10× earlier on
CSAIL). An interior-point method resolves M − Λ̂ ⪰ 0 to ≈ 1e-9–1e-10 of ‖M‖, i.e. f_SDP to about
2n·1e-10‖M‖ absolutely; real SLAM data have f* ≪ n‖M‖ (CSAIL: κ up to 1e4, f* = 31.7), so the relative
accuracy of f_SDP is 1e-8 on synthetic/manhattan sub-graphs but only 1e-6…1e-3 on CSAIL/intel
sub-graphs, where Clarabel ends "AlmostSolved" or, sometimes, with a numerical error (then
``solve_sdp`` retries with L = 1 and with the non-compact chordal transformation). The **dense
primal** (9) as a cvxpy PSD variable has no sparsity for Clarabel to exploit (a 3n−1 dense cone: 36 s
at n = 30), so it is for cross-checks on n ≲ 15; the dual (10) is what scales (CSAIL's 1045 poses:
≈ 30 s, 1.7 GB).
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass, field, replace

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .graph import check_connected
from .linalg import factorize
from .posegraph import PoseGraph, rot2, wrap_angle
from .refine import _check_iteration_args, _check_poses, _resolve_anchor, _small_step

__all__ = [
    "sesync_weights", "sesync_cost", "stacked_variable", "poses_from_stacked", "data_matrix",
    "SesyncRefineResult", "refine_sesync",
    "multipliers", "certificate_matrix", "reduced_certificate_matrix", "Certificate", "certify",
    "optimal_translations", "round_solution",
    "SDP_SETTINGS", "sdp_relaxation", "SdpResult", "solve_sdp", "subgraph", "LeafPruning", "prune_leaves",
]

log = logging.getLogger(__name__)


# =============================================================================== 1. the cost
def sesync_weights(graph: PoseGraph) -> tuple[np.ndarray, np.ndarray]:
    """SE-Sync weights of eq. (2): ``kappa`` (m,) = Ω[2, 2] and ``tau`` (m,) = 2 / tr(Ω_tt⁻¹).

    For Ω_tt = [[a, b], [b, c]], tr(Ω_tt⁻¹) = (a + c)/(ac − b²), so τ = 2(ac − b²)/(a + c)."""
    info = graph.information
    a, b, c = info[:, 0, 0], 0.5 * (info[:, 0, 1] + info[:, 1, 0]), info[:, 1, 1]
    tau = 2.0 * (a * c - b * b) / (a + c)
    kappa = info[:, 2, 2].copy()
    return kappa, tau


def _edge_residuals(graph: PoseGraph, poses: np.ndarray):
    """Translation error d = t_j − t_i − R_i t̃ (m, 2), v = R_i t̃ (m, 2) and e = wrap(θ_j − θ_i − δ) (m,)."""
    pi, pj = poses[graph.tails], poses[graph.heads]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    tl = graph.delta_l
    v = np.column_stack([c * tl[:, 0] - s * tl[:, 1], s * tl[:, 0] + c * tl[:, 1]])
    d = pj[:, :2] - pi[:, :2] - v
    e = wrap_angle(pj[:, 2] - pi[:, 2] - graph.delta)
    return d, v, e


def sesync_cost(graph: PoseGraph, poses) -> float:
    """f(x) of eq. (1) (no ½) for ``poses`` (n, 3): Σ τ‖t_j − t_i − R_i t̃‖² + 4κ(1 − cos e)."""
    poses = _check_poses(graph, poses)
    kappa, tau = sesync_weights(graph)
    d, _, e = _edge_residuals(graph, poses)
    # 4κ(1 − cos e) = 8κ sin²(e/2): the second form keeps relative accuracy for small e
    return float(np.sum(tau * np.einsum("ka,ka->k", d, d)) + np.sum(8.0 * kappa * np.sin(0.5 * e) ** 2))


# ====================================================================== 3. the quadratic form
def stacked_variable(poses) -> np.ndarray:
    """Y of eq. (4), shape (2, 3n): column 3i = t_i, columns 3i+1, 3i+2 = R(θ_i)."""
    poses = np.asarray(poses, dtype=float)
    n = poses.shape[0]
    Y = np.empty((2, n, 3))
    Y[:, :, 0] = poses[:, :2].T
    Y[:, :, 1:] = np.transpose(rot2(poses[:, 2]), (1, 0, 2))  # Y[a, i, 1 + b] = R_i[a, b]
    return Y.reshape(2, 3 * n)


def poses_from_stacked(Y) -> np.ndarray:
    """Inverse of ``stacked_variable`` for Y (2, 3n) whose rotation blocks are rotations: (n, 3) poses;
    θ_i = atan2(R_i[1, 0] − R_i[0, 1], R_i[0, 0] + R_i[1, 1]) (also the angle of the nearest rotation
    for any block, the 2-D orthogonal Procrustes solution)."""
    Y = np.asarray(Y, dtype=float)
    n = Y.shape[1] // 3
    B = Y.reshape(2, n, 3)
    R = B[:, :, 1:]  # R[a, i, b]
    theta = np.arctan2(R[1, :, 0] - R[0, :, 1], R[0, :, 0] + R[1, :, 1])
    return np.column_stack([B[0, :, 0], B[1, :, 0], theta])


def _edge_blocks(graph: PoseGraph):
    """Per-edge 6×6 blocks of M (eq. (5)) on the local indices (t_i, R_i, t_j, R_j), shape (m, 6, 6),
    and the matching global indices (m, 6)."""
    m = graph.n_edges
    kappa, tau = sesync_weights(graph)
    Rt = rot2(graph.delta)  # (m, 2, 2)
    A = np.zeros((m, 6, 2))
    A[:, 1:3, :] = -Rt
    A[:, 4, 0] = 1.0
    A[:, 5, 1] = 1.0
    b = np.zeros((m, 6))
    b[:, 0] = -1.0
    b[:, 1:3] = -graph.delta_l
    b[:, 3] = 1.0
    blocks = (kappa[:, None, None] * np.einsum("kpa,kqa->kpq", A, A)
              + tau[:, None, None] * np.einsum("kp,kq->kpq", b, b))
    idx = np.concatenate([3 * graph.tails[:, None] + np.arange(3), 3 * graph.heads[:, None] + np.arange(3)], 1)
    return blocks, idx


def data_matrix(graph: PoseGraph) -> sp.csr_matrix:
    """M of eq. (5), shape (3n, 3n), CSR, symmetric PSD, with f(x) = tr(Y M Yᵀ) for Y = ``stacked_variable``."""
    blocks, idx = _edge_blocks(graph)
    rows = np.broadcast_to(idx[:, :, None], blocks.shape).reshape(-1)
    cols = np.broadcast_to(idx[:, None, :], blocks.shape).reshape(-1)
    N = 3 * graph.n_poses
    M = sp.csr_matrix((blocks.reshape(-1), (rows, cols)), shape=(N, N))
    M.sum_duplicates()
    return M


def _rotation_index(n: int) -> np.ndarray:
    """Indices of the rotation columns of Y, shape (n, 2): [3i+1, 3i+2]."""
    return 3 * np.arange(n)[:, None] + np.array([1, 2])


# ======================================================================= 2. the local solver
#: Maximum number of step halvings of the backtracking line search of ``refine_sesync``.
MAX_HALVINGS = 20
# A step with ‖dx‖∞ ≤ refine.STEP_TOLERANCE·(1 + ‖x‖∞) counts as converged (``_small_step``, shared with ``refine``).


@dataclass(eq=False)
class SesyncRefineResult:
    """Outcome of ``refine_sesync``: ``poses`` (n, 3) (θ unwrapped), ``cost`` f of eq. (1) there and
    ``cost_initial`` at the start; ``iterations`` accepted GN steps; ``converged`` and ``reason``;
    ``gradient_norm`` ‖∇f‖∞ = ‖2Jᵀr‖∞ at the last linearization (the point before the last step); ``anchor`` the fixed pose's
    index; ``log`` one dict per iteration (``iteration``, ``cost``, ``step_norm``, ``halvings``,
    ``time``); ``time`` seconds."""

    poses: np.ndarray
    cost: float
    cost_initial: float
    iterations: int
    converged: bool
    reason: str = ""
    gradient_norm: float = float("nan")
    anchor: int = 0
    log: list = field(default_factory=list)
    time: float = 0.0


class _SesyncProblem:
    """Residuals (3) and their Jacobian with a fixed sparsity pattern (8 entries per edge)."""

    def __init__(self, graph: PoseGraph, anchor: int):
        n, m = graph.n_poses, graph.n_edges
        self.graph, self.n, self.m, self.anchor = graph, n, m, anchor
        kappa, tau = sesync_weights(graph)
        self.sqrt_tau = np.sqrt(tau)
        self.sqrt_8kappa = np.sqrt(8.0 * kappa)
        col = np.arange(3 * n).reshape(n, 3)
        col = np.where(np.arange(n)[:, None] > anchor, col - 3, col)
        col[anchor] = -1
        self.free = np.ones(n, bool)
        self.free[anchor] = False
        i, j = graph.tails, graph.heads
        k3 = 3 * np.arange(m)
        # entry order: (row, column) for the 8 derivatives listed in the module docstring
        rows = np.column_stack([k3, k3, k3, k3 + 1, k3 + 1, k3 + 1, k3 + 2, k3 + 2])
        cols = np.column_stack([col[i, 0], col[i, 2], col[j, 0], col[i, 1], col[i, 2], col[j, 1],
                                col[i, 2], col[j, 2]])
        keep = cols >= 0
        self.keep = keep.reshape(-1)
        self.rows = rows.reshape(-1)[self.keep]
        self.cols = cols.reshape(-1)[self.keep]
        self.dim = 3 * (n - 1)
        self.col_theta = col[:, 2]

    def residuals(self, poses: np.ndarray):
        d, v, e = _edge_residuals(self.graph, poses)
        r = np.empty((self.m, 3))
        r[:, :2] = self.sqrt_tau[:, None] * d
        r[:, 2] = self.sqrt_8kappa * np.sin(0.5 * e)
        return r, v, e

    def cost(self, poses: np.ndarray) -> float:
        r = self.residuals(poses)[0]
        return float(np.einsum("ka,ka->", r, r))

    def linearize(self, poses: np.ndarray):
        r, v, e = self.residuals(poses)
        st = self.sqrt_tau
        dR = 0.5 * self.sqrt_8kappa * np.cos(0.5 * e)  # = √(2κ) cos(e/2)
        vals = np.column_stack([-st, st * v[:, 1], st, -st, -st * v[:, 0], st, -dR, dR]).reshape(-1)[self.keep]
        J = sp.csr_matrix((vals, (self.rows, self.cols)), shape=(3 * self.m, self.dim))
        return r.reshape(-1), J

    def curvature(self, poses: np.ndarray) -> sp.csr_matrix:
        """½Σ r_k ∇²r_k (3(n−1) square, sparse): what the exact Hessian ½∇²f adds to JᵀJ (eq. (3')).

        Only θ–θ entries: τ d·v on (θ_i, θ_i) from ∂²d/∂θ_i² = v, and −2κ sin²(e/2)·[[1, −1], [−1, 1]]
        on (θ_i, θ_j) from ∂²(4κ(1 − cos e)) = 4κ cos e = 2(√(2κ)cos(e/2))² − 4κ sin²(e/2)."""
        d, v, e = _edge_residuals(self.graph, poses)
        tau = self.sqrt_tau ** 2
        w = -0.25 * self.sqrt_8kappa ** 2 * np.sin(0.5 * e) ** 2  # −2κ sin²(e/2)
        ci, cj = self.col_theta[self.graph.tails], self.col_theta[self.graph.heads]
        rows = np.concatenate([ci, ci, cj, ci, cj])
        cols = np.concatenate([ci, ci, cj, cj, ci])
        vals = np.concatenate([tau * np.einsum("ka,ka->k", d, v), w, w, -w, -w])
        keep = (rows >= 0) & (cols >= 0)
        return sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(self.dim, self.dim))

    def update(self, poses: np.ndarray, dx: np.ndarray) -> np.ndarray:
        new = poses.copy()
        new[self.free] += dx.reshape(-1, 3)
        return new


def _newton_step(H: sp.spmatrix, g: np.ndarray, backend: str):
    """Newton step −H⁻¹g with the exact (½-scaled) Hessian H, or None when H cannot be factored or the
    step is not a descent direction (H indefinite away from a minimum)."""
    try:
        dx = -factorize(sp.csc_matrix(H), backend=backend).solve(g)
    except (RuntimeError, ValueError):
        return None
    if not np.isfinite(dx).all() or not float(g @ dx) < 0.0:
        return None
    return dx


#: Accepted values of ``refine_sesync(method=...)``.
SESYNC_METHODS = ("gauss-newton", "newton")


def refine_sesync(graph: PoseGraph, poses, *, max_iterations: int = 50, tolerance: float = 1e-12,
                  anchor=None, method: str = "gauss-newton", backend: str = "auto") -> SesyncRefineResult:
    """Minimise the SE-Sync cost f of eq. (1) from ``poses`` (n, 3) by Gauss–Newton on the residuals (3).

    Keyword-only: ``max_iterations`` GN iterations; ``tolerance`` stop when the relative decrease of f
    in an iteration is below it; ``anchor`` id of the pose held fixed (default the smallest id);
    ``method`` ``"gauss-newton"`` (default) or ``"newton"`` (exact Hessian of eq. (3') whenever its step
    is a descent direction, else the GN step: quadratic instead of linear convergence near a minimum);
    ``backend`` sparse solver (``lago_cvx.linalg.factorize``). Each iteration factors JᵀJ
    (3(n−1) square, sparse); a step that does not decrease f is halved (at most ``MAX_HALVINGS``
    times), so f never increases. Raises ``GraphError`` for a disconnected graph."""
    if method not in SESYNC_METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {SESYNC_METHODS}")
    _check_iteration_args(max_iterations, tolerance)
    x = _check_poses(graph, poses)
    a = _resolve_anchor(graph, anchor)
    check_connected(graph)
    t0 = time.perf_counter()
    prob = _SesyncProblem(graph, a)
    f = prob.cost(x)
    res = SesyncRefineResult(poses=x, cost=f, cost_initial=f, iterations=0, converged=False, anchor=a,
                             log=[{"iteration": 0, "cost": f, "step_norm": 0.0, "halvings": 0, "time": 0.0}],
                             reason="max_iterations reached")
    if prob.dim == 0 or graph.n_edges == 0:
        res.converged, res.reason = True, "nothing to optimize"
        return res
    tiny = np.finfo(float).tiny
    for it in range(1, max_iterations + 1):
        r, J = prob.linearize(x)
        Jt = J.T.tocsr()
        g = Jt @ r
        res.gradient_norm = float(np.max(np.abs(2.0 * g)))  # ∇f = 2Jᵀr
        H = (Jt @ J).tocsc()
        dx = None
        if method == "newton":
            dx = _newton_step(H + prob.curvature(x), g, backend)
        if dx is None:
            try:
                dx = -factorize(H, backend=backend).solve(g)
            except RuntimeError as exc:
                res.reason = f"singular normal equations ({exc})"
                break
        if not np.isfinite(dx).all():
            res.reason = "non-finite Gauss-Newton step (singular normal equations)"
            break
        step = float(np.max(np.abs(dx)))
        if _small_step(dx, x):
            res.converged, res.reason = True, f"step norm {step:.3g} below tolerance"
            break
        predicted = -float(g @ dx)  # ‖r‖² − ‖r + J dx‖² = −gᵀdx for the GN step
        alpha, halvings = 1.0, 0
        new = prob.update(x, dx)
        f_new = prob.cost(new)
        while not f_new <= f and halvings < MAX_HALVINGS:
            halvings += 1
            alpha *= 0.5
            new = prob.update(x, alpha * dx)
            f_new = prob.cost(new)
        if not f_new <= f:
            res.converged = predicted <= 10.0 * max(tolerance, 1e-15) * max(f, tiny)
            res.reason = ("no further decrease (stationary to working precision)" if res.converged else
                          f"line search failed after {halvings} halvings (predicted decrease {predicted:.3g})")
            break
        rel = (f - f_new) / max(f, tiny)
        x, f = new, f_new
        res.iterations += 1
        res.log.append({"iteration": res.iterations, "cost": f, "step_norm": alpha * step, "halvings": halvings,
                        "time": time.perf_counter() - t0})
        log.info("SE-Sync GN iteration %d: f = %.12g, |dx| = %.3g, halvings %d", res.iterations, f, alpha * step,
                 halvings)
        if rel < tolerance:
            res.converged, res.reason = True, "relative decrease below tolerance"
            break
    res.poses, res.cost = x, f
    res.time = time.perf_counter() - t0
    log.info("refine_sesync: f %.10g → %.10g in %d steps, %.3f s; %s", res.cost_initial, f, res.iterations,
             res.time, res.reason)
    return res


# ======================================================================= 3'. the certificate
def multipliers(M: sp.spmatrix, Y: np.ndarray) -> np.ndarray:
    """Λ_i of eq. (7), shape (n, 2, 2): sym((M Yᵀ)_{R_i} R_i) for M (3n, 3n) and Y (2, 3n)."""
    n = Y.shape[1] // 3
    rot = _rotation_index(n)
    MY = np.asarray(M @ Y.T)  # (3n, 2)
    B = MY[rot]  # (n, 2, 2): rows 3i+1, 3i+2 of M Yᵀ
    R = np.transpose(Y[:, rot], (1, 0, 2))  # (n, 2, 2): R[i] = Y[:, 3i+1:3i+3]
    L = B @ R
    return 0.5 * (L + np.swapaxes(L, 1, 2))


def _lambda_hat(lam: np.ndarray) -> sp.csr_matrix:
    """Λ̂ (3n, 3n): the blocks Λ_i (n, 2, 2) on the rotation indices, zeros on translations."""
    n = lam.shape[0]
    rot = _rotation_index(n)
    rows = np.broadcast_to(rot[:, :, None], lam.shape).reshape(-1)
    cols = np.broadcast_to(rot[:, None, :], lam.shape).reshape(-1)
    return sp.csr_matrix((lam.reshape(-1), (rows, cols)), shape=(3 * n, 3 * n))


def certificate_matrix(graph: PoseGraph, poses) -> sp.csr_matrix:
    """S = M − Λ̂(Y) of eq. (6), shape (3n, 3n), sparse symmetric, at ``poses`` (n, 3)."""
    Y = stacked_variable(_check_poses(graph, poses))
    M = data_matrix(graph)
    return (M - _lambda_hat(multipliers(M, Y))).tocsr()


def _grounded_index(n: int, anchor: int) -> np.ndarray:
    """Indices 0 … 3n−1 without the anchor's translation index 3·anchor, shape (3n−1,)."""
    return np.delete(np.arange(3 * n), 3 * anchor)


def _schur_solver(M: sp.spmatrix, anchor: int, backend: str = "auto"):
    """x ↦ L_τ⁺-type solve used by the Schur complement Q = M_RR − M_Rt L_τ⁺ M_tR: returns the
    translation indices (n,), the rotation indices (2n,) and a function solving the grounded
    Laplacian system (anchor translation removed) for right-hand sides with zero sum."""
    n = M.shape[0] // 3
    t_idx = 3 * np.arange(n)
    r_idx = _rotation_index(n).reshape(-1)
    Ltt = sp.csc_matrix(M[t_idx][:, t_idx])
    keep = np.delete(np.arange(n), anchor)
    factor = factorize(Ltt[keep][:, keep], backend=backend)

    def solve(b: np.ndarray) -> np.ndarray:
        x = np.zeros((n,) + b.shape[1:])
        x[keep] = factor.solve(b[keep])
        return x

    return t_idx, r_idx, solve


def reduced_certificate_matrix(graph: PoseGraph, poses, *, anchor: int = 0) -> np.ndarray:
    """S_Q = Q − blkdiag(Λ_i), **dense** (2n, 2n): SE-Sync's certificate matrix with the translations
    eliminated (Q = M_RR − M_Rt L_τ⁺ M_tR). For small graphs and cross-checks only (O(n²) memory)."""
    poses = _check_poses(graph, poses)
    M = data_matrix(graph).tocsr()
    Y = stacked_variable(poses)
    t_idx, r_idx, solve = _schur_solver(M, anchor)
    MtR = M[t_idx][:, r_idx].toarray()
    Q = M[r_idx][:, r_idx].toarray() - MtR.T @ solve(MtR)
    lam = multipliers(M, Y)
    n = graph.n_poses
    Lam = np.zeros((2 * n, 2 * n))
    ii = 2 * np.arange(n)[:, None] + np.arange(2)
    Lam[ii[:, :, None], ii[:, None, :]] = lam
    S = Q - Lam
    return 0.5 * (S + S.T)


def optimal_translations(graph: PoseGraph, theta, *, anchor: int = 0, anchor_translation=(0.0, 0.0),
                         backend: str = "auto") -> np.ndarray:
    """Translations minimising f for fixed orientations ``theta`` (n,): the weighted linear least squares
    min Σ τ‖t_j − t_i − R(θ_i) t̃‖², i.e. L_τ t = A(τ ⊙ R(θ_i)t̃) with L_τ = A diag(τ) Aᵀ (A the n × m
    incidence matrix), solved with the anchor's translation fixed to ``anchor_translation`` by
    ``lago_cvx.linalg.solve_least_squares`` on √τ·A2ᵀ (m × (n−1)). Returns (n, 2)."""
    from .graph import reduced_incidence
    from .linalg import solve_least_squares

    theta = np.asarray(theta, dtype=float)
    _, tau = sesync_weights(graph)
    v = np.einsum("kab,kb->ka", rot2(theta[graph.tails]), graph.delta_l)  # R_i t̃ (m, 2)
    t0 = np.asarray(anchor_translation, dtype=float).reshape(2)
    out = np.broadcast_to(t0, (graph.n_poses, 2)).copy()
    if graph.n_poses == 1:
        return out
    W = sp.diags(np.sqrt(tau))
    A2t = (W @ reduced_incidence(graph, anchor).T).tocsc()  # (m, n−1)
    x, _, _, _ = solve_least_squares(A2t, np.sqrt(tau)[:, None] * v, backend=backend)
    out[np.delete(np.arange(graph.n_poses), anchor)] += x
    return out


#: Below this dimension the shift-inverted operator is formed densely instead of running Lanczos.
DENSE_LIMIT = 64


class _ShiftedLDL:
    """K(σ) = K0 − σ·diag(D) (K0 sparse symmetric (N, N), D (N,) of 0/1) factored by QDLDL (AMD
    ordering, no pivoting) with a fixed pattern: ``inertia(σ)`` returns the number of negative pivots of
    LDLᵀ, i.e. (Sylvester) the number of negative eigenvalues of K(σ); ``solve`` uses the last factor."""

    def __init__(self, K0: sp.spmatrix, D: np.ndarray):
        import qdldl

        K0 = sp.csc_matrix(K0)
        N = K0.shape[0]
        U = sp.triu(K0 + sp.eye(N, format="csc"), format="csc")  # the +I forces every diagonal entry
        U.sort_indices()
        self.diag_pos = U.indptr[1:] - 1  # last entry of each column of an upper-triangular CSC
        self.diag0 = K0.diagonal()
        self.D = np.asarray(D, dtype=float)
        U.data[self.diag_pos] = self.diag0
        self.U = U
        self._qdldl = qdldl
        self._solver = None
        self.sigma = None

    def inertia(self, sigma: float) -> int:
        """Number of negative eigenvalues of K(σ) (a zero pivot counts as negative: K(σ) not ≻ 0)."""
        self.U.data[self.diag_pos] = self.diag0 - sigma * self.D
        try:
            if self._solver is None:
                self._solver = self._qdldl.Solver(self.U, upper=True)
            else:
                self._solver.update(self.U, upper=True)
        except Exception:  # QDLDL stops at an exactly zero pivot
            self._solver, self.sigma = None, None
            return 1
        self.sigma = sigma
        d = self._solver.factors()[1]
        return int(np.count_nonzero(~(d > 0)))

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._solver.solve(np.ascontiguousarray(b, dtype=float))


def _bottom_eigenvalues(ldl: _ShiftedLDL, sel: np.ndarray, *, lower: float, upper: float, k: int,
                        negative_at_upper: int, rel_width: float = 0.05, max_bisections: int = 60):
    """The k smallest eigenvalues of the operator T with (T − σI)⁻¹ b = [K(σ)⁻¹ E b]_sel (E the
    embedding of ``sel`` into ℝ^N): T = S_Q for the grounded reduced certificate, T = S for the full one.

    ``lower`` is a proven lower bound of λ_min(T); ``upper`` a shift at which ``negative_at_upper``
    eigenvalues lie below. If that count is positive, the bracket [lower, upper] is bisected with
    inertia counts until its width is ``rel_width``·|upper| (λ_min is then the dominant eigenvalue of
    the shift-inverted operator and Lanczos converges in a few steps); otherwise σ = upper − |upper|
    (= −2η) is used, just below the proven bound λ_min ≥ −η. Returns (eigenvalues ascending (k,), σ used)."""
    if negative_at_upper > 0:
        lo, hi = lower, upper
        for _ in range(max_bisections):
            if hi - lo <= rel_width * abs(hi):
                break
            mid = 0.5 * (lo + hi)
            if ldl.inertia(mid) == 0:
                lo = mid
            else:
                hi = mid
        sigma = lo
    else:
        sigma = upper - abs(upper)  # upper = −η: σ = −2η < λ_min
    if ldl.inertia(sigma) != 0:  # should not happen: lower is a proven bound
        raise RuntimeError(f"certificate: K(σ) is not positive definite at σ = {sigma:.3g}")
    N = ldl.U.shape[0]
    d = sel.size
    k = max(1, min(k, d - 1))

    def op(b):
        full = np.zeros(N)
        full[sel] = np.ravel(b)
        return ldl.solve(full)[sel]

    if d <= DENSE_LIMIT:  # small: the whole shift-inverted operator, column by column
        T = np.column_stack([op(e) for e in np.eye(d)])
        nu = np.linalg.eigvalsh(0.5 * (T + T.T))[::-1][:k]
    else:
        A = spla.LinearOperator((d, d), matvec=op, dtype=float)
        v0 = np.random.default_rng(0).standard_normal(d)
        nu = spla.eigsh(A, k=k, which="LA", v0=v0, return_eigenvectors=False, tol=1e-12)
    return np.sort(sigma + 1.0 / nu), sigma


@dataclass(eq=False)
class Certificate:
    """Outcome of ``certify`` (see the module docstring, section 3).

    ``certified`` — True iff the LDLᵀ inertia of S_g + ηÎ_R has no negative pivot, i.e.
    λ_min(S_Q) ≥ −η, which proves f(poses) − f* ≤ ``suboptimality_bound`` = 2nη;
    ``verdict`` — one line saying so or why not.
    ``cost`` f at the certified point (translations re-optimised for the given rotations when
    ``optimize_translations``; ``cost_input`` at the poses as given); ``poses`` that point (n, 3).
    ``dual_value`` Σ tr Λ_i (= ``cost`` when translations are optimal); ``multipliers`` Λ (n, 2, 2).
    ``lambda_min`` λ_min(S_Q) (SE-Sync's certificate matrix, translations eliminated) by shift-invert
    Lanczos; ``eigenvalues`` the ``n_eigenvalues`` smallest of S_Q (at an optimum two are ≈ 0, the
    third is the margin); ``lambda_min_full`` λ_min(S) of the full 3n × 3n S (≤ 0 always: S 1_t = 0;
    NaN unless ``full``). ``eta`` = tol·‖M‖₂, ``norm_M`` ‖M‖₂; ``n_negative`` eigenvalues of S_Q below
    −η (inertia count). ``residual`` ‖S Yᵀ‖_F (first-order condition (6)), ``residual_rel`` =
    residual/(‖M‖₂ √(2n)). ``lower_bound`` a proven lower bound on f* (eq. (8) with the shift ``shift``:
    Λ + shift·I is dual feasible), ``suboptimality_bound`` = cost − lower_bound, and
    ``suboptimality_estimate`` = 2n·max(0, −λ_min) (to Lanczos accuracy, SE-Sync's number).
    ``times`` seconds per step."""

    certified: bool
    verdict: str
    cost: float
    cost_input: float
    dual_value: float
    lambda_min: float
    eigenvalues: np.ndarray
    lambda_min_full: float
    eta: float
    norm_M: float
    n_negative: int
    residual: float
    residual_rel: float
    lower_bound: float
    shift: float
    suboptimality_bound: float
    suboptimality_estimate: float
    poses: np.ndarray
    multipliers: np.ndarray
    times: dict = field(default_factory=dict)

    @property
    def relative_suboptimality_bound(self) -> float:
        """(f − lower_bound)/f: relative distance to the global optimum proven by the certificate."""
        return self.suboptimality_bound / max(abs(self.cost), np.finfo(float).tiny)


#: Default relative tolerance of ``certify``: η = CERTIFY_TOL·‖M‖₂. Measured: the optima of the five
#: SE-Sync datasets still certify at 1e-15 (their computed λ_min(S_Q) is ≈ −5e-13, i.e. ~1e-17‖M‖);
#: 1e-12 leaves three orders of magnitude for rounding in S and in the factorization.
CERTIFY_TOL = 1e-12


def _norm2(M: sp.spmatrix) -> float:
    """‖M‖₂ = λ_max(M) for the PSD M (Lanczos, 1e-6 relative; dense for tiny M)."""
    if M.shape[0] <= DENSE_LIMIT:
        return float(np.linalg.eigvalsh(M.toarray())[-1])
    v0 = np.ones(M.shape[0])
    return float(spla.eigsh(M, k=1, which="LA", v0=v0, tol=1e-6, return_eigenvectors=False)[0])


def certify(graph: PoseGraph, poses, *, tol: float = CERTIFY_TOL, optimize_translations: bool = True,
            anchor=None, n_eigenvalues: int = 3, full: bool = True) -> Certificate:
    """SE-Sync's verification (Rosen et al. 2019, §4.2) of ``poses`` (n, 3) for the cost of eq. (1).

    Keyword-only: ``tol`` relative PSD tolerance, η = tol·‖M‖₂ (default ``CERTIFY_TOL`` = 1e-12; the
    optima of the SE-Sync datasets still pass at 1e-15, rounding shows below ~1e-16); ``optimize_translations`` replace the translations by the optimal
    ones for the given rotations first (exact linear solve; then Σ tr Λ_i = f and the certificate is on
    the rotations, as in SE-Sync); ``anchor`` pose id whose translation is grounded (default the
    smallest id); ``n_eigenvalues`` how many of S_Q's smallest eigenvalues to report; ``full`` also
    compute λ_min of the full S.

    Cost: one sparse LDLᵀ of S_g + ηÎ_R (3n−1 square) for the verdict, a few more (same pattern) for
    the spectrum; city10000 (30 000 × 30 000) takes about a second."""
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol}")
    if graph.n_edges == 0:
        raise ValueError("certify needs a graph with at least one edge")
    times = {}
    t_all = time.perf_counter()
    poses_in = _check_poses(graph, poses)
    check_connected(graph)
    a = _resolve_anchor(graph, anchor)
    n = graph.n_poses
    cost_input = sesync_cost(graph, poses_in)
    x = poses_in.copy()
    t = time.perf_counter()
    if optimize_translations:
        x[:, :2] = optimal_translations(graph, x[:, 2], anchor=a, anchor_translation=x[a, :2])
    times["translations"] = time.perf_counter() - t
    t = time.perf_counter()
    M = data_matrix(graph)
    Y = stacked_variable(x)
    lam = multipliers(M, Y)
    S = (M - _lambda_hat(lam)).tocsr()
    cost = float(np.sum(Y * (M @ Y.T).T))  # tr(Y M Yᵀ)
    dual = float(np.trace(lam, axis1=1, axis2=2).sum())
    residual = float(np.linalg.norm(S @ Y.T))
    norm_M = _norm2(M)
    eta = tol * norm_M
    times["assemble"] = time.perf_counter() - t

    # the verdict: inertia of S_g + ηÎ_R (grounded), = In(L_g) + In(S_Q + ηI)
    t = time.perf_counter()
    keep = _grounded_index(n, a)
    Sg = S[keep][:, keep]
    is_rot = (keep % 3 != 0).astype(float)
    ldl = _ShiftedLDL(Sg, is_rot)
    n_negative = ldl.inertia(-eta)
    times["inertia"] = time.perf_counter() - t

    # the spectrum of S_Q near its bottom; Q ⪰ 0 gives λ_min(S_Q) ≥ −max_i λ_max(Λ_i)
    t = time.perf_counter()
    lam_max = float(np.linalg.eigvalsh(lam)[:, -1].max()) if n else 0.0
    lower = -max(lam_max, 0.0) - eta - 1e-12 * norm_M
    eigs, _ = _bottom_eigenvalues(ldl, np.flatnonzero(is_rot), lower=lower, upper=-eta, k=n_eigenvalues,
                                  negative_at_upper=n_negative)
    lambda_min = float(eigs[0])
    if n_negative == 0:
        shift = -eta
    else:  # a proven shift: largest bisection point below λ_min, verified by inertia
        shift = lambda_min - eta
        if ldl.inertia(shift) != 0:
            shift = lower
    times["spectrum"] = time.perf_counter() - t

    lambda_min_full = float("nan")
    if full:
        t = time.perf_counter()
        ldl_full = _ShiftedLDL(S, np.ones(3 * n))
        neg_full = ldl_full.inertia(-eta)
        eig_full, _ = _bottom_eigenvalues(ldl_full, np.arange(3 * n), lower=lower, upper=-eta, k=1,
                                          negative_at_upper=neg_full)
        lambda_min_full = float(eig_full[0])
        times["spectrum_full"] = time.perf_counter() - t

    lower_bound = dual + 2 * n * shift
    sub_bound = cost - lower_bound
    sub_est = 2 * n * max(0.0, -lambda_min)
    residual_rel = residual / max(norm_M * np.sqrt(2 * n), np.finfo(float).tiny)
    certified = n_negative == 0
    if certified:
        verdict = (f"globally optimal (certified): λ_min(S_Q) = {lambda_min:.3g} ≥ −η = {-eta:.3g}, "
                   f"f − f* ≤ {sub_bound:.3g} ({sub_bound / max(cost, np.finfo(float).tiny):.2g} relative)")
    else:
        kind = ("not a critical point" if residual_rel > np.sqrt(tol) else "approximately a critical point")
        verdict = (f"NOT certified ({kind}, ‖SYᵀ‖ = {residual:.3g}): {n_negative} eigenvalue(s) of S_Q below "
                   f"−η = {-eta:.3g}, λ_min = {lambda_min:.4g}; f* ≥ {lower_bound:.6g}")
    times["total"] = time.perf_counter() - t_all
    log.info("certify: %s (%.3f s)", verdict, times["total"])
    return Certificate(certified=certified, verdict=verdict, cost=cost, cost_input=cost_input, dual_value=dual,
                       lambda_min=lambda_min, eigenvalues=eigs, lambda_min_full=lambda_min_full, eta=eta,
                       norm_M=norm_M, n_negative=n_negative, residual=residual, residual_rel=residual_rel,
                       lower_bound=lower_bound, shift=shift, suboptimality_bound=sub_bound,
                       suboptimality_estimate=sub_est, poses=x, multipliers=lam, times=times)


# ================================================================= 4. the SDP relaxation (cvxpy)
#: Clarabel settings for the SDPs (9)/(10). Not ``CLARABEL_SETTINGS``: its static regularization
#: 1e-11 and 1e-12 tolerances make Clarabel fail on these SDPs; at the defaults (1e-8) it stops at
#: the accuracy the data allow (see ``solve_sdp``). Chordal decomposition is Clarabel's default; the
#: clique merging is "parent_child" because Clarabel's default "clique_graph" merge did not finish in
#: 10 minutes on the first 200 poses of manhattan (parent_child: 80 cones, 6 s).
SDP_SETTINGS = {
    "max_iter": 300,
    "chordal_decomposition_enable": True,
    "chordal_decomposition_merge_method": "parent_child",
    "chordal_decomposition_complete_dual": True,
}


def subgraph(graph: PoseGraph, n_first: int) -> PoseGraph:
    """The subgraph induced by the first ``n_first`` poses (indices 0 … n_first−1): those poses and the
    edges between them (``PoseGraph.subgraph_edges`` + fewer poses); ids and initial guess are cut to
    match. The result may be disconnected if the file's odometry chain is broken."""
    n_first = int(n_first)
    if not 1 <= n_first <= graph.n_poses:
        raise ValueError(f"n_first must lie in 1..{graph.n_poses}, got {n_first}")
    inner = (graph.tails < n_first) & (graph.heads < n_first)
    g = graph.subgraph_edges(inner)
    initial = None if graph.initial is None else graph.initial[:n_first]
    name = f"{graph.name}[:{n_first}]" if graph.name else f"[:{n_first}]"
    return replace(g, n_poses=n_first, ids=graph.ids[:n_first], initial=initial, name=name)


@dataclass(eq=False)
class LeafPruning:
    """The 2-core of a pose graph (``prune_leaves``): ``core`` the core graph, ``index`` (n_core,) the
    original indices of its poses, ``rounds`` the peeled (leaf, edge, leaf_is_head) arrays, outermost
    last; ``extend(core_poses)`` rebuilds all n poses with zero residual on every peeled edge."""

    graph: PoseGraph
    core: PoseGraph
    index: np.ndarray
    rounds: list

    @property
    def n_removed(self) -> int:
        return self.graph.n_poses - self.core.n_poses

    def extend(self, core_poses) -> np.ndarray:
        """Poses (n, 3) of the whole graph from ``core_poses`` (n_core, 3): each peeled leaf ℓ is put
        where its one edge says — head ℓ of i → ℓ: θ_ℓ = θ_i + δ, t_ℓ = t_i + R_i t̃; tail ℓ of ℓ → i:
        θ_ℓ = θ_i − δ, t_ℓ = t_i − R_ℓ t̃ — processing the rounds innermost first (vectorized per round)."""
        g = self.graph
        out = np.zeros((g.n_poses, 3))
        out[self.index] = np.asarray(core_poses, dtype=float)
        for leaf, edge, is_head in reversed(self.rounds):
            other = np.where(is_head, g.tails[edge], g.heads[edge])
            theta = out[other, 2] + np.where(is_head, g.delta[edge], -g.delta[edge])
            Rt = np.einsum("kab,kb->ka", rot2(np.where(is_head, out[other, 2], theta)), g.delta_l[edge])
            out[leaf, 2] = theta
            out[leaf, :2] = out[other, :2] + np.where(is_head[:, None], Rt, -Rt)
        return out


def prune_leaves(graph: PoseGraph, *, anchor=None) -> LeafPruning:
    """Remove degree-1 poses (one edge) repeatedly, never the anchor (id, default the smallest), down to
    the 2-core. **Exact for both f* and f_SDP**: a leaf ℓ on edge (i, ℓ) can always be placed with zero
    residual on that edge — R_ℓ = R_i R̃, t_ℓ = t_i + R_i t̃ also for the r × 2 Stiefel blocks of any
    factor Z = YᵀY of the relaxation — so it changes neither optimum. Dangling chains add n‖M‖ but no
    cost, and SDP accuracy scales like f/(n‖M‖); pruning them matters (CSAIL's first 500 poses: 512
    edges, core 213 poses). One vectorized pass per peeling round."""
    a = _resolve_anchor(graph, anchor)
    n, m = graph.n_poses, graph.n_edges
    alive_pose = np.ones(n, bool)
    alive_edge = np.ones(m, bool)
    rounds = []
    while True:
        t, h = graph.tails[alive_edge], graph.heads[alive_edge]
        deg = np.bincount(t, minlength=n) + np.bincount(h, minlength=n)
        is_leaf = (deg == 1) & alive_pose
        is_leaf[a] = False
        if not is_leaf.any():
            break
        edges = np.flatnonzero(alive_edge)
        head_leaf = is_leaf[graph.heads[edges]]
        tail_leaf = is_leaf[graph.tails[edges]] & ~head_leaf  # an edge with two leaves: peel its head only
        sel = head_leaf | tail_leaf
        edge = edges[sel]
        is_head = head_leaf[sel]
        leaf = np.where(is_head, graph.heads[edge], graph.tails[edge])
        alive_pose[leaf] = False
        alive_edge[edge] = False
        rounds.append((leaf, edge, is_head))
    index = np.flatnonzero(alive_pose)
    if index.size == n:
        return LeafPruning(graph=graph, core=graph, index=index, rounds=[])
    relabel = np.full(n, -1, dtype=np.int64)
    relabel[index] = np.arange(index.size)
    g = graph.subgraph_edges(alive_edge)
    core = replace(g, n_poses=index.size, tails=relabel[g.tails], heads=relabel[g.heads], ids=graph.ids[index],
                   initial=None if graph.initial is None else graph.initial[index],
                   name=f"{graph.name} (2-core)")
    return LeafPruning(graph=graph, core=core, index=index, rounds=rounds)


def _translation_scale(M: sp.spmatrix) -> float:
    """Data-only length L for the translation indices of the SDP: L² = mean rotation diagonal of M /
    mean translation diagonal of M, so that the congruence D M D has balanced diagonal blocks
    (≈ √(κ/τ); CSAIL ≈ 9, intel ≈ 1)."""
    d = M.diagonal().reshape(-1, 3)
    rot, tra = float(d[:, 1:].mean()), float(d[:, 0].mean())
    return float(np.sqrt(rot / tra)) if rot > 0 and tra > 0 else 1.0


def sdp_relaxation(graph: PoseGraph, *, form: str = "dual", anchor=None, translation_scale=None):
    """The SDP relaxation of eq. (9) (``form="primal"``) or its dual eq. (10) (``form="dual"``) as an
    explicit cvxpy problem; ``problem.value`` is f_SDP (≤ f*) in both forms.

    Gauge: the anchor's translation index is removed (N = 3n − 1 rows and columns), see the module
    docstring. Scaling: translation indices are multiplied by L = ``translation_scale`` (default:
    L² = mean rotation / mean translation diagonal of M), i.e. M' = D M D, Z' = D⁻¹ Z D⁻¹ with D = diag(L on translations, 1 on rotations):
    an exact congruence that keeps Λ̂, the constraints Z_RiRi = I and the objective unchanged, and only
    balances the magnitudes Clarabel sees.

    dual — variable ``lam`` (3n,): Λ_i = [[lam[i], lam[n+i]], [lam[n+i], lam[2n+i]]];
        maximize Σ (lam[i] + lam[2n+i]) subject to ``M' − Λ̂ >> 0`` (N × N; its sparsity is the pose
        graph's, which Clarabel's chordal decomposition exploits; the constraint's dual value is Z').
    primal — variable ``Z`` (N × N, PSD): minimize Σ M' ⊙ Z' subject to Z'[r, r] = 1 and
        Z'[3i+1, 3i+2] = 0 on every rotation block. Dense: only for small graphs (n ≲ 40).

    Returns ``(problem, variables)``; ``variables`` has ``"lam"`` or ``"Z"``, ``"psd"`` (the PSD
    constraint or None), ``"index"`` (N,) the kept indices of 0 … 3n−1, ``"scale"`` (N,) the diagonal
    of D, ``"M"`` M' (sparse N × N) and ``"anchor"``."""
    if form not in ("dual", "primal"):
        raise ValueError(f"unknown form {form!r}; expected 'dual' or 'primal'")
    check_connected(graph)
    a = _resolve_anchor(graph, anchor)
    n = graph.n_poses
    M = data_matrix(graph)
    L = _translation_scale(M) if translation_scale is None else float(translation_scale)
    if not L > 0:
        raise ValueError(f"translation_scale must be > 0, got {translation_scale}")
    keep = _grounded_index(n, a)
    N = keep.size
    dscale = np.where(keep % 3 == 0, L, 1.0)
    Ms = (sp.diags(dscale) @ M[keep][:, keep] @ sp.diags(dscale)).tocsc()
    Ms = 0.5 * (Ms + Ms.T)
    rot = _rotation_index(n)
    r0, r1 = np.searchsorted(keep, rot[:, 0]), np.searchsorted(keep, rot[:, 1])
    variables = {"index": keep, "scale": dscale, "M": Ms, "anchor": a, "r0": r0, "r1": r1, "L": L}
    if form == "dual":
        lam = cp.Variable(3 * n, name="lam")
        # vec(Λ̂) = B·lam (column-major), 4 entries per pose
        flat = np.concatenate([r0 + N * r0, r1 + N * r1, r0 + N * r1, r1 + N * r0])
        which = np.concatenate([np.arange(n), 2 * n + np.arange(n), n + np.arange(n), n + np.arange(n)])
        B = sp.csc_matrix((np.ones(flat.size), (flat, which)), shape=(N * N, 3 * n))
        Lhat = cp.reshape(B @ lam, (N, N), order="F")
        psd = Ms - Lhat >> 0
        problem = cp.Problem(cp.Maximize(cp.sum(lam[:n]) + cp.sum(lam[2 * n:])), [psd])
        variables.update(lam=lam, psd=psd)
    else:
        Z = cp.Variable((N, N), PSD=True, name="Z")
        vecZ = cp.vec(Z, order="F")
        diag_idx = np.concatenate([r0 + N * r0, r1 + N * r1])
        off_idx = r0 + N * r1
        cons = [vecZ[diag_idx] == 1.0, vecZ[off_idx] == 0.0]
        Mc = Ms.tocoo()
        objective = cp.Minimize(Mc.data @ vecZ[Mc.row + N * Mc.col])
        problem = cp.Problem(objective, cons)
        variables.update(Z=Z, psd=None)
    return problem, variables


def round_solution(graph: PoseGraph, Z_rr: np.ndarray, *, anchor: int = 0):
    """Round the rotation block Z_RR ≈ Y_RᵀY_R (2n × 2n, rotation indices in pose order: 2i, 2i+1
    are R_i's columns) of an SDP solution to poses (SE-Sync's rounding, d = 2).

    Y_R = diag(√w₁, √w₂)·[v₁ v₂]ᵀ from the top-2 eigenpairs (2 × 2n); the 2×2 blocks B_i of Y_R are
    O(2) elements times a common G ∈ O(2). If most det(B_i) are negative the second row of Y_R is
    negated (G·diag(1, −1) is an equally valid gauge); each block is then projected to its nearest
    rotation θ_i = atan2(B₁₀ − B₀₁, B₀₀ + B₁₁), the anchor's angle is subtracted, and the
    translations are the optimal ones for these rotations (``optimal_translations``, anchor at the
    origin). Returns ``(poses (n, 3), n_reflected, eigenvalues)``: ``n_reflected`` blocks whose
    determinant has the minority sign (a genuine O(2) \\ SO(2) element), ``eigenvalues`` the three
    largest eigenvalues of Z_RR (rank 2 ⟺ the third is ≈ 0)."""
    n = graph.n_poses
    Z_rr = 0.5 * (np.asarray(Z_rr, dtype=float) + np.asarray(Z_rr, dtype=float).T)
    k = min(3, 2 * n)
    if 2 * n <= 400:
        w, V = np.linalg.eigh(Z_rr)
        w, V = w[::-1][:k], V[:, ::-1][:, :k]
    else:
        w, V = spla.eigsh(Z_rr, k=k, which="LA", v0=np.ones(2 * n))
        order = np.argsort(w)[::-1]
        w, V = w[order], V[:, order]
    Yr = (np.sqrt(np.maximum(w[:2], 0.0))[:, None] * V[:, :2].T)  # (2, 2n)
    B = Yr.reshape(2, n, 2).transpose(1, 0, 2)  # B[i] = Y_R[:, 2i:2i+2]
    det = np.linalg.det(B)
    if np.count_nonzero(det < 0) > n / 2:
        B[:, 1, :] *= -1.0
        det = -det
    n_reflected = int(np.count_nonzero(det < 0))
    theta = np.arctan2(B[:, 1, 0] - B[:, 0, 1], B[:, 0, 0] + B[:, 1, 1])
    theta = theta - theta[anchor]
    poses = np.zeros((n, 3))
    poses[:, 2] = theta
    poses[:, :2] = optimal_translations(graph, theta, anchor=anchor)
    return poses, n_reflected, w


@dataclass(eq=False)
class SdpResult:
    """Outcome of ``solve_sdp``.

    ``value`` f_SDP as reported by Clarabel (a lower bound on f* up to solver accuracy; equal for the
    graph and its 2-core); ``status``
    cvxpy's status; ``form``; ``lower_bound`` a **proven** lower bound on f*: Clarabel's multipliers Λ
    shifted by λ_min(S_Q(Λ)) to exact dual feasibility (eq. (8)), NaN if not computed;
    ``multipliers`` Λ (n, 2, 2); ``poses`` the rounded solution (n, 3), ``cost_rounded`` f there (an
    upper bound on f*), ``gap`` = (cost_rounded − value)/|value| (signed: a small negative gap is
    solver inaccuracy), ``n_reflected`` rotation blocks of the rank-2 factor with the minority
    determinant sign; ``z_eigenvalues`` the three largest eigenvalues of Z_RR (tight relaxation ⟺
    rank 2 ⟺ the third ≈ 0); ``Z`` the (grounded, unscaled) N × N primal matrix, ``index`` its rows
    in 0 … 3n−1; ``iterations``; ``times`` seconds (``build``, ``solve`` — cvxpy compile + Clarabel,
    ``round``, ``bound``, ``polish``, ``total``); ``n_poses``, ``n_edges`` of the graph, ``n_core`` poses
    of the 2-core the SDP was solved on; ``attempts`` the retry ladder's record; ``primal_value`` tr(MZ) of the
    recovered Z and ``primal_violation`` max_i ‖Z_RiRi − I‖_max (primal–dual consistency: with an
    accurate solve ``primal_value`` ≈ ``value``); with ``polish``: ``cost_polished`` f after
    ``refine_sesync`` from the rounded poses and ``certificate`` (``certify`` there) — SE-Sync's
    pipeline, which makes the answer exact even where the interior-point value is not."""

    value: float
    status: str
    form: str
    lower_bound: float
    multipliers: np.ndarray
    poses: np.ndarray
    cost_rounded: float
    gap: float
    n_reflected: int
    z_eigenvalues: np.ndarray
    Z: np.ndarray
    index: np.ndarray
    iterations: int
    times: dict
    n_poses: int
    n_edges: int
    primal_value: float = float("nan")
    primal_violation: float = float("nan")
    cost_polished: float = float("nan")
    certificate: "Certificate | None" = None
    attempts: list = field(default_factory=list)
    n_core: int = 0


def _dual_lower_bound(graph: PoseGraph, lam: np.ndarray, anchor: int) -> float:
    """Σ tr Λ_i + 2n·min(0, σ) with σ ≤ λ_min(S_Q(Λ)) proven by an LDLᵀ inertia count (eq. (8); σ = −η
    with η = CERTIFY_TOL·‖M‖₂ when S_Q(Λ) ⪰ −ηI, else just below the Lanczos λ_min). A graph without
    edges (e.g. the 2-core of a tree: the anchor alone) has f ≡ 0, so its bound is 0."""
    n = graph.n_poses
    if graph.n_edges == 0:
        return 0.0
    M = data_matrix(graph)
    S = (M - _lambda_hat(lam)).tocsr()
    keep = _grounded_index(n, anchor)
    is_rot = (keep % 3 != 0).astype(float)
    ldl = _ShiftedLDL(S[keep][:, keep], is_rot)
    norm_M = _norm2(M)
    eta = CERTIFY_TOL * norm_M
    neg = ldl.inertia(-eta)
    dual = float(np.trace(lam, axis1=1, axis2=2).sum())
    if neg == 0:
        return dual - 2 * n * eta
    lam_max = float(np.linalg.eigvalsh(lam)[:, -1].max())
    lower = -max(lam_max, 0.0) - eta - 1e-12 * norm_M
    eigs, sigma = _bottom_eigenvalues(ldl, np.flatnonzero(is_rot), lower=lower, upper=-eta, k=1,
                                      negative_at_upper=neg)
    shift = float(eigs[0]) - 1e-3 * abs(float(eigs[0])) - eta
    if ldl.inertia(shift) != 0:
        shift = sigma
    return dual + 2 * n * min(shift, 0.0)


def solve_sdp(graph: PoseGraph, *, form: str = "dual", settings: dict | None = None, anchor=None,
              translation_scale=None, prune: bool = True, lower_bound: bool = True, polish: bool = False,
              retries: bool = True, verbose: bool = False) -> SdpResult:
    """Build (``sdp_relaxation``) and solve the SDP relaxation with Clarabel (``SDP_SETTINGS`` updated
    by ``settings``), recover Z (dual form: the PSD constraint's dual value, PSD-completed by
    Clarabel) and Λ (primal form: Λ_i = sym([M Z]_{R_i R_i}), complementary slackness (M − Λ̂)Z = 0),
    round Z to poses (``round_solution``), if ``lower_bound`` make Λ exactly dual feasible, and if
    ``polish`` refine the rounded poses (``refine_sesync``) and ``certify`` them. With ``prune`` (default)
    the SDP is solved on the 2-core (``prune_leaves``: exact) and the rounded poses are extended to the
    whole graph; ``Z``, ``index`` and ``multipliers`` then refer to the core graph.

    Accuracy: an interior-point method resolves M − Λ̂ ⪰ 0 to ~1e-9‖M‖, so f_SDP is known to about
    2n·1e-9·‖M‖ absolutely; when f* ≪ n‖M‖ (low-noise real data: CSAIL has κ up to 1e4 and f* = 31.7)
    the relative accuracy of ``value`` is correspondingly limited, while ``cost_rounded`` (a feasible
    point) is exact. Near that accuracy floor Clarabel sometimes stops with a numerical error; with
    ``retries`` the solve is repeated with L = 1, then with the (slower, ≈ 4×) non-compact chordal
    transformation (``SdpResult.attempts`` lists what was tried). Raises ``RuntimeError`` if every attempt fails."""
    t_all = time.perf_counter()
    times = {"build": 0.0, "solve": 0.0}
    full = graph
    pruning = prune_leaves(graph, anchor=anchor) if prune else None
    if pruning is not None:
        graph = pruning.core
        log.info("SDP: 2-core has %d of %d poses", graph.n_poses, full.n_poses)
    ladder = [(translation_scale, {})]
    if retries:
        ladder += [(1.0, {}), (translation_scale, {"chordal_decomposition_compact": False})]
    attempts = []
    for scale, extra in ladder:
        t = time.perf_counter()
        problem, var = sdp_relaxation(graph, form=form, anchor=anchor, translation_scale=scale)
        times["build"] += time.perf_counter() - t
        opts = dict(SDP_SETTINGS)
        opts.update(extra)
        opts.update(settings or {})
        t = time.perf_counter()
        try:
            with warnings.catch_warnings():  # cvxpy's "may be inaccurate" warning: we log the status
                warnings.simplefilter("ignore", UserWarning)
                problem.solve(solver=cp.CLARABEL, verbose=verbose, **opts)
            status = problem.status
        except cp.error.SolverError:
            status = "solver_error"
        times["solve"] += time.perf_counter() - t
        attempts.append({"translation_scale": var["L"], "settings": extra, "status": status,
                         "time": time.perf_counter() - t})
        if status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
            break
        log.warning("Clarabel: SDP attempt with L = %.3g, %s ended with %s", var["L"], extra or "defaults", status)
    else:
        raise RuntimeError(f"Clarabel did not solve the SDP relaxation ({len(attempts)} attempt(s): "
                           + ", ".join(a_["status"] for a_ in attempts) + ")")
    if problem.status == cp.OPTIMAL_INACCURATE:
        log.info("Clarabel: inaccurate SDP solution (status %s)", problem.status)
    n, a = graph.n_poses, var["anchor"]
    d = var["scale"]
    r0, r1 = var["r0"], var["r1"]
    if form == "dual":
        Zs = np.asarray(var["psd"].dual_value)
        x = np.asarray(var["lam"].value)
        lam = np.empty((n, 2, 2))
        lam[:, 0, 0], lam[:, 0, 1], lam[:, 1, 0], lam[:, 1, 1] = x[:n], x[n:2 * n], x[n:2 * n], x[2 * n:]
    else:
        Zs = np.asarray(var["Z"].value)
        MZ = var["M"] @ Zs  # (N, N) dense
        lam = np.empty((n, 2, 2))
        lam[:, 0, 0], lam[:, 1, 1] = MZ[r0, r0], MZ[r1, r1]
        lam[:, 0, 1] = lam[:, 1, 0] = 0.5 * (MZ[r0, r1] + MZ[r1, r0])
    Zs = 0.5 * (Zs + Zs.T)
    Z = Zs * d[:, None] * d[None, :]
    t = time.perf_counter()
    rr = np.column_stack([r0, r1]).reshape(-1)
    poses, n_reflected, w = round_solution(graph, Z[np.ix_(rr, rr)], anchor=a)
    if pruning is not None:
        poses = pruning.extend(poses)
    cost_rounded = sesync_cost(full, poses)
    times["round"] = time.perf_counter() - t
    t = time.perf_counter()
    lb = _dual_lower_bound(graph, lam, a) if lower_bound else float("nan")
    times["bound"] = time.perf_counter() - t
    value = float(problem.value)
    den = max(abs(value), abs(cost_rounded))
    gap = (cost_rounded - value) / den if den > 1e-12 else 0.0  # both ≈ 0 (e.g. a tree): no gap
    Mg = data_matrix(graph)[var["index"]][:, var["index"]]
    primal_value = float(np.sum(Mg.multiply(Z)))
    blocks = Z[np.ix_(rr, rr)].reshape(n, 2, n, 2)[np.arange(n), :, np.arange(n), :]
    primal_violation = float(np.abs(blocks - np.eye(2)).max())
    cost_polished, cert = float("nan"), None
    if polish:
        t = time.perf_counter()
        pol = refine_sesync(full, poses, anchor=graph.ids[a])
        cost_polished = pol.cost
        cert = certify(full, pol.poses, anchor=graph.ids[a], full=False)
        times["polish"] = time.perf_counter() - t
    stats = problem.solver_stats
    times["total"] = time.perf_counter() - t_all
    log.info("SDP (%s form, %d poses): f_SDP = %.10g, rounded f = %.10g, gap %.2g, %.2f s", form, n, value,
             cost_rounded, gap, times["total"])
    return SdpResult(value=value, status=problem.status, form=form, lower_bound=lb, multipliers=lam, poses=poses,
                     cost_rounded=cost_rounded, gap=gap, n_reflected=n_reflected, z_eigenvalues=w, Z=Z,
                     index=var["index"], iterations=int(getattr(stats, "num_iters", 0) or 0), times=times,
                     n_poses=full.n_poses, n_edges=full.n_edges, primal_value=primal_value,
                     primal_violation=primal_violation, cost_polished=cost_polished, certificate=cert,
                     attempts=attempts, n_core=graph.n_poses)
