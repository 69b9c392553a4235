"""Orientation regularization (the seed's Section IV-E: Theorem 3, eqs. (20)–(23), Corollary 3).

Measured relative orientations δ are only known modulo 2π (a sensor reports them in [−π, π)), but
phase 1 treats them as real numbers whose sums around every cycle vanish up to noise. Theorem 3
constructs integers k (one per chord of a spanning tree) such that the corrected measurements
δ_reg = δ + 2πk make every fundamental cycle consistent:

    θ_tree = orientations integrated along the spanning tree from the anchor (tree edges unchanged),
    for every chord c = (i → j):   r_c = (C δ)_c = δ_c − (θ_tree[j] − θ_tree[i])   (cycle residual),
                                   k_c = −round(r_c / 2π),   δ_reg,c = δ_c + 2π k_c,
    so that (C δ_reg)_c = r_c + 2π k_c ∈ (−π, π]                                 (eqs. 20–23).

Rounding rule for exact ties (r_c/2π exactly half-integer): ``k_c = −ceil(r_c/2π − 1/2)``, i.e. the
corrected residual always lies in the half-open interval (−π, π] (a tie gives +π). A tie
means the measurement is useless for deciding k; such chords and any chord whose residual lies within
``margin`` of ±π are listed in ``RegularizationReport.ambiguous`` (the seed's "noise too large" case:
the correct k is then not guaranteed, Corollary 3).

``regularization="chordal"`` (issue 8) replaces the tree integration by a global estimate: the chordal
relaxation of the rotations (``lago_cvx.chordal``, eqs. (C1)–(C3)) gives orientations φ (n,) that use every
measurement with its weight, and **every** edge e = (i → j) is rounded against them:

    φ̃ = φ + 2π·round((θ_tree − φ)/2π)           (the same φ, on the tree's branch: a pure gauge),
    ρ_e = δ_e − (φ̃_j − φ̃_i),   k_e = −ceil(ρ_e/2π − ½),   δ_reg,e = δ_e + 2πk_e,
    so that δ_reg,e − (φ̃_j − φ̃_i) ∈ (−π, π] for every edge (tree edges included).   (R-C)

Adding 2π(w_j − w_i) (w ∈ ℤⁿ) to all δ_reg changes no cycle sum, so only the cycle integers
C k ∈ ℤˡ matter (``cycle_k``); choosing φ̃ on the tree's branch keeps k = 0 on most tree edges and the
phase-1 orientations unwrapped like the tree ones. An edge is *ambiguous* when |δ_reg,e − (φ̃_j − φ̃_i)|
> π − margin. Chordal and tree rounding agree whenever the tree paths carry < π of accumulated rotation
error; beyond that only the chordal one keeps finding the right integers (lecture 08).

``regularization="integer"`` (issue 8) solves the problem the rounding approximates: the cycle integers
q = Ck ∈ ℤˡ minimising phase 1's own cost, J(q) = ‖L⁻¹(Cδ + 2πq)‖² with C P_δ Cᵀ = L Lᵀ
(``lago_cvx.integer``, eq. (3)); k is put on the chords (tree edges keep k = 0, no loss: only Ck matters).
The tree rounding is its exact solution when C P_δ Cᵀ is diagonal, and in practice at low noise; with
rising rotation noise the two part (lecture 08, section 3). Dense in the l chords: small and medium graphs.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .graph import SpanningTree
from .posegraph import GraphError, PoseGraph

__all__ = ["RegularizationReport", "regularize", "regularize_tree", "regularize_chordal", "regularize_integer",
           "tree_cycle_residuals",
           "REGULARIZATIONS", "MAX_INTEGER_CHORDS",
           "AMBIGUITY_MARGIN", "check_angles"]

log = logging.getLogger(__name__)

#: Default margin (radians): a chord whose cycle residual (after rounding) is within this distance of
#: ±π is reported as ambiguous. 0.5 rad ≈ 29°; a residual that large means the tree path's
#: accumulated rotation error is of the order of the decision boundary.
AMBIGUITY_MARGIN = 0.5

#: Largest accepted |δ| (radians). Beyond it δ mod 2π loses more than ~1e-10 rad to rounding
#: (ulp(1e6) ≈ 1.2e-10) and k would not fit the arithmetic; such a "measurement" is an input error.
MAX_ABS_ANGLE = 1e6

#: The regularizers: ``"tree"`` (the seed's Theorem 3), ``"chordal"`` (rounding against the chordal
#: relaxation) and ``"integer"`` (the weighted integer least-squares problem the rounding approximates).
REGULARIZATIONS = ("tree", "chordal", "integer")

#: Largest number of chords (l) ``regularization="integer"`` accepts: it works with the dense l × l cycle
#: covariance C P_δ Cᵀ and its Cholesky factor (l = 3000: 72 MB per matrix, ~1 s to factor).
MAX_INTEGER_CHORDS = 3000


@dataclass(frozen=True, eq=False)
class RegularizationReport:
    """Result of the 2kπ regularization (tree rounding, or rounding against the chordal relaxation).

    ``delta_reg`` (m,) regularized relative orientations (tree rounding: tree edges unchanged);
    ``k`` (m,) integer correction per edge (tree rounding: 0 on tree edges); ``chords`` (l,) chord edge
    indices of ``tree``;
    ``residual_before`` (l,) r_c = (C δ)_c = δ_c − (θ_tree[j] − θ_tree[i]), the cycle residual before rounding;
    ``residual`` (l,) (C δ_reg)_c ∈ (−π, π] for the tree rounding (not bounded for the chordal one: there
    the bound (R-C) holds per edge, see ``edge_residual``);
    ``ambiguous`` edge indices whose rounding residual is within ``margin`` of ±π (chords for the tree
    rounding, any edge for the chordal one); ``theta_tree`` (n,) δ_reg integrated along the tree from
    its root (for the tree rounding: the "odometric" orientations of the tree, δ_reg = δ there);
    ``regularization`` "tree" or "chordal"; ``reference`` (n,) the orientations each edge was rounded
    against (θ_tree, or the chordal φ̃); ``edge_residual`` (m,) δ_reg − (reference_j − reference_i);
    ``chordal`` the ``ChordalEstimate`` (chordal only); ``problem`` its cvxpy problem (method "cvxpy"; for
    the integer regularization the mixed-integer cvxpy problem); ``integer`` the
    ``lago_cvx.integer.IntegerRegularization`` (integer only: objective, rounding's objective, solver)."""

    delta_reg: np.ndarray
    k: np.ndarray
    chords: np.ndarray
    residual_before: np.ndarray
    residual: np.ndarray
    ambiguous: np.ndarray
    theta_tree: np.ndarray
    margin: float
    tree: SpanningTree
    regularization: str = "tree"
    reference: np.ndarray | None = None
    edge_residual: np.ndarray | None = None
    chordal: object | None = None
    problem: object | None = None
    integer: object | None = None

    @property
    def n_regularized(self) -> int:
        """Number of fundamental cycles whose sum needed a non-zero 2kπ correction (the seed's Table I, last
        row: chords with k ≠ 0 for the tree rounding)."""
        return int(np.count_nonzero(self.cycle_k))

    @property
    def k_chords(self) -> np.ndarray:
        """k per chord, shape (l,) (the tree rounding's only non-zero entries)."""
        return self.k[self.chords]

    @property
    def cycle_k(self) -> np.ndarray:
        """Integer correction of each fundamental cycle sum, C k (l,): (C δ_reg − C δ)/2π. Two
        regularizations are equivalent (give the same phase-1 θ up to 2π per pose) iff these coincide;
        equals ``k_chords`` for the tree rounding."""
        return np.rint((self.residual - self.residual_before) / (2.0 * np.pi)).astype(np.int64)

    def cycle_residual(self, graph: PoseGraph) -> np.ndarray:
        """C·δ_reg evaluated through the tree (no C formed), shape (l,); equals ``residual``."""
        return self.delta_reg[self.chords] - self.tree.path_sums(graph, self.delta_reg)[self.chords]

    def summary(self) -> dict:
        return {
            "regularization": self.regularization,
            "n_chords": int(self.chords.size),
            "n_regularized": self.n_regularized,
            "n_ambiguous": int(self.ambiguous.size),
            "max_abs_residual": float(np.abs(self.residual).max()) if self.residual.size else 0.0,
        }


def check_angles(graph: PoseGraph) -> None:
    """Raise ``GraphError`` naming the first edge whose |δ| exceeds ``MAX_ABS_ANGLE``."""
    big = np.flatnonzero(np.abs(graph.delta) > MAX_ABS_ANGLE)
    if big.size:
        k0 = big[0]
        raise GraphError(
            f"edge {graph.ids[graph.tails[k0]]}->{graph.ids[graph.heads[k0]]}: measured relative orientation "
            f"{graph.delta[k0]:.6g} rad is too large to be reduced modulo 2π accurately (|δ| > {MAX_ABS_ANGLE:g} rad"
            f"{f'; {big.size} such edges' if big.size > 1 else ''})")


def _round_residual(before: np.ndarray) -> np.ndarray:
    """k = −ceil(ρ/2π − ½) so that ρ + 2πk ∈ (−π, π] (eq. (22) with the tie rule of the module docstring)."""
    return -np.ceil(before / (2.0 * np.pi) - 0.5).astype(np.int64)


def _warn_ambiguous(graph: PoseGraph, ambiguous: np.ndarray, margin: float, what: str, why: str) -> None:
    if ambiguous.size:
        ids = graph.ids
        listed = ", ".join(f"{ids[graph.tails[e]]}->{ids[graph.heads[e]]}" for e in ambiguous[:10])
        log.warning("regularization: %d %s(s) have a residual within %.3g rad of ±π, so their 2kπ correction is "
                    "ambiguous (%s): %s%s", ambiguous.size, what, margin, why, listed,
                    " ..." if ambiguous.size > 10 else "")


def regularize(graph: PoseGraph, tree: SpanningTree, *, regularization: str = "tree",
               margin: float = AMBIGUITY_MARGIN, method: str = "closed_form", backend: str = "auto",
               solver_settings: dict | None = None, integer_options: dict | None = None) -> RegularizationReport:
    """2kπ regularization of the relative orientations.

    regularization — ``"tree"`` (the seed's Theorem 3: round each chord against the tree, see
      ``regularize_tree``) or ``"chordal"`` (round every edge against the chordal relaxation, see
      ``regularize_chordal``) or ``"integer"`` (the weighted integer program, see ``regularize_integer``).
      ``method`` ("closed_form" | "cvxpy"), ``backend`` and ``solver_settings`` concern the chordal
      relaxation; for ``"integer"`` ``method`` picks the solver (exact enumeration | SCIP through cvxpy)
      and ``integer_options`` go to ``lago_cvx.integer.integer_regularization``. margin — ambiguity
      margin (rad)."""
    if regularization == "tree":
        return regularize_tree(graph, tree, margin=margin)
    if regularization == "chordal":
        return regularize_chordal(graph, tree, margin=margin, method=method, backend=backend,
                                  solver_settings=solver_settings)
    if regularization == "integer":
        return regularize_integer(graph, tree, margin=margin, method=method, integer_options=integer_options)
    raise ValueError(f"unknown regularization {regularization!r}; expected one of {REGULARIZATIONS}")


def regularize_tree(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN) -> RegularizationReport:
    """2kπ regularization of the chords of ``tree`` (Theorem 3, eqs. (20)–(23)); vectorized, O(m + n log n).

    Returns a ``RegularizationReport``; logs a warning listing (up to 10) ambiguous chords."""
    check_angles(graph)
    before = tree_cycle_residuals(graph, tree)
    k = np.zeros(graph.n_edges, np.int64)
    k[tree.chords] = _round_residual(before)
    return _chord_report(graph, tree, k, margin=margin, regularization="tree",
                         why="rotation noise too large along the tree path")


def tree_cycle_residuals(graph: PoseGraph, tree: SpanningTree) -> np.ndarray:
    """r = C δ (l,): each chord's δ minus the tree path between its ends (eq. (20))."""
    c = tree.chords
    return graph.delta[c] - tree.path_sums(graph)[c]


def _chord_report(graph: PoseGraph, tree: SpanningTree, k: np.ndarray, *, margin: float, regularization: str,
                  why: str, **extra) -> RegularizationReport:
    """The report of a regularization whose integers k (m,) sit on the chords only (tree edges keep δ):
    the tree integration is unchanged, (C δ_reg)_c is the chord's residual, ambiguous chords are those
    within ``margin`` of ±π (or beyond), warned with ``why``."""
    theta_tree = tree.integrate(graph)
    path = theta_tree[graph.heads] - theta_tree[graph.tails]  # (m,), equals δ on tree edges
    c = tree.chords
    delta_reg = graph.delta + 2.0 * np.pi * k
    edge_residual = delta_reg - path  # 0 on tree edges, C δ_reg on chords
    residual = edge_residual[c]
    ambiguous = c[np.abs(residual) > np.pi - margin]
    _warn_ambiguous(graph, ambiguous, margin, "chord", why)
    return RegularizationReport(delta_reg=delta_reg, k=k, chords=c, residual_before=graph.delta[c] - path[c],
                                residual=residual, ambiguous=ambiguous, theta_tree=theta_tree, margin=float(margin),
                                tree=tree, regularization=regularization, reference=theta_tree,
                                edge_residual=edge_residual, **extra)


def regularize_chordal(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN,
                       method: str = "closed_form", backend: str = "auto",
                       solver_settings: dict | None = None) -> RegularizationReport:
    """2kπ regularization of every edge against the chordal relaxation (module docstring, (R-C)).

    The relaxation (``lago_cvx.chordal``, eq. (C2)) is anchored at ``tree.root`` and solved in closed
    form (``method="closed_form"``, sparse ``backend``) or as its cvxpy problem with Clarabel
    (``method="cvxpy"``; the problem is kept in ``report.problem``). O(m + n log n) plus one sparse
    factorization of the 2(n−1) × 2(n−1) connection Laplacian."""
    from .chordal import chordal_closed_form, chordal_from_problem

    check_angles(graph)
    var = graph.covariance[:, 2, 2]  # P_δ (marginal), as phase 1 uses (lago_cvx.phases.edge_uncertainty)
    info = 1.0 / var
    problem = None
    if method == "closed_form":
        est = chordal_closed_form(graph, info, anchor=tree.root, backend=backend)
    elif method == "cvxpy":
        est, problem = chordal_from_problem(graph, info, anchor=tree.root, settings=solver_settings)
    else:
        raise ValueError(f"unknown method {method!r}; expected 'closed_form' or 'cvxpy'")
    theta_raw = tree.integrate(graph)
    ref = est.theta + 2.0 * np.pi * np.rint((theta_raw - est.theta) / (2.0 * np.pi))  # φ̃: φ on the tree's branch
    target = ref[graph.heads] - ref[graph.tails]
    k = _round_residual(graph.delta - target)
    delta_reg = graph.delta + 2.0 * np.pi * k
    edge_residual = delta_reg - target
    c = tree.chords
    path_raw = theta_raw[graph.heads] - theta_raw[graph.tails]
    theta_tree = tree.integrate(graph, delta_reg)
    path_reg = theta_tree[graph.heads] - theta_tree[graph.tails]
    ambiguous = np.flatnonzero(np.abs(edge_residual) > np.pi - margin)
    _warn_ambiguous(graph, ambiguous, margin, "edge", "the measurement contradicts the chordal estimate by ≈ π")
    return RegularizationReport(delta_reg=delta_reg, k=k, chords=c, residual_before=graph.delta[c] - path_raw[c],
                                residual=delta_reg[c] - path_reg[c], ambiguous=ambiguous, theta_tree=theta_tree,
                                margin=float(margin), tree=tree, regularization="chordal", reference=ref,
                                edge_residual=edge_residual, chordal=est, problem=problem)


def regularize_integer(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN,
                       method: str = "closed_form", integer_options: dict | None = None) -> RegularizationReport:
    """2kπ regularization by the weighted integer program (``lago_cvx.integer``, eq. (3)): the cycle
    integers q ∈ ℤˡ minimising J(q) = ‖L⁻¹(Cδ + 2πq)‖², placed on the chords of ``tree`` (k = 0 on tree
    edges), so that δ_reg = δ + 2πk is what phase 1 (eq. (13)) fits best.

    method — ``"closed_form"``: exact sphere-decoding enumeration (no dependency; raises if it needs more
      than ``max_nodes`` nodes — very noisy graphs); ``"cvxpy"``: the mixed-integer cvxpy problem solved
      by SCIP (``pip install "lago-cvx[mip]"``; kept in ``report.problem``).
    integer_options — keyword arguments for ``integer_regularization`` (``solver``, ``time_limit``,
      ``max_nodes``, ``max_shift``, ``form``), overriding the method's choice of solver.
    Chords whose corrected cycle sum (Cδ_reg)_c lies within ``margin`` of ±π — or beyond: unlike the
    rounding, the weighted optimum may move a cycle sum past ±π — are reported as ambiguous.
    Raises ``ValueError`` for more than ``MAX_INTEGER_CHORDS`` chords (the problem is dense in l)."""
    from .integer import integer_regularization

    if method not in ("closed_form", "cvxpy"):
        raise ValueError(f"unknown method {method!r}; expected 'closed_form' or 'cvxpy'")
    check_angles(graph)
    c = tree.chords
    if c.size > MAX_INTEGER_CHORDS:
        raise ValueError(f"regularization='integer' works with the dense {c.size} x {c.size} cycle covariance; "
                         f"this graph has {c.size} chords (> MAX_INTEGER_CHORDS = {MAX_INTEGER_CHORDS}): use "
                         f"regularization='chordal' (sparse) or lago_cvx.integer.integer_regularization directly")
    opts = {"solver": "enumerate" if method == "closed_form" else "SCIP", **(integer_options or {})}
    ip = integer_regularization(graph, tree, **opts)
    return _chord_report(graph, tree, ip.k, margin=margin, regularization="integer",
                         why="the weighted integer optimum puts these cycle sums near or beyond ±π: large rotation "
                             "noise", problem=ip.problem, integer=ip)
