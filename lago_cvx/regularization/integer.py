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
  (a 20-pose, 2-chord graph was not proven optimal); writing the same sum of squares as
  ``cp.sum(cp.square(W @ residual))`` — m small cones, identical value — solves it at once, so the
  phase-1 form uses that (``split=True``). The cycle form's dense W keeps ``cp.sum_squares``.
  Even so the phase-1 form is slow beyond a few dozen poses, an order of magnitude and more behind the cycle
  form on Manhattan worlds of 60–150 poses, so the cycle form is the main path and the phase-1 form a
  cross-check for small graphs; and the cycle form's branch-and-bound is far slower than the enumeration
  once many integers are free (same integers; ``benchmarks/integer.md``).
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
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import MissingSolverError, OptionError, SolverError
from ..graph import SpanningTree, _reduced_incidence, cycle_basis
from ..posegraph import PoseGraph
from ..rounding import AMBIGUITY_MARGIN, TWO_PI, check_angles, round_residual, tree_cycle_residuals
from ..solvers import IntegerSearch
from ..uncertainty import EdgeUncertainty, edge_uncertainty
from .report import RegularizationReport, chord_report
from .sphere import enumerate_integers

__all__ = [
    "MIP_EXTRA", "ENUMERATE", "MAX_INTEGER_CHORDS", "CycleData", "cycle_data", "exact_box", "cycle_integers",
    "weighted_cycle_cost", "rounding_cost", "cycle_form_problem", "phase1_form_problem",
    "IntegerRegularization", "integer_regularization", "compare_with_rounding", "regularize_integer",
]

log = logging.getLogger(__name__)

#: pip requirement that installs the default mixed-integer solver (SCIP through pyscipopt).
MIP_EXTRA = 'pip install "lago-cvx[mip]"'

#: Solver name of the dependency-free exact enumeration.
ENUMERATE = "enumerate"

#: Largest number of chords (l) ``regularization="integer"`` accepts: it works with the dense l × l cycle
#: covariance C P_δ Cᵀ and its Cholesky factor (l = 3000: 72 MB per matrix; ``benchmarks/integer.md``).
MAX_INTEGER_CHORDS = 3000


def _require_solver(solver: str) -> str:
    """Check that ``solver`` can be used; return cvxpy's name for it. Lazy: imports nothing heavy
    unless asked. Raises ``MissingSolverError`` naming the extra for SCIP."""
    import cvxpy as cp

    name = str(solver).upper()
    if name == "SCIP":
        try:
            import pyscipopt  # noqa: F401
        except ImportError as exc:
            raise MissingSolverError(
                "the integer regularization needs a mixed-integer solver and SCIP (pyscipopt) is not "
                f"installed: {MIP_EXTRA}  (or use the solver \"enumerate\": the dependency-free exact "
                "enumeration)") from exc
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
    """Everything eq. (3) needs, for one graph and tree (small graphs: S is dense l × l)."""

    #: The spanning tree.
    tree: SpanningTree
    #: (l,) the chords' edge indices.
    chords: np.ndarray
    #: (l, m) the cycle basis, sparse.
    C: sp.csr_matrix
    #: (l,) r = Cδ.
    r: np.ndarray
    #: (l, l) S = C P_δ Cᵀ.
    S: np.ndarray
    #: (l, l) the lower Cholesky factor of S.
    L: np.ndarray
    #: (l, l) W = L⁻¹ (whitening).
    W: np.ndarray
    #: (m,) the seed's rounding k_c = −round(r_c/2π) per edge (as ``regularize_tree``; 0 on the tree edges).
    rounding_edges: np.ndarray

    @property
    def k_round(self) -> np.ndarray:
        """(l,) the rounding's cycle integers: ``rounding_edges`` at the chords (a new array at each read)."""
        return self.rounding_edges[self.chords]

    @property
    def n_chords(self) -> int:
        """l, the number of chords (independent cycles)."""
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
    import scipy.linalg as sla

    W = sla.solve_triangular(L, np.eye(c.size), lower=True) if c.size else S
    k_edges = np.zeros(graph.n_edges, np.int64)  # the seed's rounding (regularize_tree), without its warnings
    k_edges[c] = round_residual(r)
    return CycleData(tree=tree, chords=c, C=C, r=r, S=S, L=L, W=W, rounding_edges=k_edges)


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
            raise OptionError("exact=False needs max_shift (the integers would be unbounded)")
        return elo, ehi, False
    K = int(max_shift)
    if K < 0:
        raise OptionError(f"max_shift must be >= 0, got {max_shift}")
    lo, hi = data.k_round - K, data.k_round + K
    if exact:
        lo, hi = np.maximum(lo, elo), np.minimum(hi, ehi)
    restricted = bool(np.any(lo > elo) or np.any(hi < ehi))
    return lo, hi, restricted


