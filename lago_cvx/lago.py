"""The LAGO pipeline: spanning tree → regularization → phase 1 → phase 2 → phase 3.

``lago(graph)`` returns a ``LagoResult`` with the poses (n, 3) and every intermediate quantity, so a
reader can inspect each step; ``method="cvxpy"`` runs phases 1 and 3 as explicit cvxpy problems solved
by Clarabel (``result.problems`` keeps them), ``method="closed_form"`` by sparse factorizations.
``compare_methods`` runs both and reports their largest relative differences per phase.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from . import phases as P
from .cost import chi2
from .graph import SpanningTree, spanning_tree as build_tree
from .posegraph import GraphError, PoseGraph, compose
from .regularization import AMBIGUITY_MARGIN, REGULARIZATIONS, RegularizationReport, regularize

__all__ = ["LagoResult", "lago", "compare_methods", "METHODS", "relative_difference"]

log = logging.getLogger(__name__)

METHODS = ("closed_form", "cvxpy")


@dataclass(eq=False)
class LagoResult:
    """Everything LAGO computed.

    ``poses`` (n, 3) final estimate (x, y, θ) in the frame given by ``anchor_pose`` (θ unwrapped along
    the tree; wrap for display); ``tree``; ``regularization`` (the 2kπ report; its ``regularization``
    field says "tree", "chordal" or "integer"); ``uncertainty``
    (per-edge marginal P_Δ, P_δ); ``phase1``, ``phase2``, ``phase3`` (see ``lago_cvx.phases``; computed in
    the anchor's own frame, anchor at the origin); ``timings`` seconds per step (keys
    ``tree``, ``regularization``, ``phase1``, ``phase2``, ``phase3``, ``total``); ``problems`` the cvxpy
    problems (method "cvxpy" only: "phase1", "phase3", and "chordal" / "integer" with those regularizations)."""

    graph: PoseGraph
    poses: np.ndarray
    anchor: int
    anchor_pose: np.ndarray
    method: str
    tree: SpanningTree
    regularization: RegularizationReport
    uncertainty: P.EdgeUncertainty
    phase1: P.Phase1
    phase2: P.Phase2
    phase3: P.Phase3
    timings: dict
    problems: dict = field(default_factory=dict)

    @property
    def orientations(self) -> np.ndarray:
        """Phase-1 orientations θ̂ (n,), in the output frame."""
        return self.phase1.theta + self.anchor_pose[2]

    @property
    def chi2(self) -> float:
        """χ² of eq. (3) at ``poses`` (g2o convention, no ½)."""
        return chi2(self.graph, self.poses)

    def pose_covariances(self) -> np.ndarray:
        """Marginal covariance (n, 3, 3) of each pose from phase 3's information (zeros at the anchor),
        rotated into the output frame."""
        cov = self.phase3.pose_covariances()
        T = np.eye(3)
        c, s = np.cos(self.anchor_pose[2]), np.sin(self.anchor_pose[2])
        T[:2, :2] = [[c, -s], [s, c]]
        return T @ cov @ T.T

    def summary(self) -> dict:
        return {"n_poses": self.graph.n_poses, "n_edges": self.graph.n_edges, "method": self.method,
                "spanning_tree": self.tree.kind, **self.regularization.summary(), "chi2": self.chi2,
                "timings": dict(self.timings)}


def _resolve_anchor(graph: PoseGraph, anchor) -> int:
    """Anchor given as a pose id (as in the file); returns its index."""
    return graph.index_of(anchor)


def lago(graph: PoseGraph, *, method: str = "closed_form", spanning_tree="bfs", anchor: int | None = None,
         anchor_pose=None, margin: float = AMBIGUITY_MARGIN, solver_settings: dict | None = None,
         backend: str = "auto", anchors=None, regularization: str = "tree") -> LagoResult:
    """LAGO: the linear approximation of planar pose-graph optimization (the seed's Section IV).

    Parameters (keyword-only):
      method — ``"closed_form"`` (sparse factorizations) or ``"cvxpy"`` (phases 1 and 3 as cvxpy
        problems solved by Clarabel with ``CLARABEL_SETTINGS`` updated by ``solver_settings``).
      spanning_tree — ``"bfs"`` (default: shortest-depth from the anchor), ``"odometry"`` (the seed's
        choice), ``"mst"``, or an array of edge indices; see ``lago_cvx.graph.spanning_tree``.
      anchor — id of the pose held fixed (default: the smallest id, i.e. pose 0 in usual files).
      anchor_pose — (x, y, θ) of the anchor in the output frame (default: the origin). LAGO is solved
        with the anchor at the origin and the result is rigidly moved there (exactly equivariant).
      margin — ambiguity margin of the regularization report (radians).
      regularization — ``"tree"`` (default, the seed's Theorem 3: round each chord's cycle residual
        along ``spanning_tree``) or ``"chordal"`` (round every edge against the chordal relaxation of
        the rotations, ``lago_cvx.chordal``; robust to rotation noise accumulated along tree paths).
        With ``method="cvxpy"`` the chordal relaxation is solved as its cvxpy problem too.
        ``"integer"``: the weighted integer least-squares problem of the cycle integers that the tree
        rounding approximates (``lago_cvx.integer``; exact enumeration, or with ``method="cvxpy"`` the
        mixed-integer cvxpy problem solved by SCIP, ``pip install "lago-cvx[mip]"``); at most
        ``MAX_INTEGER_CHORDS`` chords.
      backend — sparse solver of the closed form: ``"auto"``, ``"superlu"``, ``"cholmod"``.
      anchors — ``{id: (x, y, θ)}`` known poses (None for unknown components); when given (even ``{}``)
        LAGO runs with the known entries moved to the right-hand side, see ``lago_cvx.variants``
        (``anchored_lago``; returns its ``VariantResult``).
    Raises ``GraphError`` for a disconnected graph (naming component sizes), a broken odometric chain,
    or an unknown anchor.
    """
    if anchors is not None:
        from .variants import anchored_lago
        return anchored_lago(graph, anchors=anchors, method=method, spanning_tree=spanning_tree, anchor=anchor,
                             anchor_pose=anchor_pose, margin=margin, solver_settings=solver_settings, backend=backend,
                             regularization=regularization)
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {METHODS}")
    if regularization not in REGULARIZATIONS:
        raise ValueError(f"unknown regularization {regularization!r}; expected one of {REGULARIZATIONS}")
    if graph.n_edges == 0 and graph.n_poses > 1:
        raise GraphError(f"the graph has {graph.n_poses} poses and no edges: nothing links them")
    a = _resolve_anchor(graph, graph.ids[0] if anchor is None else anchor)
    anchor_pose = np.zeros(3) if anchor_pose is None else np.asarray(anchor_pose, dtype=float).reshape(3)
    timings = {}
    t_all = time.perf_counter()

    t = time.perf_counter()
    tree = build_tree(graph, spanning_tree, anchor=a)
    timings["tree"] = time.perf_counter() - t

    t = time.perf_counter()
    reg = regularize(graph, tree, regularization=regularization, margin=margin, method=method, backend=backend,
                     solver_settings=solver_settings)
    unc = P.edge_uncertainty(graph)
    timings["regularization"] = time.perf_counter() - t

    problems = {} if reg.problem is None else {reg.regularization: reg.problem}  # "chordal" or "integer"
    t = time.perf_counter()
    if method == "closed_form":
        ph1 = P.phase1_closed_form(graph, reg.delta_reg, unc, anchor=a, backend=backend)
    else:
        ph1, problems["phase1"] = P.phase1_from_problem(graph, reg.delta_reg, unc, anchor=a,
                                                        settings=solver_settings)
    timings["phase1"] = time.perf_counter() - t

    t = time.perf_counter()
    ph2 = P.phase2(graph, ph1.theta, unc, anchor=a)
    timings["phase2"] = time.perf_counter() - t

    t = time.perf_counter()
    if method == "closed_form":
        ph3 = P.phase3_closed_form(graph, ph2, anchor=a, backend=backend)
    else:
        ph3, problems["phase3"] = P.phase3_from_problem(graph, ph2, anchor=a, settings=solver_settings)
    timings["phase3"] = time.perf_counter() - t

    poses = compose(np.broadcast_to(anchor_pose, ph3.poses.shape), ph3.poses)
    timings["total"] = time.perf_counter() - t_all
    log.info("LAGO (%s, %s tree, %s regularization): %d poses, %d edges, %d cycles regularized, %.3f s", method,
             tree.kind, regularization, graph.n_poses, graph.n_edges, reg.n_regularized, timings["total"])
    return LagoResult(graph=graph, poses=poses, anchor=a, anchor_pose=anchor_pose, method=method, tree=tree,
                      regularization=reg, uncertainty=unc, phase1=ph1, phase2=ph2, phase3=ph3, timings=timings,
                      problems=problems)


def relative_difference(a, b) -> float:
    """‖a − b‖∞ / max(‖b‖∞, tiny): the "relative difference" reported by ``--check``."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.size == 0:
        return 0.0
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), np.finfo(float).tiny))


