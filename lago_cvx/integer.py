r"""Orientation regularization as an integer program (the seed's Section IV-E, Theorem 3, made exact).

The seed's 2kπ rounding (``lago_cvx.regularization``) is the closed-form solution of a *decoupled*
integer least-squares problem. This module writes the *weighted* problem that phase 1 of LAGO actually
minimises, explicitly in cvxpy as a mixed-integer problem, solves it exactly (SCIP, or a dependency-free
enumeration for tiny problems), and compares the two.

Notation (as in ``lago_cvx.graph``): n poses, m edges, a spanning tree T rooted at the anchor, its
l = m − n + 1 chords; δ ∈ ℝ^m the measured (wrapped) relative orientations, P_δ = diag(var_δ) (m × m,
``EdgeUncertainty.var_delta``); A2 (n−1 × m) the reduced incidence matrix; C = [I_l B] (l × m) the
fundamental cycle basis (``cycle_basis``); E (m × l) the chord selector (E[chord_c, c] = 1), so C E = I_l.

The integer program
-------------------
An integer vector k ∈ ℤ^m corrects the measurements, δ_reg = δ + 2πk. Phase 1 (eq. (13)) then costs

    J(k) = min_θ ‖P_δ^{-1/2}(A2ᵀθ − δ − 2πk)‖²                                                (1)

and the best correction is argmin_k J(k). Two equivalent forms:

(b) **phase-1 form** (sparse, n − 1 + l unknowns) — phase 1 of LAGO with the integers left free:

    min_{θ ∈ ℝ^{n−1}, k ∈ ℤ^l}  ‖P_δ^{-1/2}(A2ᵀθ − δ − 2π E k)‖²,                            (2)

    θ are the unwrapped orientations (anchor at 0). ``phase1_form_problem``.

(a) **cycle form** (dense, l unknowns) — θ eliminated. Because C A2ᵀ = 0 and rank A2 + rank C = m, the
    whitened columns P_δ^{-1/2}A2ᵀ and P_δ^{1/2}Cᵀ span orthogonal complements of ℝ^m, so the phase-1
    residual of any right-hand side d is  min_θ ‖P_δ^{-1/2}(A2ᵀθ − d)‖² = (Cd)ᵀ(C P_δ Cᵀ)⁻¹(Cd).  With
    d = δ + 2πEk and CE = I_l, Cd = r + 2πk with r = Cδ (the cycle residuals, ``residual_before``):

    min_{k ∈ ℤ^l}  ‖L⁻¹(r + 2πk)‖²,     S = C P_δ Cᵀ = L Lᵀ  (l × l, dense, Cholesky).           (3)

    ``cycle_form_problem``. Both are written ``cp.sum_squares(W @ residual)`` with a whitening W
    (never ``quad_form``); the optimal values agree (tests/test_integer.py).

**Gauge (why chords only).** J depends on k only through the cycle integers q = Ck ∈ ℤ^l:
C(δ + 2πk) = r + 2πCk. Integer shifts k ↦ k + A2ᵀz (z ∈ ℤ^{n−1}) only move the unwrapped θ by 2πz and
leave Ck unchanged, and every q ∈ ℤ^l is reached by the chord-only vector k = Eq. So tree edges keep
k = 0 without loss of generality, and **two per-edge k-vectors are equivalent iff their cycle
integers Ck coincide** — ``cycle_integers`` computes them for any per-edge k (e.g. one produced by a
relaxation that puts integers on tree edges), as round((C(δ + 2πk) − Cδ)/2π) = Ck, evaluated through
the tree's path sums (no C formed).

**The seed's rounding solves the decoupled problem.** The rounding of Theorem 3,
k_c = −round(r_c/2π), is the exact minimiser of

    min_{k ∈ ℤ^l}  Σ_c (r + 2πk)_c²                                                             (4)

whose terms are independent (each chord picks the integer that brings its own corrected residual into
(−π, π]). It also minimises (3) whenever S is diagonal (each term is then only scaled by 1/S_cc). But

    S_cc' = Σ_{e ∈ cycle c ∩ cycle c'} ± var_δ,e                                                (5)

is not diagonal: two fundamental cycles that share tree edges share their noise. When they share a long
noisy tree path, r_c and r_c' carry a common error ε; S⁻¹ then penalises the *difference* of the
corrected residuals (known precisely: only the chords and the unshared edges contribute) heavily and their
common part (variance ≈ the shared path's) lightly. If ε pushes r_c just below π and r_c' just above
π, rounding maps them to ≈ +π and ≈ −π — a 2π jump in a precisely known difference — whereas (3) moves
both together. ``tests/test_integer.py`` builds exactly this graph and derives the answer by hand.

**Bounding the search (exact, not a heuristic).** With J₀ = J(k_round), every minimiser has J ≤ J₀,
and for x = r + 2πk, Cauchy–Schwarz gives |x_c| = |(Lᵀe_c)ᵀ(L⁻¹x)| ≤ √S_cc ‖L⁻¹x‖, hence

    |r_c + 2πk_c| ≤ ρ_c = √(J₀ S_cc),    k_c ∈ [⌈(−r_c − ρ_c)/2π⌉, ⌊(−r_c + ρ_c)/2π⌋].           (6)

This box (``exact_box``) contains every optimum, so adding it as bounds changes nothing but gives the
branch-and-bound finite integer ranges. ``max_shift=K`` additionally imposes |k − k_round| ≤ K (a user
restriction; the result is then optimal only inside that box and ``box_restricted`` says so).
At low noise the box (6) is a single point — the rounding is then *certified* optimal with no search
(every Manhattan world of the sweep up to σθ = 0.1; tests/test_integer.py checks one).

Solvers
-------
* ``solver="SCIP"`` (default; the optional extra ``pip install "lago-cvx[mip]"`` = ``pyscipopt``): cvxpy
  hands the problem to SCIP as a mixed-integer SOCP (``sum_squares`` becomes a second-order cone).
  HiGHS (installed with cvxpy) and SciPy's MILP cannot take it: cvxpy's HiGHS interface is
  mixed-integer only for LPs and HiGHS has no MIQP (``SolverError: The solver HIGHS cannot solve this
  problem``). SCIP's outer approximation of *one* (m+2)-dimensional cone stalls in the phase-1 form
  (a 20-pose, 2-chord graph was not proven optimal in 30 s); writing the same sum of squares as
  ``cp.sum(cp.square(W @ residual))`` — m small cones, identical value — solves it in 0.1 s, so the
  phase-1 form uses that (``split=True``). The cycle form's dense W keeps ``cp.sum_squares``.
  Even so the phase-1 form is slow beyond a few dozen poses — measured here (2 cores), Manhattan worlds,
  box (6): 60 poses / 26 chords at σθ = 0.4 (25 free integers) 22 s against 1.6 s for the cycle form;
  80 poses / 19 chords at σθ = 0.5: 118 s against 1.6 s; 150 poses / 54 chords at σθ = 0.3: not done
  in 120 s (incumbent far from optimal) against 9.6 s. With the plain box |k − k_round| ≤ 2 instead of
  (6), 60 poses / 26 chords at σθ = 0.05: 116 s against 0.4 s. So the cycle form is the main path and
  the phase-1 form a cross-check for small graphs. The enumeration solves all of these in < 0.1 s.
  Even the cycle form's branch-and-bound is far slower than the enumeration once many integers are
  free: a 100-pose world with 52 chords at σθ = 0.5 (all 52 free in the box) — SCIP finds the optimum
  but cannot prove it in 60 s, the enumeration proves it in 0.01–0.05 s (500–7 640 nodes); a 3-lap
  circle with 91 chords at σθ = 0.2: SCIP 59 s, enumeration milliseconds; same integers.
* ``solver="enumerate"``: exact Schnorr–Euchner sphere decoding of (3) (LAMBDA-style integer least
  squares), no dependency. Order: min-variance pivoted Cholesky of S/(2π)² (the best-determined cycle
  integer first); initial radius J₀ (so the rounding is the incumbent and ties keep it); the box (6)
  (∩ the user box). ``max_nodes`` bounds the work and raises if exceeded (large, noisy problems).
* Any other cvxpy mixed-integer solver name (e.g. ``"GUROBI"``, ``"MOSEK"``) is passed through.

Results are always re-evaluated exactly in NumPy at the returned integers (``objective``); the solver's
own value is kept in ``solver_value``. A solver stopped by its time limit returns its incumbent with
status ``optimal_inaccurate`` (SCIP's own status is in ``solver_status``); if that incumbent costs more
than the rounding (SCIP starts without it: cvxpy cannot warm-start SCIP), the rounding — feasible and
cheaper — is returned instead, with the same status and a warning (``solver_status`` says so). Never a
point worse than the rounding, never an unproven point reported as optimal.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .graph import SpanningTree, cycle_basis, reduced_incidence, spanning_tree as build_tree
from .phases import EdgeUncertainty, edge_uncertainty
from .posegraph import PoseGraph
from .regularization import _round_residual, check_angles, tree_cycle_residuals

__all__ = [
    "MIP_EXTRA", "MissingSolverError", "SearchLimitError", "CycleData", "cycle_data", "exact_box",
    "cycle_integers", "true_edge_integers", "weighted_cycle_cost", "rounding_cost",
    "cycle_form_problem", "phase1_form_problem", "enumerate_integers",
    "IntegerRegularization", "integer_regularization", "compare_with_rounding",
    "noise_sweep", "format_sweep",
]

log = logging.getLogger(__name__)

TWO_PI = 2.0 * np.pi

#: The enumeration logs its progress every this many nodes (≈ 5–10 s on M3500-sized problems).
PROGRESS_NODES = 200_000

#: pip requirement that installs the default mixed-integer solver (SCIP through pyscipopt).
MIP_EXTRA = 'pip install "lago-cvx[mip]"'

#: Solver names accepted besides cvxpy's: the dependency-free exact enumeration.
ENUMERATE = "enumerate"

#: Relative tolerance under which a candidate must beat the incumbent to replace it (ties keep the
#: rounding, so "equal to rounding" is decided by cost, not by floating-point noise).
TIE_RTOL = 1e-10


class MissingSolverError(ImportError):
    """The requested mixed-integer solver is not installed; the message names the pip extra."""


class SearchLimitError(RuntimeError):
    """The exact enumeration exceeded ``max_nodes`` (too many uncertain integers); the message says what to do."""


def _require_solver(solver: str) -> str:
    """Check that ``solver`` can be used; return cvxpy's name for it. Lazy: imports nothing heavy
    unless asked. Raises ``MissingSolverError`` naming the extra for SCIP."""
    name = str(solver).upper()
    if name == "SCIP":
        try:
            import pyscipopt  # noqa: F401
        except ImportError as exc:
            raise MissingSolverError(
                "the integer regularization needs a mixed-integer solver and SCIP (pyscipopt) is not "
                f"installed: {MIP_EXTRA}  (or pass solver=\"enumerate\" for the dependency-free exact "
                "enumeration, fine for tiny problems)") from exc
        if name not in cp.installed_solvers():
            raise MissingSolverError(f"pyscipopt is importable but cvxpy does not list SCIP as installed "
                                     f"({cp.installed_solvers()}); reinstall with {MIP_EXTRA}")
        return name
    if name not in cp.installed_solvers():
        raise MissingSolverError(f"solver {solver!r} is not installed for cvxpy (installed: "
                                 f"{cp.installed_solvers()}); the default SCIP comes with {MIP_EXTRA}")
    return name


# --------------------------------------------------------------------------- cycle quantities
@dataclass(frozen=True, eq=False)
class CycleData:
    """Everything eq. (3) needs, for one graph and tree (small graphs: S is dense l × l).

    ``chords`` (l,) chord edge indices; ``C`` sparse (l, m) cycle basis; ``r`` (l,) r = Cδ;
    ``S`` (l, l) C P_δ Cᵀ; ``L`` (l, l) lower Cholesky factor of S; ``W`` (l, l) = L⁻¹ (whitening);
    ``k_round`` (l,) the seed's rounding k_c = −round(r_c/2π) as cycle integers (as ``regularize_tree``);
    ``rounding_edges`` (m,) the rounding's per-edge k."""

    tree: SpanningTree
    chords: np.ndarray
    C: sp.csr_matrix
    r: np.ndarray
    S: np.ndarray
    L: np.ndarray
    W: np.ndarray
    k_round: np.ndarray
    rounding_edges: np.ndarray

    @property
    def n_chords(self) -> int:
        return int(self.chords.size)

    def cost(self, q) -> np.ndarray | float:
        """J = ‖W(r + 2πq)‖² of eq. (3) for cycle integers q of shape (l,) or (..., l)."""
        x = self.r + TWO_PI * np.asarray(q, dtype=float)
        w = x @ self.W.T
        out = np.einsum("...i,...i->...", w, w)
        return float(out) if np.ndim(out) == 0 else out


