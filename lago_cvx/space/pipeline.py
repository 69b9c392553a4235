r"""``lago3d``: LAGO's two routes in space, and the result they return.

* ``route="seed"`` — Carlone, Tron, Daniilidis and Dellaert's procedure (ICRA 2015): the rotations by the chordal
  relaxation (``chordal``), then the positions at those rotations (``positions``: the exact minimizer of χ² for
  them, with the full 6×6 information).
* ``route="default"`` — then one **joint linearized step**: the Gauss–Newton step δ = (δv, δφ) of χ² on all poses at
  the seed's estimate, with the full 6×6 information and the exact Jacobians of the graph's cost (``gauss_newton``),
  the rotations moved to R_i Exp(α δφ_i) and the positions re-solved exactly at them. Guarded like the planar position polish (``lago_cvx.positions``):
  α = 1 is kept if its χ² does not exceed the seed's, else α is halved (at most ``MAX_HALVINGS`` times) until it
  does, else the seed's estimate is kept — so χ²(default) ≤ χ²(seed) always. GTSAM's ``InitializePose3`` is the
  chordal relaxation followed by one Gauss–Newton step without the re-solve and without the guard.

Every χ² is the graph's cost (``graph.cost``: g2o's, the default, or GTSAM's; :mod:`lago_cvx.posegraph3d`): the
positions are its exact minimizer at fixed rotations and the joint step its Gauss–Newton step, in either cost. Only the
chordal relaxation speaks Log coordinates: its weights take the information there
(``posegraph3d.information_in_log_coordinates``; for g2o's cost S Ω S, S = blkdiag(I₃, ½I₃), the first-order
equivalent — at zero error the g2o error's derivative is S, so the joint step's normal matrix is that too).

The anchor (a pose **id**, default the smallest) is held at the identity pose (R = I, t = 0).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import OptionError, check_choice
from ..graph import check_connected
from ..posegraph3d import chi2_3d
from ..reports import fmt_timings, short_repr
from ..solvers import check_method
from ..so3 import exp_so3
from ..sparse import threads_option
from .chordal import WEIGHTINGS, chordal_closed_form, chordal_cvxpy
from .gauss_newton import gauss_newton_step
from .positions import positions_closed_form, positions_cvxpy

__all__ = ["ROUTES3D", "MAX_HALVINGS", "Lago3DResult", "lago3d", "compare_methods3d"]

ROUTES3D = ("default", "seed")
#: Step halvings the joint step tries before the seed's estimate is kept.
MAX_HALVINGS = 3


@dataclass(frozen=True, eq=False)
class Lago3DResult:
    """What ``lago3d`` returns; plain arrays and numbers only (picklable).

    ``t`` (n, 3), ``R`` (n, 3, 3): the estimate; ``chi2`` its χ² (no ½) in the graph's cost, ``cost``;
    ``chi2_seed``: χ² after chordal → positions; ``chi2_chordal_only`` is not kept (the positions are part of every route). ``alpha`` the fraction of
    the joint step taken (None on the seed route), ``trials`` the (α, χ²) pairs evaluated; ``route``, ``method``,
    ``weighting``; ``anchor`` (id) and ``anchor_index``; ``timings`` seconds per stage (chordal, positions, joint,
    total); ``accuracy`` the solvers' reports per stage."""

    t: np.ndarray
    R: np.ndarray
    chi2: float
    chi2_seed: float
    route: str
    method: str
    weighting: str
    anchor: int
    anchor_index: int
    alpha: float | None = None
    trials: tuple = ()
    timings: dict = field(default_factory=dict)
    accuracy: dict = field(default_factory=dict)
    cost: str = "g2o"
    graph: object = field(default=None, repr=False)
    variant: object = field(default=None, repr=False)

    dim = 3

    @property
    def poses(self):
        """(t, R)."""
        return self.t, self.R

    def _describe(self) -> tuple[str, list[str]]:
        """The head and lines of ``repr``: counts, χ², route, timings (never an array)."""
        g = self.graph
        head = (f"{self.t.shape[0]} poses" + (f", {g.n_edges} edges ({g.n_loop_closures} loop closures)" if g is not None
                                              else "") + f": χ² = {self.chi2:.6g} ({self.cost}, Σ eᵀΩe)")
        alpha = "seed route, no joint step" if self.alpha is None else f"joint step α = {self.alpha:.3g}"
        return head, [f"route {self.route}, {self.weighting} weighting, method {self.method}; χ² after chordal → "
                      f"positions {self.chi2_seed:.6g}; {alpha}", f"anchor pose {self.anchor}",
                      "time " + fmt_timings(self.timings)]

    def __repr__(self) -> str:
        """A few lines whatever the size; the arrays are ``t`` and ``R``."""
        return short_repr(type(self).__name__, *self._describe())

    def pose_covariances(self) -> np.ndarray:
        """First-order covariances Σ_ii (n, 6, 6) of δ = (δv, δφ) at the estimate, (JᵀΩJ)⁻¹ blocks with the anchor
        held (zero there; ``covariance.pose_covariances3d``); with anchors, priors or rotation constraints those of
        the same problem as ``refine``'s (``space.refine``: anchors held, priors included, δφ ∥ a)."""
        if self.graph is None:
            raise OptionError("pose_covariances: this result does not carry its graph")
        if self.variant is None:
            from .covariance import pose_covariances3d

            return pose_covariances3d(self.graph, self.t, self.R, anchor=self.anchor)
        from .refine import Problem3D

        v = self.variant
        return Problem3D(self.graph, self.t, self.R, reference=v.reference, anchors=v.anchors, priors=v.priors,
                         constraints=v.constraints).covariances(self.t, self.R)


