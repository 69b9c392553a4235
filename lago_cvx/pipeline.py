"""The LAGO pipeline: spanning tree → regularization → phase 1 → phase 2 → phase 3.

``lago(graph)`` returns a ``LagoResult`` with the poses (n, 3) and every intermediate quantity, so a
reader can inspect each step; ``method="cvxpy"`` runs phases 1 and 3 as explicit cvxpy problems solved
by Clarabel (``result.problems`` keeps them), ``method="closed_form"`` by sparse factorizations.
``compare_methods`` runs both and reports their largest relative differences per phase.

With ``anchors=`` (even ``{}``) ``lago`` hands over to the engine of ``lago_cvx.variants``, whose
result is a ``VariantResult`` — a ``LagoResult`` with more fields.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from . import phases as P
from .errors import GraphError, OptionError, check_choice
from .graph import spanning_tree as build_tree
from .metrics import chi2, relative_difference
from .posegraph import PoseGraph, compose
from .normal_equations import COMPILED_MIN, GraphElimination
from .positions import Polish, PositionSolver, polish, positions_from_problem, resolve_positions
from .regularization import REGULARIZATIONS, regularize
from .result import LagoResult
from .rounding import AMBIGUITY_MARGIN
from .routes import POSITIONS, resolve_route
from .solvers import ClarabelSettings, IntegerSearch, check_method
from .uncertainty import INFORMATION_MODES, edge_uncertainty

__all__ = ["lago", "compare_methods"]

log = logging.getLogger(__name__)


def lago(graph: PoseGraph, *, route: str = "default", method: str = "closed_form", spanning_tree=None,
         regularization: str | None = None, information: str | None = None, positions: str | None = None,
         anchor=None, anchor_pose=None, margin: float = AMBIGUITY_MARGIN,
         solver_settings: ClarabelSettings | None = None, backend: str = "auto", anchors=None,
         integer_search: IntegerSearch | None = None, progress=None) -> LagoResult:
    """LAGO: the linear approximation of planar pose-graph optimization (the seed's Section IV).

    Parameters (keyword-only):
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
      anchors — ``{id: (x, y, θ)}`` known poses (None for unknown components); when given (even ``{}``)
        LAGO runs with the known entries moved to the right-hand side (``lago_cvx.variants.anchored_lago``;
        returns its ``VariantResult``, a ``LagoResult``).
    Raises ``GraphError`` for a disconnected graph (naming component sizes), a broken odometric chain,
    or an unknown anchor; ``OptionError`` for a bad option.

    A 3-D graph (``graph.dim == 3``, a ``PoseGraph3D``) goes to ``lago_cvx.space.lago3d`` with ``route``,
    ``method``, ``anchor`` and ``solver_settings`` (the planar options do not apply and must be left unset).
    """
    if getattr(graph, "dim", 2) == 3:
        from .space import lago3d

        planar = {"spanning_tree": spanning_tree, "regularization": regularization, "information": information,
                  "positions": positions, "anchor_pose": anchor_pose, "anchors": anchors,
                  "integer_search": integer_search}
        given = sorted(k for k, v in planar.items() if v is not None)
        if given:
            raise OptionError(f"option(s) {', '.join(given)} apply to planar graphs only")
        return lago3d(graph, route=route, method=method, anchor=anchor, solver_settings=solver_settings)
    choice, route_name = resolve_route(route, spanning_tree=spanning_tree, regularization=regularization,
                                       information=information, positions=positions)
    if anchors is not None:
        from .variants import anchored_lago  # the engine of anchors, priors, constraints (loaded on demand)

        return anchored_lago(graph, anchors=anchors, method=method, route=route, spanning_tree=spanning_tree,
                             regularization=regularization, information=information, positions=positions,
                             anchor=anchor, anchor_pose=anchor_pose, margin=margin, solver_settings=solver_settings,
                             backend=backend)
    check_method(method)
    check_choice("regularization", choice["regularization"], REGULARIZATIONS)
    check_choice("information", choice["information"], INFORMATION_MODES)
    check_choice("positions", choice["positions"], POSITIONS)
    if graph.n_edges == 0 and graph.n_poses > 1:
        raise GraphError(f"the graph has {graph.n_poses} poses and no edges: nothing links them")
    a = graph.anchor_index(anchor)
    aid = int(graph.ids[a])
    anchor_pose = np.zeros(3) if anchor_pose is None else np.asarray(anchor_pose, dtype=float).reshape(3)
    timings, problems = {}, {}
    t_all = time.perf_counter()

    # The pose-level elimination, shared by every closed-form system: AMD and the factorization of phase 1's
    # Ω_θ = A2 P_δ⁻¹ A2ᵀ (QDLDL), the elimination tree and fronts (lago_cvx.multifrontal); timed as phase 1.
    # AMD (lago_cvx.amd) and QDLDL run in C without the GIL, so they run in a worker thread while this one
    # builds the tree.
    t = time.perf_counter()
    unc = edge_uncertainty(graph)
    elim_job = None
    early = choice["regularization"] == "chordal"  # factors on the shared elimination before phase 1
    if method == "closed_form" and backend == "auto":
        weights = unc.info_delta  # here: the worker starts with AMD, whose call releases the GIL at once
        # Ω_θ factored in the worker; or, when QDLDL factors the chordal relaxation (below COMPILED_MIN
        # unknowns), beside that factorization, whose pattern the worker builds after AMD while this thread
        # computes the uncertainty forms (``warm``). Above, the compiled engine's plan needs Ω_θ's factor.
        qdldl_first = early and 2 * (graph.n_poses - 1) < COMPILED_MIN

        def eliminate():
            el = GraphElimination(graph, a, weights=weights, factor_laplacian=not qdldl_first)
            if qdldl_first:
                el.upper_pattern(2)
            return el

        elim_job = _Beside(eliminate)
    t_elim = time.perf_counter() - t

    t = time.perf_counter()
    try:
        tree = build_tree(graph, choice["spanning_tree"], anchor=aid)
    except BaseException:
        if elim_job is not None:
            elim_job.join()
        raise
    timings["tree"] = time.perf_counter() - t

    elim, pos_solver = None, None

    def elimination(b):  # wait for the worker, then register what runs beside the first QDLDL factorization
        nonlocal elim, pos_solver
        elim = elim_job.result() if elim_job is not None else None
        if elim is not None:  # (the chordal relaxation's, or phase 3's)
            if method == "closed_form":  # the next compiled factorization (b×b blocks), when it will run, made
                elim.prepare(b)  # ready beside the work before it
            elim.defer(lambda: elim.upper_pattern(3))  # phase 3's pattern
            elim.defer(lambda: elim.laplacian)  # Ω_θ's factorization, when it waited (phase 1 needs it)
            if choice["positions"] == "resolve":
                pos_solver = PositionSolver(graph, unc, elim)
                elim.defer(pos_solver.prefactor)  # the polish's θ-independent factorization (isotropic)
            if b == 3:
                prepare_polish()

    def prepare_polish():  # the polish's isotropic system (1×1 blocks, θ-independent) made ready beside phase 3's
        if method == "closed_form" and pos_solver is not None and pos_solver.isotropic:
            elim.prepare(1)

    def warm():  # while the worker builds the elimination: the uncertainty forms phases 2–3 will read
        if elim_job is None or graph.n_edges == 0:
            return
        forms = ["sqrt_info_delta_l" if choice["information"] == "marginal" else "sqrt_info"]
        if choice["positions"] == "resolve":
            forms.append("sqrt_info_pp")
        for form in forms:  # each computed once, when first read (lago_cvx.uncertainty)
            getattr(unc, form)

    # Only the chordal regularizer factors on the shared elimination: the others run while it is built.
    if early:  # the chordal relaxation (2×2 blocks) prepared first, phase 3 after it
        t = time.perf_counter()
        warm()
        elimination(2)
        t_elim += time.perf_counter() - t

    t = time.perf_counter()
    try:
        reg = regularize(graph, tree, regularization=choice["regularization"], margin=margin, method=method,
                         backend=backend, settings=solver_settings, search=integer_search, progress=progress,
                         uncertainty=unc, elimination=elim)
    except BaseException:
        if elim_job is not None and not early:
            elim_job.join()
        raise
    timings["regularization"] = time.perf_counter() - t
    if not early:
        t = time.perf_counter()
        warm()
        elimination(3)
        t_elim += time.perf_counter() - t
    elif elim is not None and method == "closed_form":
        elim.prepare(3)  # beside phases 1 and 2
        prepare_polish()
    if reg.problem is not None:
        problems[reg.regularization] = reg.problem  # "chordal" or "integer"

    t = time.perf_counter()
    if method == "closed_form":
        ph1 = P.phase1_closed_form(graph, reg.delta_reg, unc, anchor=aid, backend=backend, elimination=elim)
    else:
        ph1, problems["phase1"] = P.phase1_from_problem(graph, reg.delta_reg, unc, anchor=aid,
                                                        settings=solver_settings)
    timings["phase1"] = time.perf_counter() - t + t_elim
    at_theta_hat = {}
    if pos_solver is not None and pos_solver.isotropic:  # the polish's θ̂ trial and its χ², beside phase 3's
        def theta_hat_trial():  # factorization
            at_theta_hat["base"] = pos_solver(ph1.theta)
            at_theta_hat["cost"] = chi2(graph, at_theta_hat["base"].poses)

        elim.defer(theta_hat_trial)

    t = time.perf_counter()
    ph2 = P.phase2(graph, ph1.theta, unc, anchor=aid, information=choice["information"], delta_reg=reg.delta_reg,
                   elimination=elim)
    timings["phase2"] = time.perf_counter() - t

    t = time.perf_counter()
    if method == "closed_form":
        ph3 = P.phase3_closed_form(graph, ph2, backend=backend, elimination=elim, progress=progress)
        if elim is not None:
            elim.cancel_deferred()  # not run (phase 3 by the multifrontal engine): done when needed
    else:
        ph3, problems["phase3"] = P.phase3_from_problem(graph, ph2, settings=solver_settings)
    timings["phase3"] = time.perf_counter() - t

    t = time.perf_counter()
    pol, poses = None, ph3.poses
    if choice["positions"] == "resolve":
        pol = _polish(graph, ph1.theta, ph3.poses[:, 2], unc, aid, method, backend, solver_settings, problems, elim,
                      pos_solver, at_theta_hat.get("base"), at_theta_hat.get("cost"))
        poses = pol.poses
    timings["positions"] = time.perf_counter() - t

    poses = compose(np.broadcast_to(anchor_pose, poses.shape), poses)
    timings["total"] = time.perf_counter() - t_all
    log.info("LAGO (%s route, %s, %s tree, %s regularization, %s information, %s positions): %d poses, %d edges, "
             "%d cycles regularized, %.3f s", route_name, method, tree.kind, reg.regularization,
             choice["information"], choice["positions"], graph.n_poses, graph.n_edges, reg.n_regularized,
             timings["total"])
    return LagoResult(graph=graph, poses=poses, anchor=aid, anchor_index=a, anchor_pose=anchor_pose, method=method,
                      tree=tree, regularization=reg, uncertainty=unc, phase1=ph1, phase2=ph2, phase3=ph3,
                      timings=timings, problems=problems, route=route_name, information=choice["information"],
                      positions=choice["positions"], polish=pol)


class _Beside:
    """``fn()`` run in a worker thread (for work that releases the GIL, beside this thread's own):
    ``result()`` waits for it and returns its value or raises its exception."""

    def __init__(self, fn):
        import threading

        self._value, self._error = None, None

        def run():
            try:
                self._value = fn()
            except BaseException as exc:  # handed to whoever asks for the result
                self._error = exc

        self._thread = threading.Thread(target=run, daemon=True, name="lago-beside")
        self._thread.start()

    def join(self) -> None:
        self._thread.join()

    def result(self):
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value


def _polish(graph, theta_hat, theta_star, unc, aid, method, backend, settings, problems, elim=None,
            solver=None, base=None, base_cost=None) -> Polish:
    """The position polish in closed form or as cvxpy problems (the last one solved is kept). In closed
    form one ``PositionSolver`` (``solver``, or a new one) serves every trial (isotropic information: one
    factorization for all); ``base`` the trial at θ̂ when it was solved already, ``base_cost`` its χ²."""
    if solver is None and elim is not None:
        solver = PositionSolver(graph, unc, elim)

    def solve_positions(theta):
        if method == "closed_form":
            return resolve_positions(graph, theta, unc, anchor=aid, backend=backend, solver=solver)
        pos, problems["positions"] = positions_from_problem(graph, theta, unc, anchor=aid, settings=settings)
        return pos

    many = None
    if method == "closed_form" and backend == "auto" and solver is not None and solver.elim.anchor_index == \
            graph.anchor_index(aid):
        many = solver.many  # both first trials as right-hand sides of one system (isotropic information)
    return polish(graph, theta_hat, theta_star, unc, solve_positions=solve_positions, solve_many=many, base=base,
                  base_cost=base_cost if base is not None else None)


def compare_methods(graph: PoseGraph, *, solver_settings: ClarabelSettings | None = None, anchors=None,
                    **kwargs) -> tuple[LagoResult, dict]:
    """Run LAGO in closed form, then solve phases 1 and 3 as cvxpy problems **on the same inputs**
    (phase 3 uses the closed form's z and W, so each phase is compared in isolation).

    Returns (closed-form result, report) where report has ``max_rel_diff`` {phase1, phase3, ``positions``
    (the polish at the orientations it chose) with ``positions="resolve"``, and ``chordal`` (the relaxed
    rotations) with ``regularization="chordal"``}, the cvxpy timings and the problems.
    ``anchors`` as in ``lago`` (then ``lago_cvx.variants.compare_anchored_methods``)."""
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
