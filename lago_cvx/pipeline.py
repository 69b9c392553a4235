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
from .errors import GraphError
from .graph import spanning_tree as build_tree
from .metrics import relative_difference
from .posegraph import PoseGraph, compose
from .regularization import REGULARIZATIONS, regularize
from .result import LagoResult
from .rounding import AMBIGUITY_MARGIN
from .solvers import ClarabelSettings, IntegerSearch, check_method
from .uncertainty import edge_uncertainty
from .variants import anchored_lago, compare_anchored_methods

__all__ = ["lago", "compare_methods"]

log = logging.getLogger(__name__)


def lago(graph: PoseGraph, *, method: str = "closed_form", spanning_tree="bfs", anchor=None,
         anchor_pose=None, margin: float = AMBIGUITY_MARGIN, solver_settings: ClarabelSettings | None = None,
         backend: str = "auto", anchors=None, regularization: str = "tree",
         integer_search: IntegerSearch | None = None) -> LagoResult:
    """LAGO: the linear approximation of planar pose-graph optimization (the seed's Section IV).

    Parameters (keyword-only):
      method — ``"closed_form"`` (sparse factorizations) or ``"cvxpy"`` (phases 1 and 3 as cvxpy
        problems solved by Clarabel with ``solver_settings``, a ``ClarabelSettings`` over the preset
        ``lago_cvx.solvers.LEAST_SQUARES``).
      spanning_tree — ``"bfs"`` (default: shortest-depth from the anchor), ``"odometry"`` (the seed's
        choice), ``"mst"``, or an array of edge indices; see ``lago_cvx.graph.spanning_tree``.
      anchor — id of the pose held fixed (default: the smallest id).
      anchor_pose — (x, y, θ) of the anchor in the output frame (default: the origin). LAGO is solved
        with the anchor at the origin and the result is rigidly moved there (exactly equivariant).
      margin — ambiguity margin of the regularization report (radians).
      regularization — ``"tree"`` (default, the seed's Theorem 3: round each chord's cycle residual
        along ``spanning_tree``), ``"chordal"`` (round every edge against the chordal relaxation of
        the rotations; robust to rotation noise accumulated along tree paths; with ``method="cvxpy"`` the
        relaxation is solved as its cvxpy problem too) or ``"integer"`` (the weighted integer
        least-squares problem the tree rounding approximates: exact enumeration, or with
        ``method="cvxpy"`` the mixed-integer cvxpy problem solved by SCIP, ``pip install
        "lago-cvx[mip]"``; ``integer_search`` an ``IntegerSearch`` to choose otherwise; at most
        ``MAX_INTEGER_CHORDS`` chords).
      backend — sparse solver of the closed form: ``"auto"``, ``"qdldl"``, ``"superlu"``, ``"cholmod"``.
      anchors — ``{id: (x, y, θ)}`` known poses (None for unknown components); when given (even ``{}``)
        LAGO runs with the known entries moved to the right-hand side (``lago_cvx.variants.anchored_lago``;
        returns its ``VariantResult``, a ``LagoResult``).
    Raises ``GraphError`` for a disconnected graph (naming component sizes), a broken odometric chain,
    or an unknown anchor; ``OptionError`` for a bad option.
    """
    if anchors is not None:
        return anchored_lago(graph, anchors=anchors, method=method, spanning_tree=spanning_tree, anchor=anchor,
                             anchor_pose=anchor_pose, margin=margin, solver_settings=solver_settings, backend=backend,
                             regularization=regularization)
    check_method(method)
    if regularization not in REGULARIZATIONS:
        from .errors import OptionError

        raise OptionError(f"unknown regularization {regularization!r}; expected one of {REGULARIZATIONS}")
    if graph.n_edges == 0 and graph.n_poses > 1:
        raise GraphError(f"the graph has {graph.n_poses} poses and no edges: nothing links them")
    a = graph.anchor_index(anchor)
    aid = int(graph.ids[a])
    anchor_pose = np.zeros(3) if anchor_pose is None else np.asarray(anchor_pose, dtype=float).reshape(3)
    timings = {}
    t_all = time.perf_counter()

    t = time.perf_counter()
    tree = build_tree(graph, spanning_tree, anchor=aid)
    timings["tree"] = time.perf_counter() - t

    t = time.perf_counter()
    reg = regularize(graph, tree, regularization=regularization, margin=margin, method=method, backend=backend,
                     settings=solver_settings, search=integer_search)
    unc = edge_uncertainty(graph)
    timings["regularization"] = time.perf_counter() - t

    problems = {} if reg.problem is None else {reg.regularization: reg.problem}  # "chordal" or "integer"
    t = time.perf_counter()
    if method == "closed_form":
        ph1 = P.phase1_closed_form(graph, reg.delta_reg, unc, anchor=aid, backend=backend)
    else:
        ph1, problems["phase1"] = P.phase1_from_problem(graph, reg.delta_reg, unc, anchor=aid,
                                                        settings=solver_settings)
    timings["phase1"] = time.perf_counter() - t

    t = time.perf_counter()
    ph2 = P.phase2(graph, ph1.theta, unc, anchor=aid)
    timings["phase2"] = time.perf_counter() - t

    t = time.perf_counter()
    if method == "closed_form":
        ph3 = P.phase3_closed_form(graph, ph2, backend=backend)
    else:
        ph3, problems["phase3"] = P.phase3_from_problem(graph, ph2, settings=solver_settings)
    timings["phase3"] = time.perf_counter() - t

    poses = compose(np.broadcast_to(anchor_pose, ph3.poses.shape), ph3.poses)
    timings["total"] = time.perf_counter() - t_all
    log.info("LAGO (%s, %s tree, %s regularization): %d poses, %d edges, %d cycles regularized, %.3f s", method,
             tree.kind, regularization, graph.n_poses, graph.n_edges, reg.n_regularized, timings["total"])
    return LagoResult(graph=graph, poses=poses, anchor=aid, anchor_index=a, anchor_pose=anchor_pose, method=method,
                      tree=tree, regularization=reg, uncertainty=unc, phase1=ph1, phase2=ph2, phase3=ph3,
                      timings=timings, problems=problems)


def compare_methods(graph: PoseGraph, *, solver_settings: ClarabelSettings | None = None, anchors=None,
                    **kwargs) -> tuple[LagoResult, dict]:
    """Run LAGO in closed form, then solve phases 1 and 3 as cvxpy problems **on the same inputs**
    (phase 3 uses the closed form's z and W, so each phase is compared in isolation).

    Returns (closed-form result, report) where report has ``max_rel_diff`` {phase1, phase3, and chordal
    (the relaxed rotations) when ``regularization="chordal"``}, the cvxpy timings and the problems.
    ``anchors`` as in ``lago`` (then ``lago_cvx.variants.compare_anchored_methods``)."""
    if anchors is not None:
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
    if res.regularization.regularization == "chordal":
        from .regularization.chordal import chordal_from_problem

        t = time.perf_counter()
        est, prob_c = chordal_from_problem(graph, res.uncertainty.info_delta, anchor=res.anchor,
                                           settings=solver_settings)
        report["cvxpy_timings"]["chordal"] = time.perf_counter() - t
        report["max_rel_diff"]["chordal"] = relative_difference(est.vectors, res.regularization.chordal.vectors)
        report["problems"]["chordal"] = prob_c
    return res, report
