r"""Constrained variants of LAGO (issue 6): fixed anchors, priors, convex constraints, robust losses —
each phase still one explicit cvxpy problem, and (for the least-squares variants) a sparse closed form.

Notation as in ``lago_cvx.phases``: n poses, m edges, A the (n × m) incidence matrix, δ_reg the
regularized relative orientations, P_δ, P_Δ the per-edge marginal covariances, S = [[0, −1], [1, 0]].
Here the phases are written over **all** coordinates and a set K of them is *known*:
phase 1 over θ ∈ ℝⁿ, phase 3 over x = [p; θ] ∈ ℝ³ⁿ (p interleaved x₀, y₀, x₁, y₁, …). U is the rest.

(V1) Every phase is a weighted linear least-squares problem with known coordinates,
         minimise ‖W (z − Bᵀx)‖²   subject to   x_K = x̄_K,
     W a sparse whitening (rows × measurements), Bᵀ the design (measurements × coordinates).
(V2) Closed form: with M = W Bᵀ the known columns move to the right-hand side (the reduced incidence
     matrix loses the anchored rows),
         x_U = argmin ‖M_U x_U − (W z − M_K x̄_K)‖² = (M_UᵀM_U)⁻¹ M_Uᵀ (W z − M_K x̄_K),
     solved by ``lago_cvx.linalg.solve_least_squares`` (sparse factorization + refinement).
     cvxpy: one variable x for all coordinates, the objective ``cp.sum_squares(W @ (z − Bᵀ @ x))``,
     and the anchors as ONE equality constraint ``x[K] == x̄_K``.
(V3) Strain of a hard anchor. The gradient of the cost at the known coordinates,
     g_K = 2 M_Kᵀ(M x − W z), is the negated Lagrange multiplier of ``x[K] == x̄_K`` (cvxpy's dual
     value ν satisfies ∇f + ν = 0). Releasing the coordinates c of one anchor alone (everything
     else re-optimized) lowers the cost by
         Δχ²_c = ¼ g_cᵀ S_c⁺ g_c,    S_c = M_cᵀM_c − M_cᵀM_U (M_UᵀM_U)⁻¹ M_UᵀM_c,
     the Lagrange-multiplier (score) test: χ² with |c| degrees of freedom when the anchor agrees with
     the measurements. Orientations are tested in phase 1 (1 dof), positions in phase 3 (2 dof);
     an anchor is reported *strained* when the p-value of its statistic is below ``strain_level``
     and a warning names it. A hard anchor cannot compromise: the measurement residuals absorb the
     inconsistency, and this statistic is what tells.

Regularization with anchors (V4). The tree is rooted at the reference pose; θ_tree is the tree
integral offset so that the first pose of known orientation (the reference if it has one) matches
its value. Every other orientation anchor a acts like a chord from the root: its value is corrected
by 2πk_a, k_a = −round((θ_a − θ_tree[a]) / 2π) (ties as in ``regularization``: residual in (−π, π]),
reported like a chord (``AnchorRegularization``, ambiguous within ``margin`` of ±π, logged). Prior
means are rounded the same way.

Phase 1 (V5), with priors Q (pose q, mean μ_q, information Λ_q, 3×3 SPD):
     Bᵀ₁ = [Aᵀ; E_Q] ((m + |Q|) × n),  z₁ = [δ_reg; μ̃_θ],  W₁ = diag(P_δ^{-1/2}, σ_Q⁻¹),
     σ_q² = (Λ_q⁻¹)_θθ the prior's marginal variance of θ, μ̃_θ the rounded prior mean.
Phase 2 (V6): z = [Δᵍ; θ̂_U] ∈ ℝ^{2m + d_θ}, Δᵍ = R(θ̂_i)Δˡ, and
     W = [[P_Δ^{-1/2} Rᵀ, −P_Δ^{-1/2} S Δˡ e_iᵀ], [0, L]],   L = (W₁ Bᵀ₁)[:, U_θ],
     so WᵀW = P_z⁻¹ with P_θ⁻¹ = LᵀL (the anchored, prior-informed phase-1 information). An edge
     whose tail has a known orientation has no J block (θ_i carries no uncertainty).
Phase 3 (V7): x = [p; θ] ∈ ℝ³ⁿ, rows
     Δᵍ − (A ⊗ I₂)ᵀ p      (2m, whitened by the first block row of W),
     θ̂_U − θ_U            (d_θ, whitened by L),
     μ_p,q + h_q μ̃_θ,q − (p_q + h_q θ_q)   (2 per prior, whitened by C_q, C_qᵀC_q = Λ_pp,q),
     h_q = Λ_pp⁻¹Λ_pθ. (V8) This splits a prior exactly:
     eᵀΛe = (e_p + h e_θ)ᵀΛ_pp(e_p + h e_θ) + e_θ²/σ²,   e = pose − μ:
     the marginal θ part enters phase 1 (and reaches phase 3 through θ̂ and L), the conditional
     (x, y, θ) part enters phase 3 — every prior is counted once. A prior with information → ∞
     converges to the anchor (tested at 1e12).

Frame (gauge) decision. The reference pose (``anchor=`` if given, else the first full anchor, else
the first anchor with a known orientation, else the first anchor, else the first prior, else the
smallest id) roots the spanning tree. Orientation: fixed by the orientation anchors, else by the
priors; else, with ≥ 2 position anchors, a provisional LAGO in the reference's frame (θ_ref = 0) is
rotated onto the anchored positions (2-D Kabsch, equal weights) and θ_ref := that angle is held as a
*gauge* (not an anchor: never reported as strained); else θ_ref := ``anchor_pose[2]`` (default 0,
the usual LAGO frame). Position: fixed by the position anchors or the priors, else
p_ref := ``anchor_pose[:2]`` (default the origin). With ``anchors={}`` and no priors this is exactly
plain LAGO.

Convex constraints (V9). ``constrained_lago`` solves phases 1 and 3 as cvxpy problems to which a
user function adds named convex constraints through ``PoseVariables`` (affine expressions of every
pose's x, y, θ): ``box_constraint``, ``polygon_constraint`` (convex polygon as half-planes
nᵢᵀp ≤ cᵢ), ``orientation_bounds`` (lower ≤ θ_v − center_v ≤ upper). Orientation bounds act in both
phases, position constraints in phase 3. An infeasible problem raises ``InfeasibleConstraintsError``
naming the constraints: the ones infeasible on their own (with the anchors), else an irreducible
infeasible subset found by a deletion filter (drop each constraint in turn, keep it only if the rest
becomes feasible without it).

Robust losses (V10), for the edge rows only (anchors hard, priors quadratic). Let r_k be the whitened
residual rows of edge k (phase 1: one row; phase 3: its two position rows and its θ row of L — an
edge is an outlier as a whole, so its rows form one group; ``grouping="component"`` treats rows
separately). With threshold M (whitened units)
     huber:  ρ(r_k) = ‖r_k‖² if ‖r_k‖ ≤ M, else 2M‖r_k‖ − M²,
             written DCP as min_v ‖r_k − v_k‖² + 2M‖v_k‖₂ (a Moreau envelope; phase 1 uses
             ``cp.huber`` directly),
     l1:     ρ(r_k) = 2M‖r_k‖₂ (Huber's tails without its quadratic core; per-edge ℓ2 norms).
Both bound an edge's influence (its gradient) by 2M, so a false loop closure pulls with a bounded
force instead of a force growing with its error. Outliers also corrupt the 2kπ regularization: a BFS
tree may use a false loop closure as a tree edge, making θ_tree wrong on a whole subtree, and every
chord rounded against it. ``robust_lago`` therefore (a) roots the regularization on the odometric
tree when the odometric chain is complete (``spanning_tree="auto"``; false loop closures are never
odometric), and (b) re-rounds **every** edge (tree edges included) against the robust phase-1
estimate θ_rob, k_e = −round((δ_e − (θ_rob,j − θ_rob,i))/2π), re-solving phase 1 until no k changes
(at most ``reround_rounds`` times) — a wrong tree rounding or the drift of a long odometric chain
is then corrected by the loop closures that agree with each other. Phase 2 then uses the
robust phase-1 information L_w = diag(√w) L with the IRLS weights w_k = min(1, M/‖r_k‖) of the
robust phase-1 optimum (an outlier carries no information about θ̂).

Gating (V11, ``robust_lago(gate=τ)``). Measured on ``manhattan_world(500, seed=0,
outlier_fraction=0.1)`` (tests/test_variants.py, lecture 7): the convex Huber estimate down-weights
every false loop closure yet lands at 15× the error of LAGO without them (bounded is not zero: the
pulls of 27 outliers still bend weakly constrained loops). So the convex estimate is used to
*classify*: edges with whitened error √(eᵀΩe) of eq. (3) > τ (``GATE_THRESHOLD`` ≈ 5.5) are rejected,
except those of a trusted spanning tree (the odometric one; else the minimum-error tree), LAGO runs
on the accepted edges, and the classification is repeated at the new estimate until it is stable.
That reproduces the outlier-free LAGO (all outliers rejected, no inlier).
"""

from __future__ import annotations

import logging
import math
import re
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
from scipy import stats as sps

from . import phases as P
from .graph import incidence_matrix, spanning_tree as build_tree
from .lago import LagoResult, METHODS, relative_difference
from .linalg import Factor, block_diagonal_inverse, factorize, solve_least_squares, whitening_2x2
from .posegraph import GraphError, PoseGraph, rot2
from .regularization import AMBIGUITY_MARGIN, regularize