def cycle_data(graph: PoseGraph, tree: SpanningTree, *, unc: EdgeUncertainty | None = None) -> CycleData:
    """Build ``CycleData`` (eq. (3)): r = Cδ through the tree's path sums, S = C P_δ Cᵀ, L, W = L⁻¹."""
    check_angles(graph)
    unc = edge_uncertainty(graph) if unc is None else unc
    c = tree.chords
    r = tree_cycle_residuals(graph, tree)
    C = cycle_basis(graph, tree).tocsr()
    S = (C.multiply(unc.var_delta[None, :]) @ C.T).toarray() if c.size else np.zeros((0, 0))
    S = 0.5 * (S + S.T)
    L = np.linalg.cholesky(S) if c.size else S
    W = sla.solve_triangular(L, np.eye(c.size), lower=True) if c.size else S
    k_edges = np.zeros(graph.n_edges, np.int64)  # the seed's rounding (regularize_tree), without its warnings
    k_edges[c] = _round_residual(r)
    return CycleData(tree=tree, chords=c, C=C, r=r, S=S, L=L, W=W, k_round=k_edges[c].copy(),
                     rounding_edges=k_edges)


def exact_box(data: CycleData, *, max_shift: int | None = None, exact: bool = True
              ) -> tuple[np.ndarray, np.ndarray, bool]:
    """Integer box for eq. (3). ``exact=True``: the box (6), which contains every minimiser, intersected
    with |k − k_round| ≤ ``max_shift`` if given. ``exact=False``: only |k − k_round| ≤ ``max_shift``
    (required then) — for cross-checks that the box (6) loses nothing. Returns (lo (l,), hi (l,),
    restricted) where ``restricted`` is True when the box does not contain the box (6) (optimality then
    holds only inside it)."""
    J0 = data.cost(data.k_round)
    rho = np.sqrt(max(J0, 0.0) * np.diag(data.S)) * (1.0 + 1e-9) + 1e-12
    elo = np.ceil((-data.r - rho) / TWO_PI).astype(np.int64)
    ehi = np.floor((-data.r + rho) / TWO_PI).astype(np.int64)
    elo = np.minimum(elo, data.k_round)  # the rounding satisfies (6); guard against round-off anyway
    ehi = np.maximum(ehi, data.k_round)
    if max_shift is None:
        if not exact:
            raise ValueError("exact=False needs max_shift (the integers would be unbounded)")
        return elo, ehi, False
    K = int(max_shift)
    if K < 0:
        raise ValueError(f"max_shift must be >= 0, got {max_shift}")
    lo, hi = data.k_round - K, data.k_round + K
    if exact:
        lo, hi = np.maximum(lo, elo), np.minimum(hi, ehi)
    restricted = bool(np.any(lo > elo) or np.any(hi < ehi))
    return lo, hi, restricted


