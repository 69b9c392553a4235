r"""Robust variants (V10–V11): a convex robust loss on the edges, and gating of false loop closures.

Let r_k be the whitened residual rows of edge k (phase 1: one row; phase 3: its two position rows and
its θ row of L — an edge is an outlier as a whole, so its rows form one group; ``grouping="component"``
treats rows separately). With threshold M (whitened units)

     huber:  ρ(r_k) = ‖r_k‖² if ‖r_k‖ ≤ M, else 2M‖r_k‖ − M²,
             written DCP as min_v ‖r_k − v_k‖² + 2M‖v_k‖₂ (a Moreau envelope; phase 1 uses
             ``cp.huber`` directly),
     l1:     ρ(r_k) = 2M‖r_k‖₂ (Huber's tails without its quadratic core; per-edge ℓ2 norms).

Both bound an edge's influence (its gradient) by 2M, so a false loop closure pulls with a bounded force
instead of a force growing with its error. Outliers also corrupt the 2kπ regularization: a BFS tree may
use a false loop closure as a tree edge, making θ_tree wrong on a whole subtree, and every chord rounded
against it. ``robust_lago`` therefore (a) roots the regularization on the odometric tree when the
odometric chain is complete (``spanning_tree="auto"``; false loop closures are never odometric), and
(b) re-rounds **every** edge (tree edges included) against the robust phase-1 estimate θ_rob, re-solving
phase 1 until no k changes (at most ``reround_rounds`` times). Phase 2 then uses the robust phase-1
information L_w = diag(√w) L with the IRLS weights w_k = min(1, M/‖r_k‖) of the robust phase-1 optimum.

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
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..errors import OptionError
from ..graph import minimum_spanning_edges
from ..metrics import whitened_errors
from ..posegraph import PoseGraph
from ..rounding import AMBIGUITY_MARGIN
from ..solvers import ClarabelSettings
from .engine import VariantResult, lago_variant
from .systems import DEFAULT_THRESHOLD

__all__ = ["GATE_THRESHOLD", "robust_lago"]

log = logging.getLogger("lago_cvx.variants")

#: A suggested gate for ``robust_lago(gate=...)``: √χ²₃ at 1 − 10⁻⁶ (whitened error of one edge, 3 dof),
#: = √30.6648… (scipy.stats.chi2.ppf(1 − 1e-6, 3), written out so that importing needs no scipy.stats;
#: tests/test_variants.py checks it).
GATE_THRESHOLD = math.sqrt(30.66484970615427)


def robust_lago(graph: PoseGraph, *, loss: str = "huber", threshold: float = DEFAULT_THRESHOLD,
                grouping: str = "edge", spanning_tree="auto", reround: bool = True, reround_rounds: int = 5,
                gate: float | None = None, gate_rounds: int = 5, anchors=None, priors=None,
                constraints_fn: Callable | None = None, anchor=None, anchor_pose=None,
                margin: float = AMBIGUITY_MARGIN, information: str = "full",
                solver_settings: ClarabelSettings | None = None) -> VariantResult:
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
        raise OptionError("robust_lago needs loss 'huber' or 'l1'")
    if gate is not None and not gate > 0:
        raise OptionError(f"gate must be > 0 or None, got {gate}")
    res = lago_variant(graph, anchors=anchors, priors=priors, constraints_fn=constraints_fn, loss=loss,
                       threshold=threshold, grouping=grouping, method="cvxpy", spanning_tree=spanning_tree,
                       regularization="tree", information=information,
                       anchor=anchor, anchor_pose=anchor_pose, margin=margin, reround=reround,
                       reround_rounds=reround_rounds, solver_settings=solver_settings)
    if gate is None:
        return res
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
        trusted = tree if trust_tree else minimum_spanning_edges(graph, err)
        keep[trusted] = True  # connectivity: the trusted spanning tree is never rejected
        if keep_prev is not None and np.array_equal(keep, keep_prev):
            rounds -= 1
            break
        keep_prev = keep
        sub = graph.subgraph_edges(keep)
        sub_tree = (np.cumsum(keep) - 1)[trusted]
        res = lago_variant(sub, anchors=anchors, priors=priors, constraints_fn=constraints_fn, loss="l2",
                           method="cvxpy" if constraints_fn is not None else "closed_form", spanning_tree=sub_tree,
                           regularization="tree", information=information, anchor=convex.anchor, anchor_pose=anchor_pose, margin=margin,
                           reround=True, reround_rounds=reround_rounds, solver_settings=solver_settings)
        poses = res.poses
        log.info("gating round %d: %d of %d edges rejected (whitened error > %.3g)", rounds,
                 int((~keep).sum()), graph.n_edges, gate)
    robust = dict(convex.robust)
    robust.update(inliers=keep_prev, gate=float(gate), gate_rounds=rounds, convex_poses=convex.poses, subgraph=sub)
    timings = dict(res.timings)
    timings["convex"] = convex.timings["total"]
    return replace(res, graph=graph, loss=loss, robust=robust, timings=timings)


