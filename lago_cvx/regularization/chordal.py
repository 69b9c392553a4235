r"""Chordal relaxation of the planar rotations: a global orientation estimate with no spanning tree.

Why. The seed's regularization (``lago_cvx.regularization``, Theorem 3) integrates δ along a spanning
tree and rounds every chord's cycle residual to the nearest multiple of 2π. The rounding is right only
while the rotation noise accumulated along each chord's tree path stays below π; on long paths with
large rotation noise it picks the wrong 2kπ and LAGO lands in a wrong basin. The chordal relaxation
estimates all orientations *at once*, using every measurement with its weight, and needs no integers.

The relaxation. Write each rotation by the first column of its matrix, r_i = (cos θ_i, sin θ_i) ∈ ℝ²
(R_i = [r_i, S r_i], S = [[0, −1], [1, 0]]). Edge e = (i → j) measures R_j = R_i R(δ_e), whose first
column reads

    r_j = R(δ_e) r_i                                    (linear in r_i, r_j),             (C1)

and ‖R_j − R_i R(δ_e)‖_F² = 2 ‖r_j − R(δ_e) r_i‖² = 4(1 − cos(θ_j − θ_i − δ_e)) ≈ 2 (θ_j − θ_i − δ_e)².
Dropping the constraint ‖r_i‖ = 1 (SO(2) → ℝ²) leaves a linear weighted least-squares problem

    minimise_r  Σ_e ω_e ‖r_j − R(δ_e) r_i‖²,    r_anchor = (1, 0),    ω_e = 1 / P_δ,e       (C2)

(ω_e is the same rotational information phase 1 uses, so for small residuals (C2) is phase 1's cost
written on the circle). Stacking r over the d = n − 1 free poses (x ∈ ℝ^{2d}, interleaved cos, sin) and
the 2m edge rows, (C2) is ‖M x − b‖² with the sparse whitened design

    M = Ω^{1/2} (A_j − A_i^δ)  (2m × 2d):  rows 2e, 2e+1 hold √ω_e I₂ at the head's columns and
        −√ω_e R(δ_e) at the tail's columns;  b (2m,) moves the anchor's known r_anchor to the right.  (C3)

Its normal matrix MᵀM is the "connection Laplacian" of the graph (Ω-weighted), positive definite for a
connected graph with one anchored pose. The estimate is projected back to SO(2) by θ_i = atan2(r_i):
since δ enters only through cos δ and sin δ, the result does not depend on any 2π wrapping of the data.
``norms`` = ‖r_i‖ is exactly 1 everywhere on noiseless data, where the relaxation is tight. With noise the
lengths are not a per-pose confidence: the solution is the anchor's column of the inverse (complex)
connection Laplacian, scaled to 1 at the anchor, so ‖r_i‖ falls with the distance from the anchor — and
falls faster the more the cycles disagree — and moving the anchor changes the lengths by large factors
while the directions θ_i barely move (lecture 08 §2 measures all three). Only the directions are used.

This is the initialization used by SE-Sync and by Carlone et al.'s ICRA 2015 survey ("chordal
relaxation"); here it only decides the integers of the seed's regularization (``regularize_chordal``);
LAGO's three phases then run unchanged.

Rounding against it (R-C). Every edge e = (i → j) is rounded against the relaxed orientations φ:

    φ̃ = φ + 2π·branch(φ, θ_tree)                 (the same φ, on the tree's branch: a pure gauge),
    k_e = branch(δ_e, φ̃_j − φ̃_i),   δ_reg,e = δ_e + 2πk_e,
    so that δ_reg,e − (φ̃_j − φ̃_i) ∈ (−π, π] for every edge (tree edges included).     (R-C)

Adding 2π(w_j − w_i) (w ∈ ℤⁿ) to all δ_reg changes no cycle sum, so only the cycle integers
C k ∈ ℤˡ matter (``RegularizationReport.cycle_k``); choosing φ̃ on the tree's branch keeps k = 0 on most
tree edges and the phase-1 orientations unwrapped like the tree ones. An edge is *ambiguous* when
|δ_reg,e − (φ̃_j − φ̃_i)| > π − margin. Chordal and tree rounding agree whenever the tree paths carry
< π of accumulated rotation error; beyond that only the chordal one keeps finding the right integers.

Both forms are provided side by side: ``chordal_problem`` (cvxpy, ``cp.sum_squares(M @ x − b)``) and
``chordal_closed_form`` (sparse normal equations with corrected semi-normal refinement).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import OptionError
from ..graph import SpanningTree, free_poses
from ..sparse import EdgeSystem, GraphElimination, solve_least_squares
from ..posegraph import PoseGraph
from ..rounding import AMBIGUITY_MARGIN, TWO_PI, branch, check_angles
from ..solvers import ClarabelSettings, check_method, named_constant, parameter, solve
from ..uncertainty import edge_uncertainty
from .report import RegularizationReport, warn_ambiguous

__all__ = ["ChordalEstimate", "chordal_system", "chordal_edge_system", "chordal_problem", "chordal_closed_form", "chordal_from_problem",
           "regularize_chordal"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ChordalEstimate:
    """Solution of the chordal relaxation (C2).

    ``vectors`` (n, 2) the relaxed first columns r_i (anchor = (1, 0)); ``theta`` (n,) the projection
    atan2(r_i) ∈ (−π, π] (anchor 0); ``norms`` (n,) ‖r_i‖ (all 1 on noiseless
    data; with noise they decay away from the anchor — a property of the anchor, not of pose i);
    ``cost`` the optimal value of (C2); ``anchor``; ``stats`` the least-squares solver's report
    (closed form only)."""

    vectors: np.ndarray
    theta: np.ndarray
    norms: np.ndarray
    cost: float
    anchor: int
    stats: dict | None = None


def chordal_system(graph: PoseGraph, info_delta, *, anchor=None) -> tuple[sp.csc_matrix, np.ndarray]:
    """The whitened linear system (C3) of the chordal relaxation: ``(M, b)`` with M (2m × 2d) sparse
    and b (2m,), so that (C2) is ‖M x − b‖², x (2d,) = the free poses' (cos, sin), interleaved, in the
    order of ``lago_cvx.graph.free_poses``. ``info_delta`` (m,) is ω_e = 1/P_δ,e; ``anchor`` a pose id
    (default the smallest)."""
    anchor = graph.anchor_index(anchor)
    n, m = graph.n_poses, graph.n_edges
    w = np.sqrt(np.asarray(info_delta, dtype=float))
    if w.shape != (m,):
        raise OptionError(f"info_delta must have shape ({m},), got {w.shape}")
    col = np.full(n, -1, dtype=np.int64)
    col[free_poses(n, anchor)] = np.arange(n - 1)
    c, s = np.cos(graph.delta), np.sin(graph.delta)
    e = np.arange(m)
    # head block: +√ω I₂ ; tail block: −√ω R(δ) = −√ω [[c, −s], [s, c]]
    rows, cols, vals = [], [], []
    b = np.zeros(2 * m)
    for r in (0, 1):  # output row within the edge's 2-row block
        for q in (0, 1):  # component of r_i / r_j (cos, sin)
            head_val = w * (1.0 if r == q else 0.0)
            rot = (c if r == q else (-s if (r, q) == (0, 1) else s))
            tail_val = -w * rot
            for node, val in ((graph.heads, head_val), (graph.tails, tail_val)):
                free = col[node] >= 0
                rows.append(2 * e[free] + r)
                cols.append(2 * col[node[free]] + q)
                vals.append(val[free])
                # the anchor's r = (1, 0): its q = 0 column goes to the right-hand side
                if q == 0:
                    fixed = ~free
                    np.subtract.at(b, 2 * e[fixed] + r, val[fixed])
    M = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(2 * m, 2 * (n - 1)))
    return M, b


def _estimate(n: int, anchor: int, x: np.ndarray, cost: float, stats=None) -> ChordalEstimate:
    vec = np.empty((n, 2))
    vec[anchor] = (1.0, 0.0)
    vec[free_poses(n, anchor)] = x.reshape(-1, 2)
    norms = np.hypot(vec[:, 0], vec[:, 1])
    theta = np.arctan2(vec[:, 1], vec[:, 0])
    theta[anchor] = 0.0
    weak = np.flatnonzero(norms < 1e-8)
    if weak.size:  # not a warning by itself: the rounding's ambiguity is judged in regularize_chordal
        log.debug("chordal relaxation: %d pose(s) have ‖r_i‖ < 1e-8 (orientation not fixed by the relaxation)",
                  weak.size)
    return ChordalEstimate(vectors=vec, theta=theta, norms=norms, cost=float(cost), anchor=anchor, stats=stats)


def chordal_problem(graph: PoseGraph, info_delta, *, anchor=None):
    """The chordal relaxation (C2) as a cvxpy problem: minimise ‖M r − b‖² (``cp.sum_squares``, M whitened)
    over the free poses' rotation vectors r (2d,), (cos θ, sin θ) interleaved.

    ``print(problem)`` reads ``minimize quad_over_lin(M @ r + -b, 1.0, …)``; b (the anchor's terms) is a
    ``cp.Parameter``. Returns ``(problem, r)``; add constraints with ``cp.Problem(problem.objective,
    [...])`` (e.g. ``cp.norm(r[2*i:2*i+2]) <= 1``). Planar (``lc.chordal_problem``); the 3-D relaxation over
    rotation matrices is ``lago_cvx.space.chordal_problem``."""
    import cvxpy as cp

    M, b = chordal_system(graph, info_delta, anchor=anchor)
    x = cp.Variable(M.shape[1], name="r")
    objective = cp.sum_squares(named_constant(sp.csc_matrix(M), "M") @ x - parameter(b, "b"))
    return cp.Problem(cp.Minimize(objective)), x


def chordal_edge_system(graph: PoseGraph, info_delta, elim: GraphElimination) -> EdgeSystem:
    """(C3) edge by edge, the form (E) of ``lago_cvx.sparse.normal_equations`` (b = q = 2): edge k = (i → j)
    contributes √ω_k (r_j − R(δ_k) r_i), i.e. A_k = −√ω_k R(δ_k), B_k = √ω_k I₂, and the anchor's known
    r = (1, 0) moves to c_k (c_k = √ω_k (cos δ_k, sin δ_k) when the tail is the anchor, −√ω_k (1, 0) when
    the head is)."""
    m = graph.n_edges
    w = np.sqrt(np.asarray(info_delta, dtype=float))
    if w.shape != (m,):
        raise OptionError(f"info_delta must have shape ({m},), got {w.shape}")
    cs, sn = np.cos(graph.delta), np.sin(graph.delta)
    A = np.empty((m, 2, 2))
    A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = -w * cs, w * sn, -w * sn, -w * cs
    B = np.zeros((m, 2, 2))
    B[:, 0, 0] = B[:, 1, 1] = w
    c = np.zeros((m, 2))
    t_fix, h_fix = elim.tails < 0, elim.heads < 0
    c[t_fix] += (w * np.stack([cs, sn]))[:, t_fix].T
    c[h_fix, 0] -= w[h_fix]
    return EdgeSystem(elim.tails, elim.heads, A, B, c, elim.d)


def chordal_closed_form(graph: PoseGraph, info_delta, *, anchor=None, backend: str = "auto",
                        elimination: GraphElimination | None = None) -> ChordalEstimate:
    """The chordal relaxation (C2) in closed form: x = (MᵀM)⁻¹Mᵀb by a sparse factorization with corrected
    semi-normal refinement; projected to angles. ``backend="auto"``: the edge system
    (``chordal_edge_system``) through the pose-level multifrontal elimination (``elimination`` reused when
    its anchor matches); another backend: ``linalg.solve_least_squares`` on M of ``chordal_system``."""
    a = graph.anchor_index(anchor)
    if backend != "auto":
        M, b = chordal_system(graph, info_delta, anchor=anchor)
        x, _, _, stats = solve_least_squares(M, b, backend=backend)
        r = M @ x - b
        return _estimate(graph.n_poses, a, x, float(r @ r), stats)
    elim = elimination if elimination is not None and elimination.anchor_index == a else GraphElimination(graph, a)
    system = chordal_edge_system(graph, info_delta, elim)
    x, _, stats = elim.solve(system, stage="chordal relaxation")
    return _estimate(graph.n_poses, a, x.reshape(-1), system.cost(x), stats)


def chordal_from_problem(graph: PoseGraph, info_delta, *, anchor=None,
                         settings: ClarabelSettings | None = None):
    """Build and solve the cvxpy form with Clarabel (``lago_cvx.solvers.solve``); returns
    (ChordalEstimate, problem)."""
    problem, x = chordal_problem(graph, info_delta, anchor=anchor)
    a = graph.anchor_index(anchor)
    if x.size == 0:  # a single pose: nothing to estimate
        return _estimate(graph.n_poses, a, np.zeros(0), 0.0), problem
    solve(problem, settings, what="the chordal relaxation")
    return _estimate(graph.n_poses, a, np.asarray(x.value, dtype=float), float(problem.value)), problem


def regularize_chordal(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN,
                       method: str = "closed_form", backend: str = "auto",
                       settings: ClarabelSettings | None = None, uncertainty=None,
                       elimination: GraphElimination | None = None) -> RegularizationReport:
    """2kπ regularization of every edge against the chordal relaxation (module docstring, (R-C)).

    The relaxation (eq. (C2)) is anchored at ``tree.root`` and solved in closed form
    (``method="closed_form"``, sparse ``backend``) or as its cvxpy problem with Clarabel
    (``method="cvxpy"``; the problem is kept in ``report.problem``). O(m + n log n) plus one sparse
    factorization of the 2(n−1) × 2(n−1) connection Laplacian. ``uncertainty`` (the graph's
    ``EdgeUncertainty``) and ``elimination`` (a ``normal_equations.GraphElimination`` anchored at the
    root) are reused when given.

    Ambiguity (warned, listed in ``ambiguous``): an edge whose residual against the relaxed orientations
    is within ``margin`` of ±π — there the other integer is within the margin. A small ‖r_i‖ alone is no
    reason for a warning: it says φ_i is loosely fixed, but the cycle integers through pose i depend only
    on the *differences* of its edges' residuals, which do not depend on φ_i; they change only if some
    residual crosses ±π, which is exactly the edge test (logged at DEBUG level)."""
    check_method(method)
    check_angles(graph)
    unc = uncertainty if uncertainty is not None else edge_uncertainty(graph)
    info = unc.info_delta  # 1/P_δ, as phase 1 weighs the orientations
    root = int(graph.ids[tree.root])
    problem = None
    if method == "closed_form":
        est = chordal_closed_form(graph, info, anchor=root, backend=backend, elimination=elimination)
    else:
        est, problem = chordal_from_problem(graph, info, anchor=root, settings=settings)
    theta_raw = tree.integrate(graph)
    ref = est.theta + TWO_PI * branch(est.theta, theta_raw)  # φ̃: φ on the tree's branch
    target = ref[graph.heads] - ref[graph.tails]
    k = branch(graph.delta, target)
    delta_reg = graph.delta + TWO_PI * k
    edge_residual = delta_reg - target
    c = tree.chords
    path_raw = theta_raw[graph.heads] - theta_raw[graph.tails]
    theta_tree = tree.integrate(graph, delta_reg)
    path_reg = theta_tree[graph.heads] - theta_tree[graph.tails]
    residual = delta_reg[c] - path_reg[c]  # (C δ_reg)_c
    ambiguous = np.flatnonzero(np.abs(edge_residual) > np.pi - margin)
    warn_ambiguous(graph, ambiguous, margin, "edge", "the measurement contradicts the chordal estimate by ≈ π")
    return RegularizationReport(delta_reg=delta_reg, k=k, chords=c, residual_before=graph.delta[c] - path_raw[c],
                                residual=residual, ambiguous=ambiguous, theta_tree=theta_tree,
                                margin=float(margin), tree=tree, regularization="chordal", reference=ref,
                                edge_residual=edge_residual, chordal=est, problem=problem)