def cycle_integers(graph: PoseGraph, tree: SpanningTree, k_edges) -> np.ndarray:
    """Cycle integers q = Ck (l,) int64 of any per-edge integer vector k (m,).

    q = round((C(δ + 2πk) − Cδ)/2π) = Ck, evaluated as k[chords] − (tree path sums of k)[chords] (no C
    formed). Two per-edge k are equivalent (same δ_reg up to the tree gauge, same phase-1 cost) iff
    their q coincide. Raises ``ValueError`` if k is not integer-valued."""
    k = np.asarray(k_edges, dtype=float).reshape(-1)
    if k.shape != (graph.n_edges,):
        raise ValueError(f"k_edges must have shape ({graph.n_edges},), got {np.shape(k_edges)}")
    if not np.all(np.isfinite(k)) or np.abs(k - np.rint(k)).max(initial=0.0) > 1e-6:
        raise ValueError("k_edges must be integer-valued")
    k = np.rint(k)
    c = tree.chords
    q = k[c] - tree.path_sums(graph, k)[c]
    return np.rint(q).astype(np.int64)


def true_edge_integers(graph: PoseGraph, theta_true) -> np.ndarray:
    """Per-edge ground-truth integers k_e = round((θ_j − θ_i − δ_e)/2π), shape (m,), so that
    δ + 2πk ≈ θ_true,j − θ_true,i (``theta_true`` (n,) unwrapped true orientations). Valid while the
    per-edge orientation noise stays below π."""
    th = np.asarray(theta_true, dtype=float)
    return np.rint((th[graph.heads] - th[graph.tails] - graph.delta) / TWO_PI).astype(np.int64)


