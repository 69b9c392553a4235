"""The LAGO pipeline: spanning tree → regularization → phase 1 → phase 2 → phase 3.

``lago(graph)`` returns a ``LagoResult`` with the poses (n, 3) and every intermediate quantity, so a
reader can inspect each step; ``method="cvxpy"`` runs phases 1 and 3 as explicit cvxpy problems solved
by Clarabel (``result.problems`` keeps them), ``method="closed_form"`` by sparse factorizations.
``compare_methods`` runs both and reports their largest relative differences per phase.

With ``anchors=`` (even ``{}``) ``lago`` hands over to the engine of ``lago_cvx.variants``, whose
result is a ``VariantResult`` — a ``LagoResult`` with more fields.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import logging
import time

_LOADING = time.perf_counter()  # this module's imports are timed: a first call's cost (``_Clock``)

import numpy as np

from . import phases as P
from .errors import GraphError, OptionError, check_choice
from .graph import spanning_tree as build_tree
from .metrics import relative_difference
from .posegraph import PoseGraph, compose
from .posegraph_base import as_graph
from .sparse import GraphElimination, threads_option
from .positions import Polish, PositionSolver, isotropic, polish, positions_from_problem, resolve_positions
from .regularization import REGULARIZATIONS, regularize
from .result import LagoResult
from .rounding import AMBIGUITY_MARGIN
from .routes import POSITIONS, resolve_route
from .solvers import ClarabelSettings, IntegerSearch, check_method
from .uncertainty import INFORMATION_MODES, edge_uncertainty

__all__ = ["lago", "compare_methods"]

log = logging.getLogger(__name__)


#: ``lago``'s options that choose how the estimate is computed (the route and its parts), not what is solved.
ROUTE_OPTIONS = ("route", "spanning_tree", "regularization", "information", "positions", "integer_search", "weighting")


def _robust_option(run):
    """``lago``'s keywords ``cost=`` and ``robust=``: the graph read for the cost asked (``graph.with_cost``), then
    for ``robust`` None / False LAGO itself; anything else runs graduated non-convexity
    (``lago_cvx.variants.gnc_lago``) around LAGO with the other options. GNC classifies the edges on the default
    route's estimates, and a route asked for (``ROUTE_OPTIONS`` other than None / "default") computes the estimate
    on the accepted edges: GNC's residuals must be those of a near-minimum, which the seed route's are not (clean
    MIT by the seed route: χ² 13 108 against the minimum's 41.16, and GNC on its residuals rejected 5 true loop
    closures)."""

    @functools.wraps(run)
    def lago(graph, *, robust=None, cost=None, **options):
        graph = as_graph(graph) if cost is None else as_graph(graph).with_cost(cost)  # a world: its graph
        if robust is None or robust is False:
            return run(graph, **options)
        from .variants import gnc_lago, robust_settings

        settings = robust_settings(robust)
        progress = options.pop("progress", None)  # the robust run reports its own stages (``progress.Stages``)
        inner = {k: v for k, v in options.items() if k not in ROUTE_OPTIONS or v in (None, "default")}
        final = None if inner == options else (lambda g: run(g, **options))  # the route asked, on the accepted edges
        return gnc_lago(graph, settings, solve=lambda g: run(g, **inner), final_solve=final, progress=progress)

    sig = inspect.signature(run)
    lago.__signature__ = sig.replace(parameters=[*sig.parameters.values(),
                                                 inspect.Parameter("robust", inspect.Parameter.KEYWORD_ONLY),
                                                 inspect.Parameter("cost", inspect.Parameter.KEYWORD_ONLY)])
    return lago


@_robust_option
@threads_option
def lago(graph: PoseGraph, *, route: str = "default", method: str = "closed_form", spanning_tree=None,
         regularization: str | None = None, information: str | None = None, positions: str | None = None,
         anchor=None, anchor_pose=None, margin: float = AMBIGUITY_MARGIN,
         solver_settings: ClarabelSettings | None = None, backend: str = "auto", anchors=None,
         priors=None, integer_search: IntegerSearch | None = None, progress=None,
         workers: int | None = None, rotation_constraints=None) -> LagoResult:
    """LAGO: the linear approximation of planar pose-graph optimization (the seed's Section IV), on ``graph`` (a
    ``PoseGraph``, a ``PoseGraph3D``, or a generated world: its ``graph``).

    Parameters (keyword-only):
      cost — the cost the graph's information is read for, one of ``lago_cvx.conventions.COSTS``
        (``graph.with_cost(cost)``); None: the graph's own (``graph.cost``: a file format's, ``"paper"`` for a
        graph built in Python). LAGO weighs eq. (3) with the information in that cost's frame
        (``lago_cvx.posegraph``), and ``result.chi2`` is that cost.
      route — ``"default"`` or ``"seed"`` (``lago_cvx.routes.ROUTES``): the choices of tree, regularization,
        information and positions below when they are left ``None``. ``route="seed"`` is exactly the
        paper's procedure.
      method — ``"closed_form"`` (sparse factorizations) or ``"cvxpy"`` (phases 1 and 3 and the position
        polish as cvxpy problems solved by Clarabel with ``solver_settings``, a ``ClarabelSettings`` over
        the preset ``lago_cvx.solvers.LEAST_SQUARES``).
      spanning_tree — ``"bfs"`` (shortest-depth from the anchor), ``"odometry"`` (the seed's choice),
        ``"mst"``, or an array of edge indices; see ``lago_cvx.graph.spanning_tree``.
      regularization — ``"tree"`` (the seed's Theorem 3: round each chord's cycle residual along
        ``spanning_tree``), ``"chordal"`` (round every edge against the chordal relaxation of the
        rotations; robust to rotation noise accumulated along tree paths; with ``method="cvxpy"`` the
        relaxation is solved as its cvxpy problem too) or ``"integer"`` (the weighted integer
        least-squares problem the tree rounding approximates: exact enumeration, or with
        ``method="cvxpy"`` the mixed-integer cvxpy problem solved by SCIP, ``pip install
        "lago-cvx[mip]"``; ``integer_search`` an ``IntegerSearch`` to choose otherwise; at most
        ``MAX_INTEGER_CHORDS`` chords).
      information — ``"full"`` (phases 2–3 from each edge's whole 3×3 information: first-order optimal
        for any information) or ``"marginal"`` (the seed's blkdiag(P_Δ, P_δ) with the marginal
        covariances); the two agree exactly for block-diagonal information (``lago_cvx.phases``).
      positions — ``"phase3"`` (phase 3's poses) or ``"resolve"`` (positions re-solved exactly for the
        orientations, guarded by phase 1's: ``lago_cvx.positions.polish``; χ² never above phase 3's).
      anchor — id of the pose held fixed (default: the smallest id).
      anchor_pose — (x, y, θ) of the anchor in the output frame (default: the origin). LAGO is solved
        with the anchor at the origin and the result is rigidly moved there (exactly equivariant).
      margin — ambiguity margin of the regularization report (radians).
      backend — sparse solver of the closed form: ``"auto"``, ``"qdldl"``, ``"superlu"``, ``"cholmod"``.
      progress — an optional ``lago_cvx.progress.ProgressCallback`` ``(stage, fraction)``, told about the
        long steps (large factorizations, the integer search); they also log at INFO level, at most
        once a second.
      workers — the most threads the sparse engine runs at once (SciPy's name; None: the cores this process may
        use, ``lago_cvx.sparse.cores``; 1: none besides the caller's). The process's BLAS settings are left alone.
      anchors — ``{id: (x, y, θ)}`` known poses (None for unknown components); when given (even ``{}``)
        LAGO runs with the known entries moved to the right-hand side (``lago_cvx.variants.anchored_lago``;
        returns its ``VariantResult``, a ``LagoResult``).
      priors — ``{id: (mean, information)}`` soft absolute measurements, full (x, y, θ) with a 3×3 information,
        position-only ``((x, y, None), Λ 2×2)`` (GPS) or ``((None, None, θ), λ)``
        (``lago_cvx.variants.normalize_priors``); like ``anchors`` they hand over to the variants engine.
      robust — None / False (default): least squares. True, ``"gnc-tls"``, ``"gnc-gm"`` or a
        ``lago_cvx.variants.RobustSettings``: graduated non-convexity around weighted LAGO runs with the
        options above, rejecting false loop closures (``lago_cvx.variants.gnc``); returns a ``RobustResult``
        (``rejected_edges``, ``weights``; its ``graph`` and ``chi2`` are those of the accepted edges); on a 3-D
        graph GNC runs around ``lago3d`` and returns a ``Robust3DResult`` (``lago_cvx.variants.robust3d``).
    Raises ``GraphError`` for a disconnected graph (naming component sizes), a broken odometric chain,
    or an unknown anchor; ``OptionError`` for a bad option.

    A 3-D graph (``graph.dim == 3``, a ``PoseGraph3D``) goes to ``lago_cvx.space.lago3d`` with ``route``,
    ``method``, ``anchor``, ``solver_settings``, ``anchors`` ``{id: (t, R)}``, ``priors`` ``{id: (t̄, R̄, Λ)}`` and
    ``rotation_constraints`` ``{id: (a, b)}`` (R_id a = b; 3-D only) — ``lago_cvx.space.variants``; the planar
    options do not apply and must be left unset.
    """
    clock = _Clock()  # from the call's first line: ``timings["total"]`` is the whole call
    if getattr(graph, "dim", 2) == 3 or rotation_constraints is not None:
        return _in_space(graph, route=route, method=method, anchor=anchor, solver_settings=solver_settings,
                         anchors=anchors, priors=priors, rotation_constraints=rotation_constraints,
                         spanning_tree=spanning_tree, regularization=regularization, information=information,
                         positions=positions, anchor_pose=anchor_pose, integer_search=integer_search)
    choice, route_name = resolve_route(route, spanning_tree=spanning_tree, regularization=regularization,
                                       information=information, positions=positions)
    if anchors is not None or priors is not None:  # the variants engine (loaded on demand)
        from .variants import anchored_lago
        return anchored_lago(graph, anchors=anchors, priors=priors, method=method, route=route, positions=positions,
                             spanning_tree=spanning_tree, regularization=regularization, information=information,
                             anchor=anchor, anchor_pose=anchor_pose, margin=margin, solver_settings=solver_settings,
                             backend=backend, integer_search=integer_search, progress=progress)
    _check_options(graph, method, choice)
    a = graph.anchor_index(anchor)
    aid = int(graph.ids[a])
    anchor_pose = np.zeros(3) if anchor_pose is None else np.asarray(anchor_pose, dtype=float).reshape(3)
    closed, resolve = method == "closed_form", choice["positions"] == "resolve"
    problems = {}
    unc = edge_uncertainty(graph)
    # The pose-level elimination shared by every closed-form system (AMD, Ω_θ = A2 P_δ⁻¹ A2ᵀ factored), built
    # by the engine while the tree and the regularization are computed; told which systems will follow.
    elim = _elimination(graph, a, unc, choice) if closed and backend == "auto" else None
    solver = PositionSolver(graph, unc, elim) if elim is not None and resolve else None
    with clock("tree"):
        tree = build_tree(graph, choice["spanning_tree"], anchor=aid)
    unc.prepare(information=choice["information"], positions=choice["positions"])
    with clock("regularization"):
        reg = regularize(graph, tree, regularization=choice["regularization"], margin=margin, method=method,
                         backend=backend, settings=solver_settings, search=integer_search, progress=progress,
                         uncertainty=unc, elimination=elim)
    if reg.problem is not None:
        problems[reg.regularization] = reg.problem  # "chordal" or "integer"
    with clock("phase1"):  # eq. (13)
        if closed:
            ph1 = P.phase1_closed_form(graph, reg.delta_reg, unc, anchor=aid, backend=backend, elimination=elim)
        else:
            ph1, problems["phase1"] = P.phase1_from_problem(graph, reg.delta_reg, unc, anchor=aid,
                                                            settings=solver_settings)
    if solver is not None:
        solver.expect(ph1.theta)  # the polish's trial at θ̂ does not need phase 3: solved beside it
    with clock("phase2"):  # eqs. (9)–(11)
        ph2 = P.phase2(graph, ph1.theta, unc, anchor=aid, information=choice["information"],
                       delta_reg=reg.delta_reg, elimination=elim)
    with clock("phase3"):  # eqs. (12), (15)
        if closed:
            ph3 = P.phase3_closed_form(graph, ph2, backend=backend, elimination=elim, progress=progress)
        else:
            ph3, problems["phase3"] = P.phase3_from_problem(graph, ph2, settings=solver_settings)
    with clock("positions"):  # eq. (14) at phase 3's orientations, guarded by phase 1's
        pol = _polish(graph, ph1.theta, ph3.poses[:, 2], unc, aid, method, backend, solver_settings, problems,
                      solver) if resolve else None
    poses = compose(np.broadcast_to(anchor_pose, ph3.poses.shape), ph3.poses if pol is None else pol.poses)
    result = LagoResult(graph=graph, poses=poses, anchor=aid, anchor_index=a, anchor_pose=anchor_pose,
                        method=method, tree=tree, regularization=reg, uncertainty=unc, phase1=ph1, phase2=ph2,
                        phase3=ph3, timings=clock.timings, problems=problems, route=route_name,
                        information=choice["information"], positions=choice["positions"], polish=pol)
    _log_run(graph, route_name, method, tree, reg, choice, clock.done()["total"])
    return result


def _log_run(graph, route_name, method, tree, reg, choice, seconds) -> None:
    log.info("LAGO (%s route, %s, %s tree, %s regularization, %s information, %s positions): %d poses, %d edges, "
             "%d cycles regularized, %.3f s", route_name, method, tree.kind, reg.regularization,
             choice["information"], choice["positions"], graph.n_poses, graph.n_edges, reg.n_regularized, seconds)


def _in_space(graph, *, route, method, anchor, solver_settings, anchors, priors, rotation_constraints, **planar):
    """A 3-D graph to ``lago_cvx.space.lago3d``; the planar-only options must be left unset."""
    from .space import lago3d

    if getattr(graph, "dim", 2) != 3:
        raise OptionError("rotation_constraints: 3-D graphs only (planar orientations: variants.orientation_bounds)")
    given = sorted(k for k, v in planar.items() if v is not None)
    if given:
        raise OptionError(f"option(s) {', '.join(given)} apply to planar graphs only")
    return lago3d(graph, route=route, method=method, anchor=anchor, solver_settings=solver_settings, anchors=anchors,
                  priors=priors, rotation_constraints=rotation_constraints)


def _check_options(graph: PoseGraph, method: str, choice: dict) -> None:
    check_method(method)
    check_choice("regularization", choice["regularization"], REGULARIZATIONS)
    check_choice("information", choice["information"], INFORMATION_MODES)
    check_choice("positions", choice["positions"], POSITIONS)
    if graph.n_edges == 0 and graph.n_poses > 1:
        raise GraphError(f"the graph has {graph.n_poses} poses and no edges: nothing links them")


def _elimination(graph: PoseGraph, a: int, unc, choice: dict) -> GraphElimination:
    """The shared elimination, started; the systems announced in the order they will be factored: the
    chordal relaxation (2×2 blocks), phase 3 (3×3) and the position polish (1×1 or 2×2)."""
    expect = ((2,) if choice["regularization"] == "chordal" else ()) + (3,)
    if choice["positions"] == "resolve":
        expect += (1 if isotropic(unc) else 2,)
    return GraphElimination.start(graph, a, expect=expect)


class _Clock:
    """Seconds per step: ``with clock("phase1"): ...``; ``done()`` adds the total and returns them. The first
    clock of a process also counts, as ``first_call`` and in the total, what loading this module and its imports
    took (on first use of ``lago_cvx.lago``; the lazy public API loads it then): a first call's wall time around
    ``lago_cvx.lago(graph)`` then matches its total."""

    def __init__(self):
        self.timings, self._t0 = {}, time.perf_counter()

    @contextlib.contextmanager
    def __call__(self, step: str):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.timings[step] = time.perf_counter() - t

    def done(self) -> dict:
        self.timings["total"] = time.perf_counter() - self._t0
        if _LOADED:
            self.timings["first_call"] = _LOADED.pop()
            self.timings["total"] += self.timings["first_call"]
        return self.timings


def _polish(graph, theta_hat, theta_star, unc, aid, method, backend, settings, problems, solver=None) -> Polish:
    """The position polish in closed form or as cvxpy problems (the last one solved is kept). In closed
    form one ``PositionSolver`` (``solver``, or a new one) serves every trial (isotropic information: one
    factorization for all), and the trial at θ̂ comes from it when it was solved ahead."""
    if solver is None and method == "closed_form" and backend == "auto":
        solver = PositionSolver(graph, unc, GraphElimination(graph, graph.anchor_index(aid)))

    def solve_positions(theta):
        if method == "closed_form":
            return resolve_positions(graph, theta, unc, anchor=aid, backend=backend, solver=solver)
        pos, problems["positions"] = positions_from_problem(graph, theta, unc, anchor=aid, settings=settings)
        return pos

    ahead = solver.expected(theta_hat) if solver is not None else None
    base, base_cost = ahead if ahead is not None else (None, None)
    return polish(graph, theta_hat, theta_star, unc, solve_positions=solve_positions,
                  solve_many=solver.many if solver is not None else None, base=base, base_cost=base_cost)


def compare_methods(graph: PoseGraph, *, solver_settings: ClarabelSettings | None = None, anchors=None,
                    **kwargs) -> tuple[LagoResult, dict]:
    """Run LAGO in closed form, then solve phases 1 and 3 as cvxpy problems **on the same inputs**
    (phase 3 uses the closed form's z and W, so each phase is compared in isolation).

    Returns (closed-form result, report) where report has ``max_rel_diff`` {phase1, phase3, ``positions``
    (the polish at the orientations it chose) with ``positions="resolve"``, and ``chordal`` (the relaxed
    rotations) with ``regularization="chordal"``}, the cvxpy timings and the problems.
    ``anchors`` as in ``lago`` (then ``lago_cvx.variants.compare_anchored_methods``, which honours every
    keyword of ``lago`` too). ``kwargs``: the keywords of ``lago`` but ``method`` (both run: ``OptionError``).

    ``robust`` (as in ``lago``): graduated non-convexity runs first, in closed form; the comparison is then made
    on its result's final least-squares run, LAGO on the accepted edges (``result.graph``), whose closed form
    is the robust result's estimate. Returns (the robust result, that report, with ``accepted_edges``).
    A 3-D graph goes to ``lago_cvx.space.compare_methods3d`` (keywords ``route`` and ``anchor``)."""
    if "method" in kwargs:
        raise OptionError("method: compare_methods solves both ways (closed form, then cvxpy); do not pass method")
    if kwargs.get("cost") is not None:
        graph = graph.with_cost(kwargs.pop("cost"))
    if kwargs.get("robust") not in (None, False):
        res = lago(graph, **kwargs, **({} if anchors is None else {"anchors": anchors}))
        kwargs.pop("robust")
        _, report = compare_methods(res.graph, solver_settings=solver_settings, anchors=anchors, **kwargs)
        report["accepted_edges"] = int(res.graph.n_edges)
        return res, report
    kwargs.pop("robust", None)
    if getattr(graph, "dim", 2) == 3:  # one door: a 3-D graph is compared by lago_cvx.space.compare_methods3d
        from .space import compare_methods3d

        given = sorted(k for k, v in kwargs.items() if v is not None and k not in ("route", "anchor"))
        if given or anchors is not None:
            raise OptionError(f"compare_methods on a 3-D graph takes route and anchor only, got "
                              f"{', '.join(given + ['anchors'] * (anchors is not None))}")
        return compare_methods3d(graph, route=kwargs.get("route", "default"), anchor=kwargs.get("anchor"),
                                 solver_settings=solver_settings)
    if anchors is not None:
        from .variants import compare_anchored_methods

        return compare_anchored_methods(graph, anchors=anchors, solver_settings=solver_settings, **kwargs)
    res = lago(graph, method="closed_form", **kwargs)
    t = time.perf_counter()
    ph1, prob1 = P.phase1_from_problem(graph, res.regularization.delta_reg, res.uncertainty, anchor=res.anchor,
                                       settings=solver_settings)
    t1 = time.perf_counter() - t
    t = time.perf_counter()
    ph3, prob3 = P.phase3_from_problem(graph, res.phase2, settings=solver_settings)
    t3 = time.perf_counter() - t
    report = {
        "max_rel_diff": {"phase1": relative_difference(ph1.theta_free, res.phase1.theta_free),
                         "phase3": relative_difference(ph3.x_star, res.phase3.x_star)},
        "cvxpy_timings": {"phase1": t1, "phase3": t3},
        "problems": {"phase1": prob1, "phase3": prob3},
    }
    if res.polish is not None:
        t = time.perf_counter()
        pos, prob_p = positions_from_problem(graph, res.polish.poses[:, 2], res.uncertainty, anchor=res.anchor,
                                             settings=solver_settings)
        report["cvxpy_timings"]["positions"] = time.perf_counter() - t
        report["max_rel_diff"]["positions"] = relative_difference(pos.poses[:, :2], res.polish.poses[:, :2])
        report["problems"]["positions"] = prob_p
    if res.regularization.regularization == "chordal":
        from .regularization.chordal import chordal_from_problem

        t = time.perf_counter()
        est, prob_c = chordal_from_problem(graph, res.uncertainty.info_delta, anchor=res.anchor,
                                           settings=solver_settings)
        report["cvxpy_timings"]["chordal"] = time.perf_counter() - t
        report["max_rel_diff"]["chordal"] = relative_difference(est.vectors, res.regularization.chordal.vectors)
        report["problems"]["chordal"] = prob_c
    return res, report


_LOADED = [time.perf_counter() - _LOADING]  # popped by the first ``_Clock.done()``