__all__ = [
    "Anchor", "Prior", "parse_anchor_spec", "normalize_anchors", "normalize_priors",
    "WeightedSystem", "AnchorRegularization", "AnchorStrain", "VariantResult",
    "anchored_lago", "constrained_lago", "robust_lago", "lago_variant", "compare_anchored_methods",
    "phase1_system", "anchored_phase2", "phase3_system", "system_problem", "solve_system",
    "PoseVariables", "NamedConstraint", "InfeasibleConstraintsError",
    "box_constraint", "polygon_constraint", "halfplane_constraint", "orientation_bounds",
    "LOSSES", "DEFAULT_THRESHOLD", "STRAIN_LEVEL", "ROBUST_SETTINGS", "GATE_THRESHOLD",
]

log = logging.getLogger(__name__)

#: Losses accepted by ``lago_variant(loss=...)``.
LOSSES = ("l2", "huber", "l1")
#: Default robust threshold M in whitened units (≈ the 95 % point of a χ with 3 dof, √7.81 = 2.8).
DEFAULT_THRESHOLD = 3.0
#: A suggested gate for ``robust_lago(gate=...)``: √χ²₃ at 1 − 10⁻⁶ (whitened error of one edge, 3 dof).
GATE_THRESHOLD = float(np.sqrt(sps.chi2.ppf(1.0 - 1e-6, 3)))
#: Default significance level of the anchor strain test (V3).
STRAIN_LEVEL = 1e-3
#: Clarabel overrides for the robust (conic) problems: their SOC/Huber structure cannot reach the 1e-12
#: gaps of ``CLARABEL_SETTINGS`` (Clarabel then reports "inaccurate"); 1e-9 is ample for an estimate
#: whose statistical error is ~1e-2. The least-squares variants keep ``CLARABEL_SETTINGS``.
ROBUST_SETTINGS = {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-9, "tol_feas": 1e-9,
                   "static_regularization_constant": 1e-8}
_S = np.array([[0.0, -1.0], [1.0, 0.0]])
_INFEASIBLE = (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE)


# =============================================================================== anchors & priors
@dataclass(frozen=True)
class Anchor:
    """A hard anchor: pose ``id`` (index ``index``) with known ``position`` (2,) or None and known
    ``theta`` or None (at least one of them known). ``theta`` is the value as given; the value used
    is corrected by 2πk (``AnchorRegularization``)."""

    id: int
    index: int
    position: tuple | None
    theta: float | None

    @property
    def kind(self) -> str:
        return "full" if self.position is not None and self.theta is not None else (
            "position" if self.position is not None else "orientation")


@dataclass(frozen=True, eq=False)
class Prior:
    """A soft absolute measurement of pose ``id``: ``mean`` (3,) = (x, y, θ), ``information`` (3, 3)
    SPD (order x, y, θ; GTSAM-style prior factor, g2o χ² convention eᵀΛe)."""

    id: int
    index: int
    mean: np.ndarray
    information: np.ndarray


_FIELD = r"\s*([^,]*)\s*"
_SPEC = re.compile(r"^\s*([+-]?\d+)\s*:" + _FIELD + "," + _FIELD + "," + _FIELD + "$")