def weighted_cycle_cost(graph: PoseGraph, tree: SpanningTree, k_edges, *, unc: EdgeUncertainty | None = None,
                        data: CycleData | None = None) -> float:
    """J(k) of eqs. (1)/(3) for any per-edge integer k (m,): ‖L⁻¹(r + 2πCk)‖² — the phase-1 optimum
    on δ + 2πk."""
    data = cycle_data(graph, tree, unc=unc) if data is None else data
    return data.cost(cycle_integers(graph, tree, k_edges))


def rounding_cost(graph: PoseGraph, tree: SpanningTree, *, unc: EdgeUncertainty | None = None,
                  data: CycleData | None = None) -> float:
    """J(k_round): the weighted cost (3) of the seed's per-chord rounding (``regularize``)."""
    data = cycle_data(graph, tree, unc=unc) if data is None else data
    return data.cost(data.k_round)


# --------------------------------------------------------------------------- cvxpy problems
def _box_constraints(k: cp.Variable, lo: np.ndarray, hi: np.ndarray) -> list:
    return [k >= lo, k <= hi]


def cycle_form_problem(data: CycleData, *, max_shift: int | None = None, exact: bool = True):
    """Cycle form, eq. (3): minimise ‖W(r + 2πk)‖² over k ∈ ℤ^l, W = L⁻¹ (l × l), with the box (6).

    Returns ``(problem, k)`` (k: integer ``cp.Variable`` of shape (l,)); add constraints with
    ``cp.Problem(problem.objective, problem.constraints + [...])``. ``max_shift``/``exact`` as in
    ``exact_box``."""
    lo, hi, _ = exact_box(data, max_shift=max_shift, exact=exact)
    k = cp.Variable(data.n_chords, integer=True, name="k")
    with np.errstate(invalid="ignore"):  # cvxpy's bound propagation multiplies 0 by ∞ (harmless)
        residual = data.r + TWO_PI * k
        problem = cp.Problem(cp.Minimize(cp.sum_squares(data.W @ residual)), _box_constraints(k, lo, hi))
    return problem, k


def phase1_form_problem(graph: PoseGraph, data: CycleData, *, unc: EdgeUncertainty | None = None,
                        max_shift: int | None = None, exact: bool = True, split: bool = True):
    """Phase-1 form, eq. (2): minimise ‖P_δ^{-1/2}(A2ᵀθ − δ − 2πEk)‖² over θ ∈ ℝ^{n−1}, k ∈ ℤ^l.

    A2 (n−1, m) reduced at the tree's root (the anchor), E (m, l) chord selector, box (6) on k.
    ``split=True`` writes the objective ``cp.sum(cp.square(W @ residual))`` (m three-dimensional cones
    for SCIP; the same value as ``cp.sum_squares(W @ residual)``, which SCIP handles badly here, see the
    module docstring). Returns ``(problem, theta, k)``; θ rows follow ``graph.free_poses``."""
    unc = edge_uncertainty(graph) if unc is None else unc
    lo, hi, _ = exact_box(data, max_shift=max_shift, exact=exact)
    m, l = graph.n_edges, data.n_chords
    A2 = reduced_incidence(graph, data.tree.root)
    E = sp.csr_matrix((np.ones(l), (data.chords, np.arange(l))), shape=(m, l))
    W = sp.diags(unc.sqrt_info_delta)
    theta = cp.Variable(A2.shape[0], name="theta")
    k = cp.Variable(l, integer=True, name="k")
    with np.errstate(invalid="ignore"):
        residual = W @ (A2.T @ theta - graph.delta - TWO_PI * (E @ k))
        objective = cp.sum(cp.square(residual)) if split else cp.sum_squares(residual)
        problem = cp.Problem(cp.Minimize(objective), _box_constraints(k, lo, hi))
    return problem, theta, k