def compare_methods(graph: PoseGraph, *, solver_settings: dict | None = None, anchors=None,
                    **kwargs) -> tuple[LagoResult, dict]:
    """Run LAGO in closed form, then solve phases 1 and 3 as cvxpy problems **on the same inputs**
    (phase 3 uses the closed form's z and W, so each phase is compared in isolation).

    Returns (closed-form result, report) where report has ``max_rel_diff`` {phase1, phase3, and chordal
    (the relaxed rotations) when ``regularization="chordal"``}, the cvxpy timings and the problems. ``anchors`` as in ``lago`` (then
    ``lago_cvx.variants.compare_anchored_methods``)."""
    if anchors is not None:
        from .variants import compare_anchored_methods
        return compare_anchored_methods(graph, anchors=anchors, solver_settings=solver_settings, **kwargs)
    res = lago(graph, method="closed_form", **kwargs)
    t = time.perf_counter()
    ph1, prob1 = P.phase1_from_problem(graph, res.regularization.delta_reg, res.uncertainty, anchor=res.anchor,
                                       settings=solver_settings)
    t1 = time.perf_counter() - t
    t = time.perf_counter()
    ph3, prob3 = P.phase3_from_problem(graph, res.phase2, anchor=res.anchor, settings=solver_settings)
    t3 = time.perf_counter() - t
    report = {
        "max_rel_diff": {"phase1": relative_difference(ph1.theta_free, res.phase1.theta_free),
                         "phase3": relative_difference(ph3.x_star, res.phase3.x_star)},
        "cvxpy_timings": {"phase1": t1, "phase3": t3},
        "problems": {"phase1": prob1, "phase3": prob3},
    }
    if res.regularization.regularization == "chordal":
        from .chordal import chordal_from_problem

        t = time.perf_counter()
        est, prob_c = chordal_from_problem(graph, 1.0 / res.uncertainty.var_delta, anchor=res.tree.root,
                                           settings=solver_settings)
        report["cvxpy_timings"]["chordal"] = time.perf_counter() - t
        report["max_rel_diff"]["chordal"] = relative_difference(est.vectors, res.regularization.chordal.vectors)
        report["problems"]["chordal"] = prob_c
    return res, report