def _joint(graph, t0, R0, cost0, a, solve_positions, elimination=None):
    """The guarded joint step (module docstring): (t, R, cost, alpha, trials)."""
    delta = gauss_newton_step(graph, t0, R0, anchor_index=a, elimination=elimination).reshape(-1, 6)
    dphi = np.zeros((graph.n_poses, 3))
    free = np.ones(graph.n_poses, bool)
    free[a] = False
    dphi[free] = delta[:, 3:]
    trials = [(0.0, cost0)]
    alpha = 1.0
    for _ in range(MAX_HALVINGS + 1):
        R = R0 @ exp_so3(alpha * dphi)
        t, _ = solve_positions(R)
        cost = chi2_3d(graph, t, R)
        trials.append((alpha, cost))
        if cost <= cost0:
            return t, R, cost, alpha, tuple(trials)
        alpha *= 0.5
    return t0, R0, cost0, 0.0, tuple(trials)


@threads_option
def lago3d(graph, *, route: str = "default", method: str = "closed_form", weighting: str = "isotropic",
           anchor=None, solver_settings=None, fixed=None, workers: int | None = None,
           blas_threads: int | None = None, cost: str | None = None, anchors=None, priors=None,
           rotation_constraints=None, rotations=None) -> Lago3DResult:
    """LAGO on a 3-D pose graph (module docstring).

    Parameters (keyword-only): ``route`` ``"default"`` or ``"seed"``; ``method`` ``"closed_form"`` (sparse
    factorizations) or ``"cvxpy"`` (the chordal relaxation and the positions as cvxpy problems solved by Clarabel
    with ``solver_settings`` over ``solvers.LEAST_SQUARES``; the joint step's linear system is the closed form's in
    both); ``weighting`` of the chordal relaxation, ``"isotropic"`` (SE-Sync's κ) or ``"anisotropic"`` (the whole
    rotational information; ``chordal``); ``anchor`` the id of the pose held at the identity (default: smallest);
    ``fixed`` ``{id: (t (3,), R (3, 3))}``: poses known exactly, which then define the frame instead of the anchor
    (``space.fixed``; closed form only); ``workers`` the most threads the sparse engine runs at once (SciPy's name;
    None: ``lago_cvx.sparse.cores()``); ``blas_threads`` None (the default) leaves the process's BLAS thread count
    alone, k holds it to at most k threads while the engine factors (the 3-D systems' compiled factorizations ask
    for one: faster when another process shares the cores, docs/performance.md "3-D graphs"); ``cost`` ``"g2o"`` or
    ``"gtsam"`` (None: the graph's, ``graph.with_cost(cost)``).

    Variants (``space.variants``; closed form or cvxpy, the same problems): ``anchors`` ``{id: (t, R)}`` known
    poses (t or R may be None: known in part); ``priors`` ``{id: (t̄ or None, R̄ or None, Λ)}`` soft absolute
    measurements (Λ 3×3, or 6×6 position first); ``rotation_constraints`` ``{id: (a, b)}``, R_id a = b kept through
    the relaxation, its projection and the joint step (``space.gravity_aligned(ids)``: R e₃ = e₃); ``rotations``
    (n, 3, 3) to continue from: the chordal relaxation skipped, the positions and the guarded joint step of the
    route from there (the rotations moved rigidly so that the anchor's is the identity). With priors ``chi2``
    includes their terms."""
    if getattr(graph, "dim", 2) != 3:
        raise OptionError("lago3d takes a 3-D pose graph (PoseGraph3D); planar graphs go to lago()")
    if cost is not None:
        graph = graph.with_cost(cost)
    check_choice("route", route, ROUTES3D)
    check_method(method)
    check_choice("weighting", weighting, WEIGHTINGS)
    check_connected(graph)  # Proposition 1's condition; the systems would be singular
    if anchors is not None or priors is not None or rotation_constraints is not None or (
            rotations is not None and fixed is not None):
        return _variant(graph, anchors={**(fixed or {}), **(anchors or {})} or None, priors=priors,
                        rotation_constraints=rotation_constraints, rotations=rotations, anchor=anchor, route=route,
                        method=method, weighting=weighting, solver_settings=solver_settings)
    if fixed is not None:
        from .fixed import lago3d_fixed

        if method != "closed_form" or anchor is not None:
            raise OptionError("fixed poses are solved in closed form and replace the anchor")
        start = time.perf_counter()
        t, R, cost, seed, alpha, trials = lago3d_fixed(graph, fixed, route=route, weighting=weighting,
                                                       max_halvings=MAX_HALVINGS)
        a = graph.index_of(next(iter(fixed)))
        return Lago3DResult(t=t, R=R, chi2=float(cost), chi2_seed=float(seed), route=route, method=method,
                            weighting=weighting, anchor=int(graph.ids[a]), anchor_index=a, alpha=alpha,
                            trials=trials, timings={"total": time.perf_counter() - start}, cost=graph.cost,
                            graph=graph, variant=_fixed_variant(graph, fixed))
    a = graph.anchor_index(anchor)
    start = time.perf_counter()
    timings, accuracy = {}, {}
    el = None
    if method == "closed_form":
        from ..sparse import GraphElimination

        el = GraphElimination(graph, a)  # every system of the route
        ch = None if rotations is not None else chordal_closed_form(graph, weighting=weighting, anchor_index=a,
                                                                    elimination=el)

        def solve_positions(R):
            return positions_closed_form(graph, R, anchor_index=a, elimination=el)
    else:
        ch = None if rotations is not None else chordal_cvxpy(graph, weighting=weighting, anchor_index=a,
                                                              settings=solver_settings)

        def solve_positions(R):
            return positions_cvxpy(graph, R, anchor_index=a, settings=solver_settings)
    if ch is None:  # continue from the given rotations, moved rigidly so that the anchor's is the identity
        R = graph.check_poses(np.zeros((graph.n_poses, 3)), rotations)[1]
        R = np.swapaxes(R[a], 0, 1) @ R
        R[a] = np.eye(3)
        accuracy["chordal"] = {"method": "given rotations"}
    else:
        timings["chordal"] = time.perf_counter() - start
        R, accuracy["chordal"] = ch.rotations, ch.accuracy
    t0 = time.perf_counter()
    t, accuracy["positions"] = solve_positions(R)
    seed = chi2_3d(graph, t, R)
    timings["positions"] = time.perf_counter() - t0
    cost, alpha, trials = seed, None, ()
    if route == "default" and graph.n_poses > 1 and graph.n_edges:
        t0 = time.perf_counter()
        t, R, cost, alpha, trials = _joint(graph, t, R, seed, a, solve_positions, el)
        timings["joint"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - start
    return Lago3DResult(t=t, R=R, chi2=float(cost), chi2_seed=float(seed), route=route, method=method,
                        weighting=weighting, anchor=int(graph.ids[a]), anchor_index=a, alpha=alpha, trials=trials,
                        timings=timings, accuracy=accuracy, cost=graph.cost, graph=graph)


def _fixed_variant(graph, fixed):
    from .variants import Variant3D

    return Variant3D(graph, anchors=fixed)


def _variant(graph, *, anchors, priors, rotation_constraints, rotations, anchor, route, method, weighting,
             solver_settings) -> Lago3DResult:
    """``lago3d`` with anchors, priors, rotation constraints or given rotations (``space.variants``)."""
    from .variants import lago3d_variant

    start = time.perf_counter()
    t, R, cost, seed, alpha, trials, var = lago3d_variant(
        graph, anchors=anchors, priors=priors, rotation_constraints=rotation_constraints, rotations=rotations,
        anchor=anchor, route=route, method=method, weighting=weighting, settings=solver_settings,
        max_halvings=MAX_HALVINGS)
    return Lago3DResult(t=t, R=R, chi2=cost, chi2_seed=seed, route=route, method=method, weighting=weighting,
                        anchor=int(graph.ids[var.reference]), anchor_index=var.reference, alpha=alpha, trials=trials,
                        timings={"total": time.perf_counter() - start}, cost=graph.cost, graph=graph, variant=var)


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / max(np.abs(a).max(), 1e-300)) if a.size else 0.0


def compare_methods3d(graph, *, weighting: str = "isotropic", anchor=None, solver_settings=None, route="default"):
    """``--check`` in 3-D: the closed-form result, and a report of the largest relative differences between the
    closed form and cvxpy **on the same inputs** — ``chordal`` (the relaxed rotations, before projection) and
    ``positions`` (at the closed form's rotations) — with the cvxpy timings."""
    res = lago3d(graph, route=route, weighting=weighting, anchor=anchor)
    a = res.anchor_index
    t0 = time.perf_counter()
    cf = chordal_closed_form(graph, weighting=weighting, anchor_index=a)
    cx = chordal_cvxpy(graph, weighting=weighting, anchor_index=a, settings=solver_settings)
    t1 = time.perf_counter()
    tc, _ = positions_closed_form(graph, res.R, anchor_index=a)
    tx, _ = positions_cvxpy(graph, res.R, anchor_index=a, settings=solver_settings)
    t2 = time.perf_counter()
    report = {"max_rel_diff": {"chordal": _rel(cf.relaxed, cx.relaxed), "positions": _rel(tc, tx)},
              "cvxpy_timings": {"chordal": t1 - t0, "positions": t2 - t1}}
    return res, report