def cycle_integers(graph: PoseGraph, tree: SpanningTree, k_edges) -> np.ndarray:
    """Cycle integers q = Ck (l,) int64 of any per-edge integer vector k (m,).

    q = round((C(δ + 2πk) − Cδ)/2π) = Ck, evaluated as k[chords] − (tree path sums of k)[chords] (no C
    formed). Two per-edge k are equivalent (same δ_reg up to the tree gauge, same phase-1 cost) iff
    their q coincide. Raises ``OptionError`` (a ValueError) if k is not integer-valued."""
    k = np.asarray(k_edges, dtype=float).reshape(-1)
    if k.shape != (graph.n_edges,):
        raise OptionError(f"k_edges must have shape ({graph.n_edges},), got {np.shape(k_edges)}")
    if not np.all(np.isfinite(k)) or np.abs(k - np.rint(k)).max(initial=0.0) > 1e-6:
        raise OptionError("k_edges must be integer-valued")
    k = np.rint(k)
    c = tree.chords
    q = k[c] - tree.path_sums(graph, k)[c]
    return np.rint(q).astype(np.int64)


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
def cycle_form_problem(data: CycleData, *, max_shift: int | None = None, exact: bool = True):
    """Cycle form, eq. (3): minimise ‖W(r + 2πk)‖² over k ∈ ℤ^l, W = L⁻¹ (l × l), with the box (6).

    Returns ``(problem, k)`` (k: integer ``cp.Variable`` of shape (l,)); add constraints with
    ``cp.Problem(problem.objective, problem.constraints + [...])``. ``max_shift``/``exact`` as in
    ``exact_box``."""
    import cvxpy as cp

    lo, hi, _ = exact_box(data, max_shift=max_shift, exact=exact)
    k = cp.Variable(data.n_chords, integer=True, name="k")
    with np.errstate(invalid="ignore"):  # cvxpy's bound propagation multiplies 0 by ∞ (harmless)
        residual = data.r + TWO_PI * k
        problem = cp.Problem(cp.Minimize(cp.sum_squares(data.W @ residual)), [k >= lo, k <= hi])
    return problem, k


def phase1_form_problem(graph: PoseGraph, data: CycleData, *, unc: EdgeUncertainty | None = None,
                        max_shift: int | None = None, exact: bool = True, split: bool = True):
    """Phase-1 form, eq. (2): minimise ‖P_δ^{-1/2}(A2ᵀθ − δ − 2πEk)‖² over θ ∈ ℝ^{n−1}, k ∈ ℤ^l.

    A2 (n−1, m) reduced at the tree's root (the anchor), E (m, l) chord selector, box (6) on k.
    ``split=True`` writes the objective ``cp.sum(cp.square(W @ residual))`` (m three-dimensional cones
    for SCIP; the same value as ``cp.sum_squares(W @ residual)``, which SCIP handles badly here, see the
    module docstring). Returns ``(problem, theta, k)``; θ rows follow ``graph.free_poses``."""
    import cvxpy as cp

    unc = edge_uncertainty(graph) if unc is None else unc
    lo, hi, _ = exact_box(data, max_shift=max_shift, exact=exact)
    m, l = graph.n_edges, data.n_chords
    A2 = _reduced_incidence(graph, data.tree.root)
    E = sp.csr_matrix((np.ones(l), (data.chords, np.arange(l))), shape=(m, l))
    W = sp.diags(unc.sqrt_info_delta)
    theta = cp.Variable(A2.shape[0], name="theta")
    k = cp.Variable(l, integer=True, name="k")
    with np.errstate(invalid="ignore"):
        residual = W @ (A2.T @ theta - graph.delta - TWO_PI * (E @ k))
        objective = cp.sum(cp.square(residual)) if split else cp.sum_squares(residual)
        problem = cp.Problem(cp.Minimize(objective), [k >= lo, k <= hi])
    return problem, theta, k