def parse_anchor_spec(spec: str) -> tuple[int, tuple]:
    """Parse ``"ID:X,Y,THETA"`` → ``(id, (x, y, θ))``; empty fields give None (partial anchors):
    ``"5:,,1.57"`` orientation only, ``"5:1,2,"`` position only. Raises ``ValueError`` naming the
    spec when it is malformed, when only one of X, Y is given, or when all three are empty."""
    m = _SPEC.match(spec)
    if not m:
        raise ValueError(f"bad anchor {spec!r}: expected ID:X,Y,THETA (empty fields allowed, e.g. 5:,,1.57)")
    vals = []
    for name, text in zip("x y theta".split(), m.groups()[1:]):
        text = text.strip()
        if text == "":
            vals.append(None)
            continue
        try:
            v = float(text)
        except ValueError:
            raise ValueError(f"bad anchor {spec!r}: {name} = {text!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"bad anchor {spec!r}: {name} must be finite")
        vals.append(v)
    if (vals[0] is None) != (vals[1] is None):
        raise ValueError(f"bad anchor {spec!r}: give both X and Y, or neither")
    if all(v is None for v in vals):
        raise ValueError(f"bad anchor {spec!r}: at least the position or the orientation must be given")
    return int(m.group(1)), tuple(vals)


def _items(spec) -> list:
    if spec is None:
        return []
    return list(spec.items()) if isinstance(spec, Mapping) else list(spec)


def _unknown(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def normalize_anchors(graph: PoseGraph, anchors) -> list[Anchor]:
    """``{id: (x, y, θ)}`` (or pairs ``(id, (x, y, θ))``; a component None or NaN is unknown) →
    list of ``Anchor`` in the given order. Raises ``ValueError`` / ``GraphError`` naming the anchor."""
    out, seen = [], set()
    for pid, val in _items(anchors):
        idx = graph.index_of(pid)
        if idx in seen:
            raise ValueError(f"anchor {pid} given twice")
        seen.add(idx)
        val = tuple(val)
        if len(val) != 3:
            raise ValueError(f"anchor {pid}: expected (x, y, θ) with None for unknown parts, got {val!r}")
        x, y, th = (None if _unknown(v) else float(v) for v in val)
        if (x is None) != (y is None):
            raise ValueError(f"anchor {pid}: give both x and y, or neither")
        if x is None and th is None:
            raise ValueError(f"anchor {pid}: nothing is known (all components None)")
        if not all(math.isfinite(v) for v in (x, y, th) if v is not None):
            raise ValueError(f"anchor {pid}: values must be finite")
        out.append(Anchor(int(pid), idx, None if x is None else (x, y), th))
    return out


def normalize_priors(graph: PoseGraph, priors) -> list[Prior]:
    """``{id: (mean (3,), information (3, 3))}`` (or pairs) → list of ``Prior``; the information must
    be symmetric positive definite. Raises ``ValueError`` naming the prior."""
    out, seen = [], set()
    for pid, val in _items(priors):
        idx = graph.index_of(pid)
        if idx in seen:
            raise ValueError(f"prior on pose {pid} given twice")
        seen.add(idx)
        mean, info = val
        mean = np.asarray(mean, dtype=float).reshape(-1)
        info = np.asarray(info, dtype=float)
        if mean.shape != (3,) or info.shape != (3, 3):
            raise ValueError(f"prior {pid}: mean must have shape (3,) and information (3, 3)")
        if not (np.isfinite(mean).all() and np.isfinite(info).all()):
            raise ValueError(f"prior {pid}: values must be finite")
        if not np.allclose(info, info.T, rtol=1e-9, atol=0.0):
            raise ValueError(f"prior {pid}: information matrix is not symmetric")
        try:
            np.linalg.cholesky(info)
        except np.linalg.LinAlgError:
            raise ValueError(f"prior {pid}: information matrix is not positive definite") from None
        out.append(Prior(int(pid), idx, mean, 0.5 * (info + info.T)))
    return out


@dataclass(frozen=True, eq=False)
class _PriorArrays:
    """Vectorized priors: ``index`` (q,), ``mean`` (q, 3) with θ rounded to the tree,
    ``sigma_theta`` (q,) marginal std of θ, ``C`` (q, 2, 2) with CᵀC = Λ_pp, ``h`` (q, 2) = Λ_pp⁻¹Λ_pθ."""

    index: np.ndarray
    mean: np.ndarray
    sigma_theta: np.ndarray
    C: np.ndarray
    h: np.ndarray

    @property
    def q(self) -> int:
        return int(self.index.size)


def _prior_arrays(priors: list[Prior], mean_theta: np.ndarray) -> _PriorArrays:
    q = len(priors)
    if q == 0:
        z = np.zeros(0)
        return _PriorArrays(np.zeros(0, np.int64), np.zeros((0, 3)), z, np.zeros((0, 2, 2)), np.zeros((0, 2)))
    info = np.stack([p.information for p in priors])
    mean = np.stack([p.mean for p in priors])
    mean[:, 2] = mean_theta
    var_theta = np.linalg.inv(info)[:, 2, 2]
    Lpp = info[:, :2, :2]
    h = np.linalg.solve(Lpp, info[:, :2, 2][..., None])[..., 0]
    return _PriorArrays(np.array([p.index for p in priors], np.int64), mean, np.sqrt(var_theta),
                        whitening_2x2(Lpp), h)


# =============================================================================== weighted systems
@dataclass(frozen=True, eq=False)
class WeightedSystem:
    """One phase as (V1): minimise ‖W (z − Bᵀx)‖² over x ∈ ℝᴺ subject to x[known] = values[known].

    ``Bt`` sparse (r, N); ``z`` (r,); ``W`` sparse (s, r); ``known`` (N,) bool; ``values`` (N,) (used
    where known); ``groups`` (s,) int: the edge of each whitened row, −1 for rows that are never
    robustified (priors); ``name`` "phase1" / "phase3"."""

    Bt: sp.csr_matrix
    z: np.ndarray
    W: sp.csr_matrix
    known: np.ndarray
    values: np.ndarray
    groups: np.ndarray
    name: str

    @property
    def n_coords(self) -> int:
        return int(self.Bt.shape[1])

    def design(self) -> sp.csc_matrix:
        """M = W Bᵀ, the whitened design (s, N)."""
        return (self.W @ self.Bt).tocsc()

    def whitened_residual(self, x: np.ndarray) -> np.ndarray:
        """W (z − Bᵀx), shape (s,)."""
        return self.W @ (self.z - self.Bt @ x)

    def cost(self, x: np.ndarray) -> float:
        return float(np.sum(self.whitened_residual(x) ** 2))


def phase1_system(graph: PoseGraph, delta_reg, unc: P.EdgeUncertainty, known: np.ndarray, values: np.ndarray,
                  priors: _PriorArrays | None = None, *, edge_weights: np.ndarray | None = None) -> WeightedSystem:
    """Phase 1 with known orientations and priors (V5): Bᵀ₁ = [Aᵀ; E_Q] ((m + q) × n),
    z₁ = [δ_reg; μ̃_θ], W₁ = diag(√w P_δ^{-1/2}, σ_Q⁻¹) (w = ``edge_weights``, default 1).
    ``known`` (n,) bool, ``values`` (n,) the known (regularized) orientations."""
    n, m = graph.n_poses, graph.n_edges
    pr = priors if priors is not None else _prior_arrays([], np.zeros(0))
    E = sp.csr_matrix((np.ones(pr.q), (np.arange(pr.q), pr.index)), shape=(pr.q, n))
    Bt = sp.vstack([incidence_matrix(graph).T, E], format="csr")
    w = unc.sqrt_info_delta if edge_weights is None else unc.sqrt_info_delta * np.sqrt(edge_weights)
    W = sp.diags(np.concatenate([w, 1.0 / pr.sigma_theta])).tocsr()
    z = np.concatenate([np.asarray(delta_reg, dtype=float), pr.mean[:, 2]])
    groups = np.concatenate([np.arange(m), -np.ones(pr.q, np.int64)])
    return WeightedSystem(Bt, z, W, np.asarray(known, bool).copy(), np.asarray(values, float).copy(), groups, "phase1")


@dataclass(frozen=True, eq=False)
class AnchoredPhase2:
    """Phase 2 with known orientations (V6). ``delta_g`` (m, 2); ``z`` (2m + d_θ,) = [Δᵍ; θ̂_U];
    ``W`` sparse (2m + r_L, 2m + d_θ) with WᵀW = P_z⁻¹; ``jac`` sparse (2m, d_θ); ``free_theta``
    (d_θ,) the poses of unknown orientation; ``groups`` (2m + r_L,) edge of each row (−1: prior)."""

    delta_g: np.ndarray
    z: np.ndarray
    W: sp.csr_matrix
    jac: sp.csr_matrix
    free_theta: np.ndarray
    groups: np.ndarray


def anchored_phase2(graph: PoseGraph, theta: np.ndarray, unc: P.EdgeUncertainty, free_theta: np.ndarray,
                    L: sp.spmatrix, L_groups: np.ndarray) -> AnchoredPhase2:
    """Phase 2 (V6): Δᵍ = R(θ̂_i)Δˡ (eq. 9), z = [Δᵍ; θ̂_U], and the sparse square root
    W = [[P_Δ^{-1/2}Rᵀ, −P_Δ^{-1/2}SΔˡe_iᵀ], [0, L]] of P_z⁻¹, ``L`` (r_L × d_θ) the square root of the
    phase-1 information (LᵀL = P_θ⁻¹). ``theta`` (n,) the phase-1 orientations (global frame)."""
    n, m = graph.n_poses, graph.n_edges
    d = free_theta.size
    col_of = np.full(n, -1, np.int64)
    col_of[free_theta] = np.arange(d)
    Ri = rot2(theta[graph.tails])
    delta_g = np.einsum("kab,kb->ka", Ri, graph.delta_l)
    z = np.concatenate([delta_g.reshape(-1), theta[free_theta]])
    k = np.arange(m)
    tail_col = col_of[graph.tails]
    has = tail_col >= 0
    r2 = np.stack([2 * k[has], 2 * k[has] + 1], 1).reshape(-1)
    jac = sp.csr_matrix(((delta_g @ _S.T)[has].reshape(-1), (r2, np.repeat(tail_col[has], 2))), shape=(2 * m, d))
    U = unc.sqrt_info_delta_l
    URt = U @ np.swapaxes(Ri, 1, 2)
    rows_a = np.repeat(np.stack([2 * k, 2 * k + 1], 1), 2, axis=1).reshape(-1)
    cols_a = np.tile(np.stack([2 * k, 2 * k + 1], 1), (1, 2)).reshape(-1)
    USdl = -np.einsum("kab,kb->ka", U, graph.delta_l @ _S.T)
    Lc = sp.csr_matrix(L).tocoo()
    rows = np.concatenate([rows_a, r2, 2 * m + Lc.row])
    cols = np.concatenate([cols_a, 2 * m + np.repeat(tail_col[has], 2), 2 * m + Lc.col])
    vals = np.concatenate([URt.reshape(-1), USdl[has].reshape(-1), Lc.data])
    W = sp.csr_matrix((vals, (rows, cols)), shape=(2 * m + L.shape[0], 2 * m + d))
    groups = np.concatenate([np.repeat(k, 2), L_groups])
    return AnchoredPhase2(delta_g, z, W, jac, free_theta, groups)


def phase3_system(graph: PoseGraph, ph2: AnchoredPhase2, known: np.ndarray, values: np.ndarray,
                  priors: _PriorArrays | None = None) -> WeightedSystem:
    """Phase 3 with known coordinates and priors (V7), over x = [p (interleaved, 2n); θ (n)].

    Bᵀ = [[A ⊗ I₂ᵀ, 0], [0, E_U], [E_Q,p, h E_Q,θ]], z = [Δᵍ; θ̂_U; μ_p + h μ̃_θ],
    W = blkdiag(phase-2 W, C_q). ``known`` (3n,) bool and ``values`` (3n,) in the same order."""
    n, m = graph.n_poses, graph.n_edges
    pr = priors if priors is not None else _prior_arrays([], np.zeros(0))
    q = pr.q
    d = ph2.free_theta.size
    Bp = sp.kron(incidence_matrix(graph).T, sp.identity(2), format="csr")  # (2m, 2n)
    Eu = sp.csr_matrix((np.ones(d), (np.arange(d), 2 * n + ph2.free_theta)), shape=(d, 3 * n))
    rq = np.arange(2 * q)
    qi = np.repeat(pr.index, 2)
    D = sp.csr_matrix((np.concatenate([np.ones(2 * q), pr.h.reshape(-1)]),
                       (np.concatenate([rq, rq]), np.concatenate([2 * qi + np.tile([0, 1], q), 2 * n + qi]))),
                      shape=(2 * q, 3 * n))
    Bt = sp.vstack([sp.hstack([Bp, sp.csr_matrix((2 * m, n))]), Eu, D], format="csr")
    z = np.concatenate([ph2.z, (pr.mean[:, :2] + pr.h * pr.mean[:, 2:3]).reshape(-1)])
    C = sp.block_diag(list(pr.C), format="csr") if q else sp.csr_matrix((0, 0))
    W = sp.block_diag([ph2.W, C], format="csr")
    groups = np.concatenate([ph2.groups, -np.ones(2 * q, np.int64)])
    return WeightedSystem(Bt, z, W, np.asarray(known, bool).copy(), np.asarray(values, float).copy(), groups, "phase3")


# =============================================================================== solving a system
@dataclass(eq=False)
class SystemSolution:
    """Solution of a ``WeightedSystem``: ``x`` (N,) all coordinates; ``info`` sparse (d_U, d_U) =
    M_UᵀM_U; ``grad_known`` (|K|,) g_K of (V3) (cvxpy: −dual value); ``factor``/``stats`` (closed form);
    ``problem`` (cvxpy); ``weights`` (s,) IRLS weights of the whitened rows (robust losses, else 1)."""

    x: np.ndarray
    info: sp.csc_matrix
    grad_known: np.ndarray | None
    factor: Factor | None = None
    stats: dict | None = None
    problem: cp.Problem | None = None
    weights: np.ndarray | None = None

    def factorized(self) -> Factor:
        if self.factor is None:
            self.factor = factorize(self.info, backend="superlu")
        return self.factor


def solve_system(sys_: WeightedSystem, *, backend: str = "auto") -> SystemSolution:
    """Closed form (V2): x_U = argmin ‖M_U x_U − (W z − M_K x̄_K)‖² by ``solve_least_squares``;
    also returns g_K = 2 M_Kᵀ(M x − W z) (V3)."""
    M = sys_.design()
    U, K = ~sys_.known, sys_.known
    MU, MK = M[:, U], M[:, K]
    Wz = sys_.W @ sys_.z
    xU, N, factor, stats = solve_least_squares(MU, Wz - MK @ sys_.values[K], backend=backend)
    x = sys_.values.copy()
    x[U] = xU
    g = 2.0 * (MK.T @ (M @ x - Wz))
    return SystemSolution(x, N.tocsc(), g, factor, stats)


def _group_matrices(groups: np.ndarray, rows: np.ndarray):
    """For the robust rows ``rows`` (indices into the whitened rows) with edge ``groups[rows]``: the
    list of sparse selectors S_a (n_g × |rows|) picking the a-th row of every group, and n_g."""
    g = groups[rows]
    uniq, gid = np.unique(g, return_inverse=True)
    order = np.argsort(gid, kind="stable")
    starts = np.r_[0, np.flatnonzero(np.diff(gid[order])) + 1]
    rank = np.empty(rows.size, np.int64)
    rank[order] = np.arange(rows.size) - np.repeat(starts, np.diff(np.r_[starts, rows.size]))
    sel = []
    for a in range(int(rank.max()) + 1 if rows.size else 0):
        j = np.flatnonzero(rank == a)
        sel.append(sp.csr_matrix((np.ones(j.size), (gid[j], j)), shape=(uniq.size, rows.size)))
    return sel, uniq.size


def system_problem(sys_: WeightedSystem, *, loss: str = "l2", threshold: float = DEFAULT_THRESHOLD,
                   grouping: str = "edge"):
    """The phase as a cvxpy problem (V1 with the loss of V10).

    Returns ``(problem, x, anchor_constraint)``: ``x`` (N,) the variable of all coordinates,
    ``anchor_constraint`` the equality ``x[K] == x̄_K`` (None when nothing is known; its
    ``dual_value`` is −g_K). Objective: ``cp.sum_squares(W @ (z − Bᵀ @ x))`` for ``loss="l2"``;
    for ``"huber"``/``"l1"`` the edge rows use the robust loss (``grouping="edge"``: the rows of an
    edge as one group, ``"component"``: each row alone) and the prior rows stay quadratic."""
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; expected one of {LOSSES}")
    if grouping not in ("edge", "component"):
        raise ValueError(f"grouping must be 'edge' or 'component', got {grouping!r}")
    if not threshold > 0:
        raise ValueError(f"threshold must be > 0, got {threshold}")
    x = cp.Variable(sys_.n_coords, name="theta" if sys_.name == "phase1" else "x")
    r = sys_.z - sys_.Bt @ x
    if loss == "l2":
        objective = cp.sum_squares(sys_.W @ r)
    else:
        robust = np.flatnonzero(sys_.groups >= 0)
        quad = np.flatnonzero(sys_.groups < 0)
        Wr = sys_.W[robust]
        terms = [cp.sum_squares(sys_.W[quad] @ r)] if quad.size else []
        groups = sys_.groups if grouping == "edge" else np.arange(sys_.groups.size)
        sel, _ = _group_matrices(groups, robust)
        if len(sel) <= 1:  # one row per group: scalar atoms
            if loss == "huber":
                terms.append(cp.sum(cp.huber(Wr @ r, threshold)))
            else:
                terms.append(2.0 * threshold * cp.norm1(Wr @ r))
        elif loss == "huber":  # group Huber as a Moreau envelope: min_v ‖r − v‖² + 2M Σ‖v_g‖
            v = cp.Variable(robust.size, name="outlier_part")
            norms = cp.norm(cp.vstack([S @ v for S in sel]), 2, axis=0)
            terms += [cp.sum_squares(Wr @ r - v), 2.0 * threshold * cp.sum(norms)]
        else:
            e = Wr @ r
            terms.append(2.0 * threshold * cp.sum(cp.norm(cp.vstack([S @ e for S in sel]), 2, axis=0)))
        objective = cp.sum(cp.hstack(terms)) if len(terms) > 1 else terms[0]
    K = np.flatnonzero(sys_.known)
    anchor = (x[K] == sys_.values[K]) if K.size else None
    return cp.Problem(cp.Minimize(objective), [anchor] if anchor is not None else []), x, anchor


def _row_weights(sys_: WeightedSystem, x: np.ndarray, loss: str, threshold: float, grouping: str) -> np.ndarray:
    """IRLS weights of the whitened rows at x: w_g = min(1, M/‖r_g‖) for robust groups, 1 else."""
    w = np.ones(sys_.W.shape[0])
    if loss == "l2":
        return w
    r = sys_.whitened_residual(x)
    rob = sys_.groups >= 0
    groups = sys_.groups if grouping == "edge" else np.arange(sys_.groups.size)
    g = groups[rob]
    uniq, gid = np.unique(g, return_inverse=True)
    norm = np.sqrt(np.bincount(gid, weights=r[rob] ** 2, minlength=uniq.size))
    wg = np.minimum(1.0, threshold / np.maximum(norm, np.finfo(float).tiny))
    w[rob] = wg[gid]
    return w


def _solve_cvxpy(problem: cp.Problem, settings: dict | None):
    opts = dict(P.CLARABEL_SETTINGS)
    opts.update(settings or {})
    problem.solve(solver=cp.CLARABEL, **opts)
    return problem.status


def solve_system_cvxpy(sys_: WeightedSystem, *, loss: str = "l2", threshold: float = DEFAULT_THRESHOLD,
                       grouping: str = "edge", constraints: list | None = None,
                       settings: dict | None = None) -> SystemSolution:
    """Build (``system_problem``) and solve with Clarabel; ``constraints`` a list of
    ``NamedConstraint`` added to the problem (an infeasible problem raises
    ``InfeasibleConstraintsError`` naming them, see ``_diagnose``)."""
    problem, x, anchor = system_problem(sys_, loss=loss, threshold=threshold, grouping=grouping)
    named = [c for c in (constraints or []) if c.constraints]
    if named:
        problem = cp.Problem(problem.objective, problem.constraints + [k for c in named for k in c.constraints])
    status = _solve_cvxpy(problem, settings)
    if status in _INFEASIBLE:
        _diagnose(sys_.name, x, [anchor] if anchor is not None else [], named, settings)
    if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise RuntimeError(f"Clarabel did not solve {sys_.name}: status {status!r}")
    if status == cp.OPTIMAL_INACCURATE:
        log.warning("Clarabel reports an inaccurate solution for %s", sys_.name)
    xv = np.asarray(x.value, dtype=float).copy()
    K = sys_.known
    xv[K] = sys_.values[K]  # exact, not to solver tolerance
    MU = sys_.design()[:, ~K]
    g = -np.asarray(anchor.dual_value, dtype=float).reshape(-1) if anchor is not None else np.zeros(0)
    return SystemSolution(xv, (MU.T @ MU).tocsc(), g, problem=problem,
                          weights=_row_weights(sys_, xv, loss, threshold, grouping))


# =============================================================================== strain (V3)
@dataclass(frozen=True)
class AnchorStrain:
    """Lagrange-multiplier test of one anchor (V3). ``chi2_theta`` (1 dof, phase 1) and
    ``chi2_position`` (2 dof, phase 3) are None for unknown components; ``chi2``/``dof`` their sum;
    ``p_value`` = P(χ²_dof > chi2); ``strained`` when p_value < the level; ``gradient`` the cost
    gradient at the anchored coordinates (x, y, θ; NaN where not anchored) — the negated multipliers."""

    id: int
    kind: str
    chi2_theta: float | None
    chi2_position: float | None
    chi2: float
    dof: int
    p_value: float
    strained: bool
    gradient: tuple


def _release_statistics(M: sp.csc_matrix, known: np.ndarray, sol: SystemSolution, coord_sets: list) -> list:
    """Δχ²_c = ¼ g_cᵀ S_c⁺ g_c (V3) for each coordinate set c (global coordinate indices, all known)."""
    if not coord_sets:
        return []
    U = ~known
    MU = M[:, U]
    kpos = np.full(known.size, -1, np.int64)
    kpos[np.flatnonzero(known)] = np.arange(int(known.sum()))
    factor = sol.factorized()
    out = []
    batch = 64
    for s in range(0, len(coord_sets), batch):  # loop over anchors (not edges), in batches
        sets = coord_sets[s:s + batch]
        cols = np.concatenate(sets)
        Mc = M[:, cols]
        B = (MU.T @ Mc).toarray()
        X = factor.solve(B) if B.shape[0] else np.zeros_like(B)
        G = (Mc.T @ Mc).toarray() - B.T @ X
        off = 0
        for c in sets:
            j = slice(off, off + c.size)
            off += c.size
            Sc = 0.5 * (G[j, j] + G[j, j].T)
            g = sol.grad_known[kpos[c]]
            w, V = np.linalg.eigh(Sc)
            scale = max(float(np.abs(np.diag((Mc[:, j].T @ Mc[:, j]).toarray())).max()), np.finfo(float).tiny)
            ok = w > 1e-12 * scale
            out.append(float(0.25 * np.sum((V[:, ok].T @ g) ** 2 / w[ok])))
    return out


# =============================================================================== constraints (V9)
@dataclass
class NamedConstraint:
    """A named group of cvxpy constraints (``constraints`` may be empty when the helper does not
    apply to the phase at hand, e.g. a position box in phase 1)."""

    name: str
    constraints: list = field(default_factory=list)


class InfeasibleConstraintsError(ValueError):
    """The named convex constraints cannot all hold. ``names``: the constraints to blame (infeasible
    on their own, or an irreducible infeasible subset); ``phase``: "phase1" or "phase3"."""

    def __init__(self, message: str, names: list, phase: str):
        super().__init__(message)
        self.names = list(names)
        self.phase = phase


@dataclass(eq=False)
class PoseVariables:
    """Affine cvxpy expressions of every pose's coordinates in one phase's variable.

    ``phase`` 1 (variable θ ∈ ℝⁿ; ``x``/``y`` are None) or 3 (variable [p; θ] ∈ ℝ³ⁿ); ``x``, ``y``,
    ``theta`` (n,) expressions indexed by pose *index*; ``index(ids)`` converts pose ids (as in the
    file) to indices; ``theta_tree`` (n,) the regularized tree orientations (the branch on which θ
    lives, handy as ``orientation_bounds(center=...)``)."""

    graph: PoseGraph
    phase: int
    variable: cp.Variable
    theta_tree: np.ndarray

    @property
    def n(self) -> int:
        return self.graph.n_poses

    @property
    def x(self):
        return None if self.phase == 1 else self.variable[0:2 * self.n:2]

    @property
    def y(self):
        return None if self.phase == 1 else self.variable[1:2 * self.n:2]

    @property
    def theta(self):
        return self.variable if self.phase == 1 else self.variable[2 * self.n:]

    def index(self, ids=None) -> np.ndarray:
        """Pose indices (k,) of the pose ``ids`` (all poses when None), vectorized."""
        if ids is None:
            return np.arange(self.n)
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        order = np.argsort(self.graph.ids)
        pos = np.searchsorted(self.graph.ids[order], ids)
        pos = np.minimum(pos, self.n - 1)
        idx = order[pos]
        bad = self.graph.ids[idx] != ids
        if bad.any():
            raise GraphError(f"no pose with id {int(ids[bad][0])}")
        return idx

    def position_selector(self, ids=None) -> sp.csr_matrix:
        """Sparse (2k × 3n) matrix G with G @ variable = [x_v1, y_v1, x_v2, …] (phase 3 only)."""
        idx = self.index(ids)
        k = idx.size
        cols = np.stack([2 * idx, 2 * idx + 1], 1).reshape(-1)
        return sp.csr_matrix((np.ones(2 * k), (np.arange(2 * k), cols)), shape=(2 * k, 3 * self.n))


def halfplane_constraint(pv: PoseVariables, normals, offsets, *, poses=None, name: str = "half-planes") -> NamedConstraint:
    """Every pose in ``poses`` (ids; all when None) satisfies nᵢᵀp ≤ cᵢ for every half-plane i:
    ``normals`` (h, 2), ``offsets`` (h,). One vectorized constraint (k·h rows). Phase 3 only (empty in
    phase 1)."""
    if pv.phase == 1:
        return NamedConstraint(name)
    Nrm = np.atleast_2d(np.asarray(normals, dtype=float))
    c = np.atleast_1d(np.asarray(offsets, dtype=float))
    if Nrm.shape[1] != 2 or c.shape != (Nrm.shape[0],):
        raise ValueError(f"{name}: normals must be (h, 2) and offsets (h,)")
    G = pv.position_selector(poses)
    k = G.shape[0] // 2
    H = sp.kron(sp.identity(k), sp.csr_matrix(Nrm), format="csr")  # (k·h, 2k)
    return NamedConstraint(name, [(H @ G) @ pv.variable <= np.tile(c, k)])


def box_constraint(pv: PoseVariables, *, poses=None, xmin=-np.inf, xmax=np.inf, ymin=-np.inf, ymax=np.inf,
                   name: str = "box") -> NamedConstraint:
    """xmin ≤ x_v ≤ xmax and ymin ≤ y_v ≤ ymax for the poses ``poses`` (ids; all when None).
    Infinite bounds are omitted. Phase 3 only (empty in phase 1)."""
    if pv.phase == 1:
        return NamedConstraint(name)
    if not (xmin <= xmax and ymin <= ymax):
        log.info("%s: empty box (xmin > xmax or ymin > ymax)", name)
    normals, offsets = [], []
    for nrm, off in (((1, 0), xmax), ((-1, 0), -xmin), ((0, 1), ymax), ((0, -1), -ymin)):
        if np.isfinite(off):
            normals.append(nrm)
            offsets.append(off)
    if not normals:
        return NamedConstraint(name)
    return halfplane_constraint(pv, normals, offsets, poses=poses, name=name)


def polygon_constraint(pv: PoseVariables, vertices, *, poses=None, name: str = "polygon") -> NamedConstraint:
    """The poses ``poses`` (ids; all when None) stay in the convex polygon ``vertices`` (h, 2), given in
    either orientation: one half-plane nᵢᵀp ≤ nᵢᵀvᵢ per side, nᵢ the outward normal of side vᵢ → vᵢ₊₁.
    Raises ``ValueError`` if the polygon is not convex (or degenerate). Phase 3 only."""
    V = np.asarray(vertices, dtype=float)
    if V.ndim != 2 or V.shape[1] != 2 or V.shape[0] < 3:
        raise ValueError(f"{name}: a polygon needs (h ≥ 3, 2) vertices")
    E = np.roll(V, -1, axis=0) - V
    cross = E[:, 0] * np.roll(E, -1, axis=0)[:, 1] - E[:, 1] * np.roll(E, -1, axis=0)[:, 0]
    if not (np.all(cross > 0) or np.all(cross < 0)):
        raise ValueError(f"{name}: the polygon is not strictly convex")
    if pv.phase == 1:
        return NamedConstraint(name)
    sign = 1.0 if cross[0] > 0 else -1.0  # counter-clockwise: outward normal is (e_y, −e_x)
    normals = sign * np.column_stack([E[:, 1], -E[:, 0]])
    return halfplane_constraint(pv, normals, np.einsum("ha,ha->h", normals, V), poses=poses, name=name)


def orientation_bounds(pv: PoseVariables, *, poses=None, lower=-np.inf, upper=np.inf, center=None,
                       name: str = "orientation bounds") -> NamedConstraint:
    """lower ≤ θ_v − center_v ≤ upper for the poses ``poses`` (ids; all when None). ``center`` (k,) or
    scalar: the nominal orientations (e.g. a compass heading), moved by 2πk onto the branch of
    ``pv.theta_tree`` like an orientation anchor (V4) — θ is unwrapped, and a center one turn away
    would silently force an extra winding; default None: bounds on θ itself, on the unwrapped branch.
    Applies in phases 1 and 3."""
    idx = pv.index(poses)
    c = np.zeros(idx.size) if center is None else np.broadcast_to(np.asarray(center, dtype=float), idx.shape)
    if center is not None:  # bring the centers onto the branch of θ (as anchors are, V4)
        c = c + 2.0 * np.pi * _round_to(c, pv.theta_tree[idx])
    th = pv.theta[idx] - c
    out = []
    lo = np.broadcast_to(np.asarray(lower, dtype=float), idx.shape)
    hi = np.broadcast_to(np.asarray(upper, dtype=float), idx.shape)
    if np.isfinite(lo).any():
        f = np.isfinite(lo)
        out.append(th[np.flatnonzero(f)] >= lo[f]) if not f.all() else out.append(th >= lo)
    if np.isfinite(hi).any():
        f = np.isfinite(hi)
        out.append(th[np.flatnonzero(f)] <= hi[f]) if not f.all() else out.append(th <= hi)
    return NamedConstraint(name, out)


def _feasible(x: cp.Variable, fixed: list, named: list, settings) -> bool:
    prob = cp.Problem(cp.Minimize(0), fixed + [k for c in named for k in c.constraints])
    return _solve_cvxpy(prob, settings) not in _INFEASIBLE


def _diagnose(phase: str, x: cp.Variable, fixed: list, named: list, settings) -> None:
    """Name the constraints to blame and raise ``InfeasibleConstraintsError``: first those infeasible on
    their own (together with the anchors), else an irreducible infeasible subset by a deletion filter."""
    alone = [c.name for c in named if not _feasible(x, fixed, [c], settings)]
    if alone:
        which = ", ".join(repr(a) for a in alone)
        msg = (f"{phase}: constraint {which} is infeasible on its own (together with the anchors)" if len(alone) == 1
               else f"{phase}: constraints {which} are each infeasible on their own (together with the anchors)")
        raise InfeasibleConstraintsError(msg, alone, phase)
    keep = list(named)
    for c in list(named):  # deletion filter
        trial = [k for k in keep if k is not c]
        if not _feasible(x, fixed, trial, settings):
            keep = trial
    names = [c.name for c in keep]
    raise InfeasibleConstraintsError(
        f"{phase}: constraints {', '.join(repr(n) for n in names)} are jointly infeasible (each is feasible "
        "alone; dropping any one of them makes the rest feasible)", names, phase)


# =============================================================================== regularization (V4)
@dataclass(frozen=True, eq=False)
class AnchorRegularization:
    """2kπ correction of the anchored orientations and prior means against the tree (V4).

    ``index`` (a,) pose indices; ``source`` (a,) "anchor" / "prior"; ``value`` (a,) as given;
    ``k`` (a,) the integer corrections; ``residual_before`` (a,) value − θ_tree; ``residual`` (a,) after
    correction, in (−π, π]; ``ambiguous`` (a,) bool (|residual| > π − margin); ``theta_tree`` (n,) the
    tree orientations in the output frame; ``offset`` the tree's orientation offset and
    ``offset_from`` what fixed it ("anchor <id>", "prior <id>", "gauge", "procrustes")."""

    index: np.ndarray
    source: np.ndarray
    value: np.ndarray
    k: np.ndarray
    residual_before: np.ndarray
    residual: np.ndarray
    ambiguous: np.ndarray
    theta_tree: np.ndarray
    offset: float
    offset_from: str

    @property
    def corrected(self) -> np.ndarray:
        return self.value + 2.0 * np.pi * self.k

    @property
    def n_regularized(self) -> int:
        return int(np.count_nonzero(self.k))


def _round_to(value: np.ndarray, target: np.ndarray) -> np.ndarray:
    """k with value + 2πk − target ∈ (−π, π] (the tie rule of ``regularization``)."""
    return -np.ceil((value - target) / (2.0 * np.pi) - 0.5).astype(np.int64)


def _anchor_regularization(graph, theta_tree0, idx, source, value, offset, offset_from, margin):
    theta_tree = theta_tree0 + offset
    before = value - theta_tree[idx]
    k = _round_to(value, theta_tree[idx])
    res = before + 2.0 * np.pi * k
    amb = np.abs(res) > np.pi - margin
    if amb.any():
        ids = graph.ids[idx[amb]]
        log.warning("regularization: anchored/prior orientation(s) of pose(s) %s are within %.3g rad of ±π "
                    "from the tree's orientation, so their 2kπ correction is ambiguous",
                    ", ".join(str(i) for i in ids[:10]), margin)
    return AnchorRegularization(idx, source, value, k, before, res, amb, theta_tree, float(offset), offset_from)


def reround_edges(graph: PoseGraph, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Round every edge against an orientation estimate θ (n,): k_e = −round((δ_e − (θ_j − θ_i))/2π),
    δ_reg = δ + 2πk (residual in (−π, π]). Returns (delta_reg (m,), k (m,))."""
    k = _round_to(graph.delta, theta[graph.heads] - theta[graph.tails])
    return graph.delta + 2.0 * np.pi * k, k


# =============================================================================== results
@dataclass(frozen=True, eq=False)
class VariantPhase1:
    """Phase-1 result of a variant. ``theta`` (n,) in the output frame; ``theta_free`` (d_θ,);
    ``free`` (d_θ,) the poses of unknown orientation; ``info`` (d_θ, d_θ) LᵀL; ``system``; ``solution``."""

    theta: np.ndarray
    theta_free: np.ndarray
    free: np.ndarray
    info: sp.csc_matrix
    system: WeightedSystem
    solution: SystemSolution

    def variances(self) -> np.ndarray:
        """Marginal variances of θ̂ (n,), 0 at known orientations."""
        var = np.zeros(self.theta.size)
        if self.free.size:
            var[self.free] = block_diagonal_inverse(self.solution.factorized(), np.arange(self.free.size)[:, None])[:, 0, 0]
        return var


@dataclass(frozen=True, eq=False)
class VariantPhase3:
    """Phase-3 result of a variant. ``x`` (3n,) all coordinates [p; θ]; ``x_star`` (d_U,) the unknown
    ones; ``poses`` (n, 3); ``info`` (d_U, d_U); ``system``; ``solution``."""

    x: np.ndarray
    x_star: np.ndarray
    poses: np.ndarray
    info: sp.csc_matrix
    system: WeightedSystem
    solution: SystemSolution

    def pose_covariances(self) -> np.ndarray:
        """Marginal 3×3 covariance (n, 3, 3) of every pose (x, y, θ), zeros at known coordinates;
        selected blocks of (M_UᵀM_U)⁻¹, grouped by pattern of known coordinates (≤ 8 patterns)."""
        n = self.poses.shape[0]
        known = self.system.known
        coord = np.stack([2 * np.arange(n), 2 * np.arange(n) + 1, 2 * n + np.arange(n)], 1)  # (n, 3)
        upos = np.full(known.size, -1, np.int64)
        upos[~known] = np.arange(int((~known).sum()))
        pattern = known[coord] @ np.array([1, 2, 4])
        out = np.zeros((n, 3, 3))
        f = self.solution.factorized()
        for pat in np.unique(pattern):  # loop over ≤ 8 patterns
            poses = np.flatnonzero(pattern == pat)
            comp = np.flatnonzero(~known[coord[poses[0]]])
            if comp.size == 0:
                continue
            blocks = block_diagonal_inverse(f, upos[coord[poses][:, comp]])
            out[np.ix_(poses, comp, comp)] = blocks
        return out


@dataclass(eq=False)
class VariantResult(LagoResult):
    """A ``LagoResult`` of a constrained variant (everything in the output frame: ``phase1.theta`` and
    ``poses`` directly, no rigid move). Extra fields: ``anchors`` (list of ``Anchor``), ``priors``
    (list of ``Prior``), ``loss``, ``frame`` (how orientation/position were fixed), ``anchor_regularization``,
    ``strain`` (list of ``AnchorStrain``; None for robust or inequality-constrained runs, where the
    least-squares test does not apply), ``constraint_names``, ``robust`` (dict: ``edge_weights`` (m,)
    the smaller of the two phases' IRLS weights, ``rounds`` re-rounding rounds, ``k_changed``)."""

    anchors: list = field(default_factory=list)
    priors: list = field(default_factory=list)
    loss: str = "l2"
    frame: dict = field(default_factory=dict)
    anchor_regularization: AnchorRegularization | None = None
    strain: list | None = None
    constraint_names: list = field(default_factory=list)
    robust: dict | None = None

    @property
    def orientations(self) -> np.ndarray:
        return self.phase1.theta

    def pose_covariances(self) -> np.ndarray:
        return self.phase3.pose_covariances()

    @property
    def strained(self) -> list:
        """Ids of the strained anchors."""
        return [s.id for s in (self.strain or []) if s.strained]

    def prior_chi2(self) -> np.ndarray:
        """eᵀΛe per prior at the final poses (e = pose − mean, θ on the rounded branch), shape (q,)."""
        out = []
        for p in self.priors:
            e = self.poses[p.index] - p.mean
            e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
            out.append(float(e @ p.information @ e))
        return np.array(out)


# =============================================================================== the engine
def _resolve_tree(graph: PoseGraph, spanning_tree, ref: int):
    if isinstance(spanning_tree, str) and spanning_tree == "auto":
        try:
            return build_tree(graph, "odometry", anchor=ref)
        except GraphError as exc:
            log.warning("robust LAGO: no complete odometric chain (%s); using the BFS tree — the re-rounding "
                        "against the robust phase-1 estimate must then undo false loop closures in the tree", exc)
            return build_tree(graph, "bfs", anchor=ref)
    return build_tree(graph, spanning_tree, anchor=ref)


def _kabsch_angle(src: np.ndarray, dst: np.ndarray) -> float:
    """φ minimising Σ‖R(φ)(s − s̄) − (d − d̄)‖² (2-D, equal weights)."""
    S, D = src - src.mean(0), dst - dst.mean(0)
    H = S.T @ D
    return float(np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1]))


def _choose_reference(graph, anchors, priors, anchor) -> int:
    if anchor is not None:
        return graph.index_of(anchor)
    for pick in (lambda a: a.kind == "full", lambda a: a.theta is not None, lambda a: True):
        for a in anchors:
            if pick(a):
                return a.index
    if priors:
        return priors[0].index
    return 0  # the smallest id, as in lago()



def _solve_with_constraints(graph, system, level, phase, constraints_fn, theta_tree, known, values, loss, threshold,
                            grouping, solver_settings):
    """Solve one phase's cvxpy problem with the user's named constraints added (V9).

    ``level`` 1 (phase 1, θ only) or 3 (phase 3, [p; θ]); ``known``/``values`` the anchored entries.
    Infeasibility is diagnosed by ``_diagnose`` (raises naming the constraint). Returns
    (``SystemSolution``, constraint names)."""
    problem, x, anchor_c = system_problem(system, loss=loss, threshold=threshold, grouping=grouping)
    named = [c for c in constraints_fn(PoseVariables(graph, level, x, theta_tree)) if c.constraints]
    problem = cp.Problem(problem.objective, problem.constraints + [k for c in named for k in c.constraints])
    status = _solve_cvxpy(problem, solver_settings)
    if status in _INFEASIBLE:
        _diagnose(phase, x, [anchor_c] if anchor_c is not None else [], named, solver_settings)
    if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise RuntimeError(f"Clarabel did not solve {phase}: status {status!r}")
    xv = np.asarray(x.value, float).copy()
    xv[known] = values[known]
    MU = system.design()[:, ~known]
    g = -np.asarray(anchor_c.dual_value, float).reshape(-1) if anchor_c is not None else np.zeros(0)
    sol = SystemSolution(xv, (MU.T @ MU).tocsc(), g, problem=problem,
                         weights=_row_weights(system, xv, loss, threshold, grouping))
    return sol, [c.name for c in named]


def lago_variant(graph: PoseGraph, *, anchors=None, priors=None, constraints_fn: Callable | None = None,
                 loss: str = "l2", threshold: float = DEFAULT_THRESHOLD, grouping: str = "edge",
                 method: str = "closed_form", spanning_tree="bfs", anchor=None, anchor_pose=None,
                 margin: float = AMBIGUITY_MARGIN, reround: bool = False, reround_rounds: int = 5,
                 strain_level: float = STRAIN_LEVEL, solver_settings: dict | None = None,
                 backend: str = "auto", regularization: str = "tree") -> VariantResult:
    """The general engine behind ``anchored_lago``, ``constrained_lago`` and ``robust_lago`` (module
    docstring, V1–V10). All options keyword-only:

      anchors — ``{id: (x, y, θ)}`` hard anchors, None components unknown (``normalize_anchors``).
      priors — ``{id: (mean (3,), information (3, 3))}`` soft absolute measurements.
      constraints_fn — ``f(pv: PoseVariables) -> list[NamedConstraint]``, called for phase 1
        (``pv.phase == 1``) and phase 3; forces the cvxpy route.
      loss — ``"l2"`` (LAGO), ``"huber"`` or ``"l1"`` (V10; cvxpy route); ``threshold`` M (whitened
        units); ``grouping`` ``"edge"`` or ``"component"``.
      method — ``"closed_form"`` or ``"cvxpy"`` for the least-squares variants (robust/constrained
        runs always use cvxpy).
      spanning_tree — as in ``lago`` plus ``"auto"`` (odometric if the chain is complete, else BFS);
        rooted at the reference pose.
      anchor — id of the reference pose (see the module docstring); anchor_pose — gauge values for
        what no anchor or prior fixes (default the origin).
      margin — ambiguity margin of the regularization (rad).
      regularization — ``"tree"``, ``"chordal"`` or ``"integer"`` (as in ``lago``; the chordal relaxation is anchored at
        the reference pose and ignores anchors and priors: it only chooses the integers).
      reround — re-round every edge against the phase-1 estimate and re-solve phase 1 until no k
        changes (at most ``reround_rounds`` rounds; V10).
      strain_level — significance of the anchor strain test (V3).
      solver_settings — override ``CLARABEL_SETTINGS``; backend — sparse solver of the closed form.
    Returns a ``VariantResult``. Raises ``GraphError`` (disconnected graph, unknown id),
    ``ValueError`` (bad option or anchor), ``InfeasibleConstraintsError``.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {METHODS}")
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; expected one of {LOSSES}")
    if graph.n_edges == 0 and graph.n_poses > 1:
        raise GraphError(f"the graph has {graph.n_poses} poses and no edges: nothing links them")
    t_all = time.perf_counter()
    timings = {}
    if loss != "l2":
        solver_settings = {**ROBUST_SETTINGS, **(solver_settings or {})}
    anc = normalize_anchors(graph, anchors)
    pri = normalize_priors(graph, priors)
    gauge_pose = np.zeros(3) if anchor_pose is None else np.asarray(anchor_pose, dtype=float).reshape(3)
    use_cvxpy = method == "cvxpy" or loss != "l2" or constraints_fn is not None
    n = graph.n_poses
    ref = _choose_reference(graph, anc, pri, anchor)
    th_anc = [a for a in anc if a.theta is not None]
    pos_anc = [a for a in anc if a.position is not None]

    # ---- frame: orientation offset of the tree, gauge coordinates
    frame = {"reference": int(graph.ids[ref])}
    theta_gauge = None
    if not th_anc and not pri and len(pos_anc) >= 2:
        prov = lago_variant(graph, anchors={int(graph.ids[ref]): (0.0, 0.0, 0.0)}, loss=loss, threshold=threshold,
                            grouping=grouping, method=method, spanning_tree=spanning_tree, anchor=None,
                            margin=margin, reround=reround, reround_rounds=reround_rounds,
                            solver_settings=solver_settings, backend=backend, strain_level=strain_level,
                            regularization=regularization)
        idx = np.array([a.index for a in pos_anc])
        theta_gauge = _kabsch_angle(prov.poses[idx, :2], np.array([a.position for a in pos_anc]))
        frame["orientation"] = f"procrustes: provisional LAGO rotated by {theta_gauge:.6g} rad onto {len(pos_anc)} position anchors"
    elif not th_anc and not pri:
        theta_gauge = float(gauge_pose[2])
        frame["orientation"] = f"gauge: θ of pose {graph.ids[ref]} := {theta_gauge:.6g}"
    else:
        frame["orientation"] = "anchors" if th_anc else "priors"
    pos_gauge = not pos_anc and not pri
    frame["position"] = (f"gauge: position of pose {graph.ids[ref]} := ({gauge_pose[0]:.6g}, {gauge_pose[1]:.6g})"
                         if pos_gauge else ("anchors" if pos_anc else "priors"))

    t = time.perf_counter()
    tree = _resolve_tree(graph, spanning_tree, ref)
    timings["tree"] = time.perf_counter() - t

    t = time.perf_counter()
    reg = regularize(graph, tree, regularization=regularization, margin=margin, backend=backend)
    unc = P.edge_uncertainty(graph)
    tt0 = reg.reference  # 0 at the root: θ_tree (tree rounding) or the chordal φ̃, the branch δ_reg follows
    # offset: the reference's own anchor/prior if any, else the first one
    first = sorted(th_anc, key=lambda a: a.index != ref)
    firstp = sorted(pri, key=lambda p: p.index != ref)
    if first:
        offset, offset_from = first[0].theta - tt0[first[0].index], f"anchor {first[0].id}"
    elif firstp:
        offset, offset_from = firstp[0].mean[2] - tt0[firstp[0].index], f"prior {firstp[0].id}"
    else:
        offset, offset_from = theta_gauge, "procrustes" if frame["orientation"].startswith("procrustes") else "gauge"
    a_idx = np.array([a.index for a in th_anc] + [p.index for p in pri], np.int64)
    a_src = np.array(["anchor"] * len(th_anc) + ["prior"] * len(pri))
    a_val = np.array([a.theta for a in th_anc] + [p.mean[2] for p in pri], float)
    areg = _anchor_regularization(graph, tt0, a_idx, a_src, a_val, offset, offset_from, margin)
    reg = replace(reg, theta_tree=areg.theta_tree)
    corrected = areg.corrected
    th_known = np.zeros(n, bool)
    th_vals = np.zeros(n)
    nt = len(th_anc)
    th_known[a_idx[:nt]] = True
    th_vals[a_idx[:nt]] = corrected[:nt]
    if not th_anc and not pri:
        th_known[ref] = True
        th_vals[ref] = theta_gauge
    pr = _prior_arrays(pri, corrected[nt:])
    timings["regularization"] = time.perf_counter() - t

    # ---- phase 1 (+ re-rounding)
    t = time.perf_counter()
    problems = {}
    c1 = []
    delta_reg = reg.delta_reg

    def solve1(dreg):
        s1 = phase1_system(graph, dreg, unc, th_known, th_vals, pr)
        if not use_cvxpy:
            return s1, solve_system(s1, backend=backend)
        if constraints_fn is not None:
            sol, names = _solve_with_constraints(graph, s1, 1, "phase1", constraints_fn, areg.theta_tree, th_known,
                                                 th_vals, loss, threshold, grouping, solver_settings)
            c1[:] = names
            return s1, sol
        return s1, solve_system_cvxpy(s1, loss=loss, threshold=threshold, grouping=grouping, settings=solver_settings)

    sys1, sol1 = solve1(delta_reg)
    rounds, k_changed = 0, 0
    if reround:
        for rounds in range(1, reround_rounds + 1):
            new_dreg, _ = reround_edges(graph, sol1.x)
            changed = int(np.count_nonzero(np.rint((new_dreg - delta_reg) / (2 * np.pi))))
            if changed == 0:
                rounds -= 1
                break
            k_changed += changed
            log.info("re-rounding against the phase-1 estimate: %d edge(s) changed k (round %d)", changed, rounds)
            delta_reg = new_dreg
            sys1, sol1 = solve1(delta_reg)
        reg = replace(reg, delta_reg=delta_reg, k=np.rint((delta_reg - graph.delta) / (2 * np.pi)).astype(np.int64))
    if sol1.problem is not None:
        problems["phase1"] = sol1.problem
    free_th = np.flatnonzero(~th_known)
    theta = sol1.x
    timings["phase1"] = time.perf_counter() - t

    # ---- phase 2
    t = time.perf_counter()
    w1 = sol1.weights if sol1.weights is not None else np.ones(sys1.W.shape[0])
    L = (sp.diags(np.sqrt(w1)) @ sys1.design())[:, free_th]
    ph2 = anchored_phase2(graph, theta, unc, free_th, L, sys1.groups)
    timings["phase2"] = time.perf_counter() - t

    # ---- phase 3
    t = time.perf_counter()
    known3 = np.zeros(3 * n, bool)
    vals3 = np.zeros(3 * n)
    for a in pos_anc:  # loop over anchors (few), not edges
        known3[2 * a.index:2 * a.index + 2] = True
        vals3[2 * a.index:2 * a.index + 2] = a.position
    if pos_gauge:
        known3[2 * ref:2 * ref + 2] = True
        vals3[2 * ref:2 * ref + 2] = gauge_pose[:2]
    known3[2 * n:] = th_known
    vals3[2 * n:] = th_vals
    sys3 = phase3_system(graph, ph2, known3, vals3, pr)
    c3 = []
    if not use_cvxpy:
        sol3 = solve_system(sys3, backend=backend)
    else:
        if constraints_fn is not None:
            sol3, c3 = _solve_with_constraints(graph, sys3, 3, "phase3", constraints_fn, areg.theta_tree, known3,
                                               vals3, loss, threshold, grouping, solver_settings)
        else:
            sol3 = solve_system_cvxpy(sys3, loss=loss, threshold=threshold, grouping=grouping, settings=solver_settings)
        problems["phase3"] = sol3.problem
    x = sol3.x
    poses = np.column_stack([x[0:2 * n:2], x[1:2 * n:2], x[2 * n:]])
    timings["phase3"] = time.perf_counter() - t

    ph1 = VariantPhase1(theta, theta[free_th], free_th, sol1.info, sys1, sol1)
    ph3 = VariantPhase3(x, x[~known3], poses, sol3.info, sys3, sol3)

    # ---- strain (V3): least squares without inequality constraints only
    strain = None
    if loss == "l2" and constraints_fn is None and anc:
        strain = _strain_report(graph, anc, sys1, sol1, sys3, sol3, strain_level)
    robust = None
    if loss != "l2":
        m = graph.n_edges
        w = np.ones(m)
        for s, sol in ((sys1, sol1), (sys3, sol3)):
            g = s.groups >= 0
            np.minimum.at(w, s.groups[g], sol.weights[g])
        robust = {"edge_weights": w, "rounds": rounds, "k_changed": k_changed, "threshold": threshold,
                  "grouping": grouping}
    timings["total"] = time.perf_counter() - t_all
    log.info("LAGO variant (%s, loss %s, %s tree): %d anchors, %d priors, %.3f s", method if not use_cvxpy else "cvxpy",
             loss, tree.kind, len(anc), len(pri), timings["total"])
    return VariantResult(graph=graph, poses=poses, anchor=ref, anchor_pose=poses[ref].copy(),
                         method="cvxpy" if use_cvxpy else method, tree=tree, regularization=reg, uncertainty=unc,
                         phase1=ph1, phase2=ph2, phase3=ph3, timings=timings, problems=problems, anchors=anc,
                         priors=pri, loss=loss, frame=frame, anchor_regularization=areg, strain=strain,
                         constraint_names=sorted(set(c1) | set(c3)), robust=robust)


def _strain_report(graph, anc, sys1, sol1, sys3, sol3, level) -> list:
    n = graph.n_poses
    th_sets = [np.array([a.index]) for a in anc if a.theta is not None]
    p_sets = [np.array([2 * a.index, 2 * a.index + 1]) for a in anc if a.position is not None]
    chi_th = _release_statistics(sys1.design(), sys1.known, sol1, th_sets)
    chi_p = _release_statistics(sys3.design(), sys3.known, sol3, p_sets)
    kpos1 = np.cumsum(sys1.known) - 1
    kpos3 = np.cumsum(sys3.known) - 1
    out, it, ip = [], iter(chi_th), iter(chi_p)
    for a in anc:  # loop over anchors
        ct = next(it) if a.theta is not None else None
        cpv = next(ip) if a.position is not None else None
        dof = (1 if ct is not None else 0) + (2 if cpv is not None else 0)
        total = (ct or 0.0) + (cpv or 0.0)
        pval = float(sps.chi2.sf(total, dof))
        grad = [np.nan, np.nan, np.nan]
        if a.position is not None:
            grad[0:2] = sol3.grad_known[kpos3[[2 * a.index, 2 * a.index + 1]]]
        if a.theta is not None:
            grad[2] = sol1.grad_known[kpos1[a.index]]
        out.append(AnchorStrain(a.id, a.kind, ct, cpv, total, dof, pval, pval < level, tuple(float(g) for g in grad)))
    bad = [s for s in out if s.strained]
    if bad:
        log.warning("%d of %d anchors are strained (hard anchors cannot compromise: the measurement residuals absorb "
                    "the inconsistency): %s", len(bad), len(out),
                    "; ".join(f"anchor {s.id} ({s.kind}): Lagrange-multiplier χ² = {s.chi2:.4g} with {s.dof} dof, "
                              f"p = {s.p_value:.2g}" for s in bad[:10]))
    return out


# =============================================================================== entry points
def anchored_lago(graph: PoseGraph, *, anchors=None, priors=None, method: str = "closed_form", spanning_tree="bfs",
                  anchor=None, anchor_pose=None, margin: float = AMBIGUITY_MARGIN,
                  strain_level: float = STRAIN_LEVEL, solver_settings: dict | None = None,
                  backend: str = "auto", regularization: str = "tree") -> VariantResult:
    """LAGO with hard anchors and/or priors (V1–V8), closed form or cvxpy (``method``); what
    ``lago(graph, anchors=...)`` runs. See ``lago_variant`` for the options and the module docstring
    for the frame decision. ``result.strain`` holds the per-anchor Lagrange-multiplier test (V3)."""
    return lago_variant(graph, anchors=anchors, priors=priors, method=method, spanning_tree=spanning_tree,
                        anchor=anchor, anchor_pose=anchor_pose, margin=margin, strain_level=strain_level,
                        solver_settings=solver_settings, backend=backend, regularization=regularization)


def constrained_lago(graph: PoseGraph, constraints_fn: Callable, *, anchors=None, priors=None, loss: str = "l2",
                     threshold: float = DEFAULT_THRESHOLD, spanning_tree="bfs", anchor=None, anchor_pose=None,
                     margin: float = AMBIGUITY_MARGIN, solver_settings: dict | None = None) -> VariantResult:
    """LAGO with named convex constraints (V9): phases 1 and 3 as cvxpy problems plus
    ``constraints_fn(pv) -> list[NamedConstraint]`` (called with ``PoseVariables`` of each phase; use
    ``box_constraint``, ``polygon_constraint``, ``halfplane_constraint``, ``orientation_bounds``, or
    ``NamedConstraint(name, [...])`` with any cvxpy constraint on ``pv.x``, ``pv.y``, ``pv.theta``).
    Raises ``InfeasibleConstraintsError`` naming the constraints when they cannot hold."""
    return lago_variant(graph, anchors=anchors, priors=priors, constraints_fn=constraints_fn, loss=loss,
                        threshold=threshold, method="cvxpy", spanning_tree=spanning_tree, anchor=anchor,
                        anchor_pose=anchor_pose, margin=margin, solver_settings=solver_settings)


def _consistency_tree(graph: PoseGraph, err: np.ndarray) -> np.ndarray:
    """Edge indices of a minimum spanning tree with weight = ``err`` (m,) (among parallel edges the one
    with the smallest error); vectorized with ``scipy.sparse.csgraph``."""
    from scipy.sparse import csgraph

    n = graph.n_poses
    lo = np.minimum(graph.tails, graph.heads)
    hi = np.maximum(graph.tails, graph.heads)
    keys = lo * n + hi
    order = np.lexsort((np.arange(err.size), err, keys))
    first = np.ones(order.size, bool)
    first[1:] = keys[order][1:] != keys[order][:-1]
    best = order[first]
    # adding a constant to every weight leaves the MST unchanged and keeps zero errors as edges
    Wm = sp.csr_matrix((err[best] + 1.0, (lo[best], hi[best])), shape=(n, n))
    T = csgraph.minimum_spanning_tree(Wm).tocoo()
    return best[np.searchsorted(keys[best], T.row * n + T.col)]


def robust_lago(graph: PoseGraph, *, loss: str = "huber", threshold: float = DEFAULT_THRESHOLD,
                grouping: str = "edge", spanning_tree="auto", reround: bool = True, reround_rounds: int = 5,
                gate: float | None = None, gate_rounds: int = 5, anchors=None, priors=None,
                constraints_fn: Callable | None = None, anchor=None, anchor_pose=None,
                margin: float = AMBIGUITY_MARGIN, solver_settings: dict | None = None) -> VariantResult:
    """LAGO with a convex robust loss on the edges (V10): ``"huber"`` (default) or ``"l1"``, threshold
    M in whitened units, on the odometric tree when available (``spanning_tree="auto"``) and with every
    edge re-rounded against the robust phase-1 estimate (``reround``). ``result.robust["edge_weights"]``
    (m,) are the IRLS weights (< 1: down-weighted, suspected outliers).

    gate — None (default): return the convex estimate. A float τ (whitened units, e.g.
      ``GATE_THRESHOLD``): then use the convex estimate only to *classify* the edges (V11): an edge
      whose whitened error √(eᵀΩe) of eq. (3) at the current estimate exceeds τ is rejected, except the
      edges of a *trusted* spanning tree, which keeps the graph connected: the odometric tree when the
      robust stage used it (false loop closures are never odometric), else — a BFS tree may contain
      false loop closures — the minimum spanning tree weighted by that error (best effort: at a
      strongly biased convex estimate it can thread through outliers; measured in the lecture).
      Least-squares LAGO then runs on the accepted edges (on the trusted tree, re-rounded), and the
      classification is repeated at the new estimate until it no longer changes (at most
      ``gate_rounds`` times). Convex losses bound an outlier's influence
      but do not remove it: with 10 % false loop closures their bounded pulls still bend weakly
      constrained loops (the lecture measures ~20× the outlier-free error); the gated estimate
      matches the outlier-free LAGO. The result's ``robust`` dict then also has ``inliers`` (m,) bool,
      ``gate``, ``gate_rounds``, ``convex_poses`` (the convex estimate) and ``subgraph`` (the accepted
      edges, to which ``phase1``…``phase3`` and ``regularization`` refer).
    """
    if loss == "l2":
        raise ValueError("robust_lago needs loss 'huber' or 'l1'")
    if gate is not None and not gate > 0:
        raise ValueError(f"gate must be > 0 or None, got {gate}")
    res = lago_variant(graph, anchors=anchors, priors=priors, constraints_fn=constraints_fn, loss=loss,
                       threshold=threshold, grouping=grouping, method="cvxpy", spanning_tree=spanning_tree,
                       anchor=anchor, anchor_pose=anchor_pose, margin=margin, reround=reround,
                       reround_rounds=reround_rounds, solver_settings=solver_settings)
    if gate is None:
        return res
    from .cost import whitened_errors

    tree = res.tree.tree_edges
    trust_tree = res.tree.kind == "odometry"
    if not trust_tree:
        log.warning("robust LAGO gating without an odometric tree: the spanning tree used to keep the graph "
                    "connected is the minimum-error tree at the convex estimate, which can contain false loop "
                    "closures when that estimate is strongly biased")
    convex = res
    poses, keep_prev, rounds = res.poses, None, 0
    sub = graph
    for rounds in range(1, gate_rounds + 1):
        err = whitened_errors(graph, poses)
        keep = err <= gate
        trusted = tree if trust_tree else _consistency_tree(graph, err)
        keep[trusted] = True  # connectivity: the trusted spanning tree is never rejected
        if keep_prev is not None and np.array_equal(keep, keep_prev):
            rounds -= 1
            break
        keep_prev = keep
        sub = graph.subgraph_edges(keep)
        sub_tree = (np.cumsum(keep) - 1)[trusted]
        res = lago_variant(sub, anchors=anchors, priors=priors, constraints_fn=constraints_fn, loss="l2",
                           method="cvxpy" if constraints_fn is not None else "closed_form", spanning_tree=sub_tree,
                           anchor=int(graph.ids[convex.anchor]), anchor_pose=anchor_pose, margin=margin,
                           reround=True, reround_rounds=reround_rounds, solver_settings=solver_settings)
        poses = res.poses
        log.info("gating round %d: %d of %d edges rejected (whitened error > %.3g)", rounds,
                 int((~keep).sum()), graph.n_edges, gate)
    robust = dict(convex.robust)
    robust.update(inliers=keep_prev, gate=float(gate), gate_rounds=rounds, convex_poses=convex.poses, subgraph=sub)
    timings = dict(res.timings)
    timings["convex"] = convex.timings["total"]
    return replace(res, graph=graph, loss=loss, robust=robust, timings=timings)


def compare_anchored_methods(graph: PoseGraph, *, anchors=None, priors=None, solver_settings: dict | None = None,
                             **kwargs) -> tuple[VariantResult, dict]:
    """``compare_methods`` for anchored LAGO: the closed form, then phases 1 and 3 as cvxpy problems (with
    the anchors as equality constraints) **on the same inputs**. Report: ``max_rel_diff`` {phase1, phase3}
    (over the unknown coordinates), ``max_rel_diff_gradient`` {phase1, phase3} (cvxpy's −dual vs the
    closed form's g_K, relative to max |g_K|), ``cvxpy_timings``, ``problems``."""
    res = anchored_lago(graph, anchors=anchors, priors=priors, method="closed_form", **kwargs)
    t = time.perf_counter()
    s1 = solve_system_cvxpy(res.phase1.system, settings=solver_settings)
    t1 = time.perf_counter() - t
    t = time.perf_counter()
    s3 = solve_system_cvxpy(res.phase3.system, settings=solver_settings)
    t3 = time.perf_counter() - t
    U1, U3 = ~res.phase1.system.known, ~res.phase3.system.known

    def gdiff(a, b):
        if a.size == 0:
            return 0.0
        return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))

    report = {
        "max_rel_diff": {"phase1": relative_difference(s1.x[U1], res.phase1.solution.x[U1]),
                         "phase3": relative_difference(s3.x[U3], res.phase3.solution.x[U3])},
        "max_rel_diff_gradient": {"phase1": gdiff(s1.grad_known, res.phase1.solution.grad_known),
                                  "phase3": gdiff(s3.grad_known, res.phase3.solution.grad_known)},
        "cvxpy_timings": {"phase1": t1, "phase3": t3},
        "problems": {"phase1": s1.problem, "phase3": s3.problem},
    }
    return res, report