# --------------------------------------------------------------------------- exact enumeration
def _min_variance_cholesky(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pivoted Cholesky Q[p][:, p] = G Gᵀ (G lower) choosing at each step the remaining coordinate of
    smallest conditional variance. Returns (p (l,), G (l, l))."""
    l = Q.shape[0]
    A = Q.copy()
    p = np.arange(l)
    G = np.zeros_like(A)
    for i in range(l):
        j = i + int(np.argmin(np.diag(A)[i:]))
        if j != i:
            A[[i, j]] = A[[j, i]]
            A[:, [i, j]] = A[:, [j, i]]
            G[[i, j], :i] = G[[j, i], :i]
            p[[i, j]] = p[[j, i]]
        d = A[i, i]
        if not d > 0:
            raise np.linalg.LinAlgError("cycle covariance is not positive definite")
        g = math.sqrt(d)
        G[i, i] = g
        G[i + 1:, i] = A[i + 1:, i] / g
        A[i + 1:, i + 1:] -= np.outer(G[i + 1:, i], G[i + 1:, i])
    return p, G


def enumerate_integers(data: CycleData, *, max_shift: int | None = None, exact: bool = True,
                       max_nodes: int = 2_000_000
                       ) -> tuple[np.ndarray, float, int]:
    """Exact minimiser of eq. (3) by Schnorr–Euchner sphere decoding (no dependency).

    In units of 2π: J(q) = (q − q̂)ᵀ Q⁻¹ (q − q̂), q̂ = −r/2π, Q = S/(2π)². With Q (permuted) = G Gᵀ,
    u_i = (q_i − c_i)/G_ii and c_i = q̂_i + Σ_{j<i} G_ij u_j, J = Σ_i u_i²: coordinates are fixed in
    order, each trying integers outward from its conditional centre c_i, and a branch is cut when its
    partial sum reaches the incumbent's cost. The incumbent starts as the rounding (radius J₀); a
    candidate replaces it only if cheaper by more than ``TIE_RTOL`` (ties keep the rounding). The box (6)
    (∩ |q − q_round| ≤ max_shift) bounds every coordinate.

    Returns (q (l,) int64, J(q), nodes visited). Raises ``RuntimeError`` after ``max_nodes`` nodes."""
    l = data.n_chords
    if l == 0:
        return np.zeros(0, np.int64), 0.0, 0
    lo, hi, _ = exact_box(data, max_shift=max_shift, exact=exact)
    qhat = -data.r / TWO_PI
    p, G = _min_variance_cholesky(data.S / TWO_PI**2)
    qh, lo_p, hi_p = qhat[p], lo[p], hi[p]
    best_q = data.k_round[p].astype(np.int64).copy()
    best = data.cost(data.k_round)
    diag = np.diag(G).copy()
    Gl = G.tolist()
    z = [0] * l
    u = [0.0] * l
    centre = [0.0] * l
    partial = [0.0] * (l + 1)
    step = [0] * l
    # per level: how many in-box candidates have been tried, out of (hi − lo + 1)
    tried = [0] * l
    span = (hi_p - lo_p + 1).tolist()
    lo_l, hi_l, qh_l, diag_l = lo_p.tolist(), hi_p.tolist(), qh.tolist(), diag.tolist()
    nodes = 0
    bound = best * (1.0 - TIE_RTOL)

    def start(i):
        row = Gl[i]
        c = qh_l[i] + sum(row[j] * u[j] for j in range(i))
        centre[i] = c
        zi = int(math.floor(c + 0.5))
        z[i] = zi
        step[i] = 1 if c >= zi else -1
        tried[i] = 0

    def advance(i):
        z[i] += step[i]
        step[i] = -step[i] - (1 if step[i] > 0 else -1)

    i = 0
    start(0)
    while True:
        zi = z[i]
        if zi < lo_l[i] or zi > hi_l[i]:
            # outside the box: the zig-zag continues on the other side until every in-box value is done
            dist = (zi - centre[i]) / diag_l[i]
            if tried[i] >= span[i] or partial[i] + dist * dist >= bound:
                i -= 1
                if i < 0:
                    break
                advance(i)
                continue
            advance(i)
            continue
        nodes += 1
        if nodes % PROGRESS_NODES == 0:  # long searches show progress (lago-cvx -v)
            log.info("integer enumeration: %d nodes (max_nodes %d), %d chords", nodes, max_nodes, l)
        if nodes > max_nodes:
            raise SearchLimitError(f"enumeration stopped after max_nodes={max_nodes} nodes (l={l} chords): too "
                                   f"many integers are uncertain (large rotation noise); use the MIP solver "
                                   f"({MIP_EXTRA}), a larger max_nodes or a max_shift, or "
                                   f"regularization='chordal'")
        tried[i] += 1
        ui = (zi - centre[i]) / diag_l[i]
        cost = partial[i] + ui * ui
        if cost >= bound:  # Schnorr–Euchner: later siblings are farther, so the whole level is done
            i -= 1
            if i < 0:
                break
            advance(i)
            continue
        if i == l - 1:
            best, bound = cost, cost * (1.0 - TIE_RTOL)
            best_q = np.array(z, dtype=np.int64)
            advance(i)
            continue
        u[i] = ui
        partial[i + 1] = cost
        i += 1
        start(i)
    q = np.empty(l, np.int64)
    q[p] = best_q
    return q, data.cost(q), nodes


# --------------------------------------------------------------------------- driver
@dataclass(eq=False)
class IntegerRegularization:
    """Result of ``integer_regularization``.

    ``k`` (m,) int64 per-edge integers (0 on tree edges); ``delta_reg`` (m,) δ + 2πk — plugs into
    ``phases.phase1_closed_form(graph, delta_reg, unc, anchor=tree.root)``; ``chords`` (l,);
    ``objective`` J(k) of eq. (3) evaluated in NumPy; ``solver_value`` the value the solver reported;
    ``rounding_k`` (m,) the seed's rounding and ``rounding_objective`` J(k_round); ``status`` cvxpy's
    status (``"optimal"`` for the enumeration); ``solver_status`` the solver's own status string;
    ``solve_time`` seconds inside the solver, ``wall_time`` seconds for the whole call;
    ``problem`` the cvxpy problem (None for the enumeration) and ``variables`` its variables by name;
    ``box_lo``, ``box_hi`` (l,) the integer box used; ``box_restricted`` True if ``max_shift`` cut the
    exact box (6); ``theta`` (n,) the unwrapped orientations of the phase-1 form (else None);
    ``nodes`` enumeration nodes (else None)."""

    k: np.ndarray
    delta_reg: np.ndarray
    chords: np.ndarray
    objective: float
    solver_value: float
    rounding_k: np.ndarray
    rounding_objective: float
    status: str
    solver_status: str
    solve_time: float
    wall_time: float
    solver: str
    form: str
    tree: SpanningTree
    box_lo: np.ndarray
    box_hi: np.ndarray
    box_restricted: bool
    problem: cp.Problem | None = None
    variables: dict = field(default_factory=dict)
    theta: np.ndarray | None = None
    nodes: int | None = None

    @property
    def k_chords(self) -> np.ndarray:
        """k per chord (l,) = the cycle integers Ck (tree edges carry 0)."""
        return self.k[self.chords]

    @property
    def rounding_k_chords(self) -> np.ndarray:
        return self.rounding_k[self.chords]

    @property
    def differing_chords(self) -> np.ndarray:
        """Edge indices of the chords whose cycle integer differs from the rounding's."""
        return self.chords[self.k_chords != self.rounding_k_chords]

    @property
    def n_differ(self) -> int:
        return int(self.differing_chords.size)

    @property
    def improvement(self) -> float:
        """J(k_round) − J(k) (≥ 0 up to solver tolerance when the solve was optimal)."""
        return self.rounding_objective - self.objective

    def summary(self) -> dict:
        return {"solver": self.solver, "form": self.form, "status": self.status,
                "solver_status": self.solver_status, "n_chords": int(self.chords.size),
                "n_differ": self.n_differ, "objective": self.objective,
                "rounding_objective": self.rounding_objective, "improvement": self.improvement,
                "solve_time": self.solve_time, "wall_time": self.wall_time,
                "box_restricted": self.box_restricted}


def _resolve_tree(graph: PoseGraph, tree, anchor: int) -> SpanningTree:
    return tree if isinstance(tree, SpanningTree) else build_tree(graph, tree, anchor=anchor)


def integer_regularization(graph: PoseGraph, tree: SpanningTree | str = "bfs", *, solver: str = "SCIP",
                           form: str = "cycle", time_limit: float = 60.0, max_shift: int | None = None,
                           exact: bool = True, unc: EdgeUncertainty | None = None, max_nodes: int = 2_000_000,
                           solver_options: dict | None = None, anchor: int = 0, verbose: bool = False,
                           data: CycleData | None = None) -> IntegerRegularization:
    """Weighted 2kπ regularization: argmin_k J(k) of eqs. (2)/(3), for small graphs (tens to a few
    hundred poses; S is dense l × l).

    Parameters (keyword-only):
      solver — ``"SCIP"`` (default, ``pip install "lago-cvx[mip]"``), ``"enumerate"`` (exact sphere
        decoding, no dependency, tiny problems) or another cvxpy mixed-integer solver name.
      form — ``"cycle"`` (eq. (3), l integers; default) or ``"phase1"`` (eq. (2), θ and k; slow beyond a
        few dozen poses). Ignored by ``"enumerate"`` (always eq. (3)).
      time_limit — seconds for the MIP solver (SCIP ``limits/time``); on the limit the incumbent is
        returned with status ``optimal_inaccurate`` and a warning.
      max_shift — optional extra box |k − k_round| ≤ max_shift (see eq. (6)).
      exact — impose the exact box (6) (default; it contains every optimum). ``exact=False`` (with
        ``max_shift``) searches the plain box |k − k_round| ≤ max_shift, to check that (6) loses nothing.
      solver_options — extra keyword arguments for ``problem.solve`` (for SCIP, ``scip_params`` is
        merged with the time limit).
      tree — a ``SpanningTree`` or a kind (``"bfs"``, ``"odometry"``, ``"mst"``) built at ``anchor``.
    Raises ``MissingSolverError`` (an ImportError naming the extra) when the solver is not installed."""
    t_all = time.perf_counter()
    if form not in ("cycle", "phase1"):
        raise ValueError(f"unknown form {form!r}; expected 'cycle' or 'phase1'")
    tree = _resolve_tree(graph, tree, anchor)
    enum = str(solver).lower() == ENUMERATE
    name = ENUMERATE if enum else _require_solver(solver)
    unc = edge_uncertainty(graph) if unc is None else unc
    data = cycle_data(graph, tree, unc=unc) if data is None else data
    lo, hi, restricted = exact_box(data, max_shift=max_shift, exact=exact)
    J_round = data.cost(data.k_round)
    l, m = data.n_chords, graph.n_edges
    problem, variables, theta, nodes = None, {}, None, None

    if l == 0:  # a tree: nothing to decide
        q, value, status, raw, t_solve = np.zeros(0, np.int64), 0.0, cp.OPTIMAL, "no chords", 0.0
    elif enum:
        t = time.perf_counter()
        q, value, nodes = enumerate_integers(data, max_shift=max_shift, exact=exact, max_nodes=max_nodes)
        t_solve = time.perf_counter() - t
        status, raw = cp.OPTIMAL, f"optimal ({nodes} nodes)"
    else:
        if form == "cycle":
            problem, kv = cycle_form_problem(data, max_shift=max_shift, exact=exact)
            variables = {"k": kv}
        else:
            problem, th, kv = phase1_form_problem(graph, data, unc=unc, max_shift=max_shift, exact=exact)
            variables = {"theta": th, "k": kv}
        opts = dict(solver_options or {})
        if name == "SCIP":
            params = {"limits/time": float(time_limit)}
            params.update(opts.pop("scip_params", {}))
            opts["scip_params"] = params
        # other solvers: pass their own time-limit option through ``solver_options``
        t = time.perf_counter()
        no_incumbent = fallback = False
        with warnings.catch_warnings(), np.errstate(invalid="ignore"):
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            try:
                value = problem.solve(solver=name, verbose=verbose, **opts)
            except cp.error.SolverError as exc:
                elapsed = time.perf_counter() - t
                if name != "SCIP" or elapsed < 0.8 * float(time_limit):
                    raise RuntimeError(f"{name} failed on the {form}-form integer program ({l} integers, "
                                       f"time limit {time_limit} s): {exc}") from exc
                no_incumbent = True  # SCIP hit its time limit before finding any integer point
        if no_incumbent:
            status, raw, t_solve, value = cp.OPTIMAL_INACCURATE, "time limit without an incumbent", elapsed, None
            log.warning("integer regularization: %s reached its time limit (%g s) without an integer point; the "
                        "rounding is returned — not proven optimal", name, time_limit)
            q, fallback = data.k_round.copy(), True
            raw += ": rounding returned"
        else:
            status = problem.status
            stats = problem.solver_stats
            extra = stats.extra_stats if stats is not None and isinstance(stats.extra_stats, dict) else {}
            raw = str(extra.get("scip_status", status))
            t_solve = float(stats.solve_time) if stats is not None and stats.solve_time is not None else float("nan")
            if kv.value is None:
                raise RuntimeError(f"{name} returned no integer solution (status {status!r}, {raw})")
            q = np.rint(kv.value).astype(np.int64)
        if status != cp.OPTIMAL and not no_incumbent:
            if data.cost(q) > J_round:
                # the rounding is feasible and cheaper: it is the best point known (cvxpy cannot warm-start SCIP)
                log.warning("integer regularization: %s stopped with status %s (%s) at an incumbent worse than "
                            "the rounding (J = %.6g > %.6g); the rounding is returned — not proven optimal",
                            name, status, raw, data.cost(q), J_round)
                q, fallback = data.k_round.copy(), True
                raw += "; incumbent worse than the rounding: rounding returned"
            else:
                log.warning("integer regularization: %s stopped with status %s (%s); the incumbent is returned "
                            "and may not be optimal", name, status, raw)
        if form == "phase1" and not fallback:  # θ of the solver's point (the rounding has none here)
            theta = np.zeros(graph.n_poses)
            theta[np.delete(np.arange(graph.n_poses), tree.root)] = th.value
        value = float(value) if value is not None else float("nan")

    k = np.zeros(m, np.int64)
    k[data.chords] = q
    J = data.cost(q)
    if J > J_round * (1.0 + 1e-7) + 1e-9:
        log.warning("integer regularization: the solution's cost %.10g exceeds the rounding's %.10g "
                    "(status %s) — solver tolerance or time limit", J, J_round, status)
    res = IntegerRegularization(
        k=k, delta_reg=graph.delta + TWO_PI * k, chords=data.chords, objective=J, solver_value=float(value),
        rounding_k=data.rounding_edges.copy(), rounding_objective=J_round, status=str(status),
        solver_status=raw, solve_time=float(t_solve), wall_time=time.perf_counter() - t_all, solver=name,
        form="cycle" if enum else form, tree=tree, box_lo=lo, box_hi=hi, box_restricted=restricted,
        problem=problem, variables=variables, theta=theta, nodes=nodes)
    log.info("integer regularization (%s, %s form): %d chords, %d differ from rounding, J = %.6g "
             "(rounding %.6g), %.3f s", name, res.form, l, res.n_differ, J, J_round, res.wall_time)
    return res


def compare_with_rounding(graph: PoseGraph, tree: SpanningTree | str = "bfs", **kwargs) -> dict:
    """Solve the integer program and compare with the seed's rounding, as cycle integers.

    Returns {"equal", "n_chords", "n_differ", "differing_chords" (edge indices), "ip_objective",
    "rounding_objective", "improvement", "status", "solver_status", "solve_time", "result"}.
    ``kwargs`` go to ``integer_regularization``."""
    res = integer_regularization(graph, tree, **kwargs)
    return {"equal": res.n_differ == 0, "n_chords": int(res.chords.size), "n_differ": res.n_differ,
            "differing_chords": res.differing_chords, "ip_objective": res.objective,
            "rounding_objective": res.rounding_objective, "improvement": res.improvement,
            "status": res.status, "solver_status": res.solver_status, "solve_time": res.solve_time,
            "result": res}


# --------------------------------------------------------------------------- noise sweep
def _lago_chi2(graph: PoseGraph, tree: SpanningTree, delta_reg: np.ndarray, unc: EdgeUncertainty
               ) -> tuple[float, float]:
    """χ² of LAGO's phases 1–3 (closed form) run on a given δ_reg, anchored at the tree's root, and χ²
    after Gauss–Newton refinement (``lago_cvx.refine``) from that estimate."""
    from . import phases as P
    from .cost import chi2
    from .refine import refine
    a = tree.root
    ph1 = P.phase1_closed_form(graph, delta_reg, unc, anchor=a)
    ph2 = P.phase2(graph, ph1.theta, unc, anchor=a)
    ph3 = P.phase3_closed_form(graph, ph2, anchor=a)
    return chi2(graph, ph3.poses), chi2(graph, refine(graph, ph3.poses).poses)


def noise_sweep(*, sigmas=(0.01, 0.05, 0.1, 0.15, 0.2, 0.3), seeds=range(5), n_poses: int = 100,
                world: str = "manhattan", tree: str = "bfs", solver: str = "SCIP", time_limit: float = 60.0,
                world_kwargs: dict | None = None, with_chi2: bool = True) -> list[dict]:
    """Integer program against rounding over rising rotation noise σ_θ on seeded synthetic worlds.

    For every σ_θ and seed: build ``manhattan_world`` / ``circle_world`` (``world_kwargs`` passed on),
    its tree, the rounding and the IP (``solver``); the ground truth is the cycle integers of
    ``true_edge_integers(graph, truth θ)``. One row per σ_θ:
      ``cases``, ``chords`` (mean l), ``ip_eq_round`` / ``ip_eq_true`` / ``round_eq_true`` (fraction of
      cases whose cycle integers coincide, all chords), ``chords_differ`` (mean chords IP ≠ rounding),
      ``ip_better`` (fraction with J_IP < J_round by > 1e-9 relative), ``gain`` (mean (J_round − J_IP)/J_IP),
      ``J_ip``, ``J_round``, ``J_true`` (means), ``truth_above_ip`` (fraction with J_true > J_IP: the
      weighted optimum itself disagrees with the truth), ``chi2_ratio`` (mean of χ²(LAGO on rounding) /
      χ²(LAGO on IP) over the cases where the two differ, if ``with_chi2``; nan if none),
      ``refined_ratio`` (the same after Gauss–Newton refinement of each LAGO estimate: > 1 means the
      rounding's start lands in a worse local minimum), ``time`` (mean solver seconds), ``not_optimal`` (count)."""
    from .synthetic import circle_world, manhattan_world
    gen = {"manhattan": manhattan_world, "circle": circle_world}.get(world)
    if gen is None:
        raise ValueError(f"unknown world {world!r}; expected 'manhattan' or 'circle'")
    rows = []
    for sigma in sigmas:
        acc = {k: [] for k in ("chords", "ip_eq_round", "ip_eq_true", "round_eq_true", "chords_differ",
                               "ip_better", "gain", "J_ip", "J_round", "J_true", "truth_above_ip",
                               "chi2_ratio", "refined_ratio", "time", "not_optimal")}
        for seed in seeds:
            w = gen(n_poses, seed=int(seed), sigma_theta=float(sigma), **(world_kwargs or {}))
            g = w.graph
            t = build_tree(g, tree)
            unc = edge_uncertainty(g)
            data = cycle_data(g, t, unc=unc)
            if data.n_chords == 0:
                continue
            res = integer_regularization(g, t, solver=solver, time_limit=time_limit, unc=unc, data=data)
            q_true = cycle_integers(g, t, true_edge_integers(g, w.truth[:, 2]))
            J_true = data.cost(q_true)
            acc["chords"].append(data.n_chords)
            acc["ip_eq_round"].append(res.n_differ == 0)
            acc["ip_eq_true"].append(bool(np.array_equal(res.k_chords, q_true)))
            acc["round_eq_true"].append(bool(np.array_equal(data.k_round, q_true)))
            acc["chords_differ"].append(res.n_differ)
            acc["ip_better"].append(res.objective < res.rounding_objective * (1 - 1e-9))
            acc["gain"].append(res.improvement / max(res.objective, 1e-300))
            acc["J_ip"].append(res.objective)
            acc["J_round"].append(res.rounding_objective)
            acc["J_true"].append(J_true)
            acc["truth_above_ip"].append(J_true > res.objective * (1 + 1e-9))
            acc["time"].append(res.solve_time)
            acc["not_optimal"].append(res.status != cp.OPTIMAL)
            if with_chi2 and res.n_differ:
                c_round, cr_round = _lago_chi2(g, t, data.rounding_edges * TWO_PI + g.delta, unc)
                c_ip, cr_ip = _lago_chi2(g, t, res.delta_reg, unc)
                acc["chi2_ratio"].append(c_round / c_ip)
                acc["refined_ratio"].append(cr_round / cr_ip)
            log.info("sweep σθ=%.3g seed=%s: l=%d, differ=%d, J_ip=%.4g, J_round=%.4g, J_true=%.4g, %.2f s",
                     sigma, seed, data.n_chords, res.n_differ, res.objective, res.rounding_objective, J_true,
                     res.solve_time)
        n = len(acc["chords"])
        mean = (lambda v: float(np.mean(v)) if len(v) else float("nan"))
        rows.append({"sigma_theta": float(sigma), "cases": n, "chords": mean(acc["chords"]),
                     "ip_eq_round": mean(acc["ip_eq_round"]), "ip_eq_true": mean(acc["ip_eq_true"]),
                     "round_eq_true": mean(acc["round_eq_true"]), "chords_differ": mean(acc["chords_differ"]),
                     "ip_better": mean(acc["ip_better"]), "gain": mean(acc["gain"]),
                     "J_ip": mean(acc["J_ip"]), "J_round": mean(acc["J_round"]), "J_true": mean(acc["J_true"]),
                     "truth_above_ip": mean(acc["truth_above_ip"]),
                     "chi2_ratio": mean(acc["chi2_ratio"]), "refined_ratio": mean(acc["refined_ratio"]),
                     "time": mean(acc["time"]), "not_optimal": int(np.sum(acc["not_optimal"]))})
    return rows


def format_sweep(rows: list[dict]) -> str:
    """Markdown table of ``noise_sweep`` rows."""
    head = ("| σθ | cases | chords | IP = round | IP = truth | round = truth | chords IP≠round | IP cheaper | "
            "mean gain | J_IP | J_round | J_truth | J_truth > J_IP | χ² round / χ² IP (where ≠) | "
            "refined χ² round / IP (where ≠) | IP s | not optimal |")
    sep = "|" + "---|" * 17
    lines = [head, sep]
    for r in rows:
        lines.append(
            f"| {r['sigma_theta']:g} | {r['cases']} | {r['chords']:.1f} | {r['ip_eq_round']:.2f} | "
            f"{r['ip_eq_true']:.2f} | {r['round_eq_true']:.2f} | {r['chords_differ']:.2f} | "
            f"{r['ip_better']:.2f} | {r['gain']:.3g} | {r['J_ip']:.4g} | {r['J_round']:.4g} | "
            f"{r['J_true']:.4g} | {r['truth_above_ip']:.2f} | {r['chi2_ratio']:.4g} | {r['refined_ratio']:.4g} | "
            f"{r['time']:.2f} | "
            f"{r['not_optimal']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python -m lago_cvx.integer [--poses N] [--seeds S] [--world manhattan|circle] [--solver …]``:
    run ``noise_sweep`` and write its markdown table to stdout."""
    import argparse
    import sys
    ap = argparse.ArgumentParser(prog="python -m lago_cvx.integer", description=noise_sweep.__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--world", default="manhattan", choices=["manhattan", "circle"])
    ap.add_argument("--tree", default="bfs")
    ap.add_argument("--solver", default="SCIP")
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.01, 0.05, 0.1, 0.15, 0.2, 0.3])
    ap.add_argument("--laps", type=float, default=None, help="circle world: number of laps")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("lago_cvx.regularization").setLevel(logging.ERROR)
    kw = {"laps": args.laps} if args.world == "circle" and args.laps else None
    t = time.perf_counter()
    rows = noise_sweep(sigmas=args.sigmas, seeds=range(args.seeds), n_poses=args.poses, world=args.world,
                       tree=args.tree, solver=args.solver, time_limit=args.time_limit, world_kwargs=kw)
    sys.stdout.write(f"{args.world} world, {args.poses} poses, seeds 0–{args.seeds - 1}, {args.tree} tree, "
                     f"solver {args.solver} ({time.perf_counter() - t:.0f} s)\n\n{format_sweep(rows)}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