# --------------------------------------------------------------------------- exact enumeration
# --------------------------------------------------------------------------- driver
@dataclass(eq=False)
class IntegerRegularization:
    """Result of ``integer_regularization``.

    ``k`` (m,) int64 per-edge integers (0 on tree edges); ``delta_reg`` (m,) δ + 2πk — plugs into
    ``phases.phase1_closed_form``; ``chords`` (l,);
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
    problem: object | None = None
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


@dataclass
class _Outcome:
    """What one solver run gives the driver: cycle integers and how they were obtained."""

    q: np.ndarray
    value: float
    status: str
    raw: str
    solve_time: float
    problem: object | None = None
    variables: dict = field(default_factory=dict)
    theta: np.ndarray | None = None
    nodes: int | None = None


def _solve_mip(graph: PoseGraph, data: CycleData, search: IntegerSearch, name: str, unc: EdgeUncertainty,
               verbose: bool) -> _Outcome:
    """The integer program as a cvxpy problem (cycle or phase-1 form) solved by ``name`` (SCIP, ...).
    A time-out never yields a point worse than the rounding (module docstring)."""
    import cvxpy as cp

    if search.form == "cycle":
        problem, kv = cycle_form_problem(data, max_shift=search.max_shift, exact=search.exact)
        variables = {"k": kv}
    else:
        problem, th, kv = phase1_form_problem(graph, data, unc=unc, max_shift=search.max_shift, exact=search.exact)
        variables = {"theta": th, "k": kv}
    opts = dict(search.solver_options)
    if name == "SCIP":
        opts["scip_params"] = {"limits/time": float(search.time_limit), **opts.pop("scip_params", {})}
    # other solvers: pass their own time-limit option through ``solver_options``
    t = time.perf_counter()
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.filterwarnings("ignore", message="Solution may be inaccurate")
        try:
            value = problem.solve(solver=name, verbose=verbose, **opts)
        except cp.error.SolverError as exc:
            elapsed = time.perf_counter() - t
            if name != "SCIP" or elapsed < 0.8 * float(search.time_limit):
                raise SolverError(f"{name} failed on the {search.form}-form integer program ({data.n_chords} "
                                  f"integers, time limit {search.time_limit} s): {exc}", "solver_error") from None
            log.warning("integer regularization: %s reached its time limit (%g s) without an integer point; the "
                        "rounding is returned — not proven optimal", name, search.time_limit)
            return _Outcome(data.k_round.copy(), float("nan"), "optimal_inaccurate",
                            "time limit without an incumbent: rounding returned", elapsed, problem, variables)
    status = problem.status
    stats = problem.solver_stats
    extra = stats.extra_stats if stats is not None and isinstance(stats.extra_stats, dict) else {}
    raw = str(extra.get("scip_status", status))
    t_solve = float(stats.solve_time) if stats is not None and stats.solve_time is not None else float("nan")
    if kv.value is None:
        raise SolverError(f"{name} returned no integer solution (status {status!r}, {raw})", status)
    q = np.rint(kv.value).astype(np.int64)
    fallback = False
    if status != "optimal":
        J_round = data.cost(data.k_round)
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
    theta = None
    if search.form == "phase1" and not fallback:  # θ of the solver's point (the rounding has none here)
        theta = np.zeros(graph.n_poses)
        theta[np.delete(np.arange(graph.n_poses), data.tree.root)] = variables["theta"].value
    return _Outcome(q, float(value) if value is not None else float("nan"), status, raw, t_solve, problem,
                    variables, theta)


def integer_regularization(graph: PoseGraph, tree: SpanningTree | str = "bfs", *,
                           search: IntegerSearch | None = None, unc: EdgeUncertainty | None = None,
                           anchor=None, verbose: bool = False, data: CycleData | None = None,
                           progress=None) -> IntegerRegularization:
    """Weighted 2kπ regularization: argmin_k J(k) of eqs. (2)/(3), for small and medium graphs (S is
    dense l × l).

    Parameters (keyword-only):
      search — an ``IntegerSearch`` (solver, form, time limit, node budget, box); its ``solver`` default
        ``None`` means SCIP here (``pip install "lago-cvx[mip]"``); ``"enumerate"`` is the exact,
        dependency-free sphere decoding.
      tree — a ``SpanningTree`` or a kind (``"bfs"``, ``"odometry"``, ``"mst"``) rooted at ``anchor``
        (a pose id, default the smallest).
      unc, data — precomputed ``EdgeUncertainty`` / ``CycleData`` (sweeps reuse them).
      progress — an optional ``lago_cvx.progress.ProgressCallback``, told ("integer search", share of the node budget used) during long enumerations.
    Raises ``MissingSolverError`` (an ImportError naming the extra) when the solver is not installed,
    ``SearchLimitError`` when the enumeration exceeds its node budget, ``SolverError`` when a MIP
    solver fails."""
    from ..graph import spanning_tree

    t_all = time.perf_counter()
    search = IntegerSearch() if search is None else search
    if not isinstance(search, IntegerSearch):
        raise OptionError(f"search must be a lago_cvx.IntegerSearch, got {type(search).__name__}")
    tree = tree if isinstance(tree, SpanningTree) else spanning_tree(graph, tree, anchor=anchor)
    solver = "SCIP" if search.solver is None else search.solver
    enum = str(solver).lower() == ENUMERATE
    name = ENUMERATE if enum else _require_solver(solver)
    unc = edge_uncertainty(graph) if unc is None else unc
    data = cycle_data(graph, tree, unc=unc) if data is None else data
    lo, hi, restricted = exact_box(data, max_shift=search.max_shift, exact=search.exact)
    J_round = data.cost(data.k_round)
    if data.n_chords == 0:  # a tree: nothing to decide
        out = _Outcome(np.zeros(0, np.int64), 0.0, "optimal", "no chords", 0.0)
    elif enum:
        t = time.perf_counter()
        q, value, nodes = enumerate_integers(data, (lo, hi), max_nodes=int(search.max_nodes), progress=progress)
        out = _Outcome(q, value, "optimal", f"optimal ({nodes} nodes)", time.perf_counter() - t, nodes=nodes)
    else:
        out = _solve_mip(graph, data, search, name, unc, verbose)
    k = np.zeros(graph.n_edges, np.int64)
    k[data.chords] = out.q
    J = data.cost(out.q)
    if J > J_round * (1.0 + 1e-7) + 1e-9:
        log.warning("integer regularization: the solution's cost %.10g exceeds the rounding's %.10g "
                    "(status %s) — solver tolerance or time limit", J, J_round, out.status)
    res = IntegerRegularization(
        k=k, delta_reg=graph.delta + TWO_PI * k, chords=data.chords, objective=J, solver_value=float(out.value),
        rounding_k=data.rounding_edges.copy(), rounding_objective=J_round, status=str(out.status),
        solver_status=out.raw, solve_time=float(out.solve_time), wall_time=time.perf_counter() - t_all,
        solver=name, form="cycle" if enum else search.form, tree=tree, box_lo=lo, box_hi=hi,
        box_restricted=restricted, problem=out.problem, variables=out.variables, theta=out.theta, nodes=out.nodes)
    log.info("integer regularization (%s, %s form): %d chords, %d differ from rounding, J = %.6g "
             "(rounding %.6g), %.3f s", name, res.form, data.n_chords, res.n_differ, J, J_round, res.wall_time)
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


def regularize_integer(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN,
                       method: str = "closed_form", search: IntegerSearch | None = None,
                       progress=None) -> RegularizationReport:
    """2kπ regularization by the weighted integer program (eq. (3)): the cycle integers q ∈ ℤˡ
    minimising J(q) = ‖L⁻¹(Cδ + 2πq)‖², placed on the chords of ``tree`` (k = 0 on tree edges), so that
    δ_reg = δ + 2πk is what phase 1 (eq. (13)) fits best.

    method — ``"closed_form"``: exact sphere-decoding enumeration (no dependency); ``"cvxpy"``: the
      mixed-integer cvxpy problem solved by SCIP (``pip install "lago-cvx[mip]"``; kept in
      ``report.problem``). A ``search`` with its own ``solver`` overrides that choice.
    Chords whose corrected cycle sum (Cδ_reg)_c lies within ``margin`` of ±π — or beyond: unlike the
    rounding, the weighted optimum may move a cycle sum past ±π — are reported as ambiguous.
    Raises ``OptionError`` for more than ``MAX_INTEGER_CHORDS`` chords (the problem is dense in l)."""
    from dataclasses import replace

    from ..solvers import check_method

    check_method(method)
    check_angles(graph)
    c = tree.chords
    if c.size > MAX_INTEGER_CHORDS:
        raise OptionError(f"the integer regularization works with the dense {c.size} x {c.size} cycle "
                          f"covariance; this graph has {c.size} chords (more than {MAX_INTEGER_CHORDS}): use the "
                          "chordal regularization (sparse)")
    search = IntegerSearch() if search is None else search
    if search.solver is None:
        search = replace(search, solver=ENUMERATE if method == "closed_form" else "SCIP")
    ip = integer_regularization(graph, tree, search=search, progress=progress)
    return chord_report(graph, tree, ip.k, margin=margin, regularization="integer",
                        why="the weighted integer optimum puts these cycle sums near or beyond ±π: large rotation "
                            "noise", problem=ip.problem, integer=ip)
