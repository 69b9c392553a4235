r"""Graduated non-convexity on 3-D pose graphs: ``lago(graph3d, robust=...)`` runs ``gnc.gnc_lago`` around ``lago3d``.

GNC's loop (``gnc``) is the same in space; what changes is the weighted solve and the residual:

* the residual of edge k is r_k² = e_kᵀ Ω_k e_k with e_k (6,) the error of the graph's cost — g2o's (translation,
  quaternion vector part) or GTSAM's (Log of SE(3)) — at ``lago3d``'s estimate (``gnc.edge_r2``); c̄² is the χ²
  quantile of 6 dof (0.99 → 16.81);
* the weighted solve is ``lago3d`` on the graph with Ω_k replaced by w_k Ω_k. Every stage reads the information,
  so the weights reach all of them: the chordal relaxation (C) Σ_k ‖(R_j − R_iR̃_ij) S_k‖²_F with S_k² = κ_k I,
  κ_k = 3 / (2 tr((w_k Ω_rr)⁻¹)) = w_k κ_k(Ω) (``space.chordal``: isotropic; the anisotropic S_k² scales by w_k
  too), the positions (P) with L_kᵀL_k = w_k Ω_tt, the joint step with w_k Ω_k. An edge of weight ≤ ``drop_below``
  leaves the solve (the 3-D graph needs no integers, only connectivity, which ``gnc._weighted`` keeps).

The result is a ``Robust3DResult``: the ``Lago3DResult`` of ``lago3d`` on the accepted edges (``chi2`` over them)
with GNC's record, as ``gnc.RobustResult`` is for planar graphs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..space import Lago3DResult
from ..result import AcceptedEdges

__all__ = ["Robust3DResult"]


@dataclass(frozen=True, eq=False, repr=False)  # repr: Lago3DResult's few lines, with the robust one
class Robust3DResult(AcceptedEdges, Lago3DResult):
    """A ``Lago3DResult`` of ``lago3d`` on the **accepted** edges (``chi2`` and ``chi2_seed`` are over them; poses
    indexed as in the input), plus GNC's record as ``gnc.RobustResult``: ``input_graph`` the graph given,
    ``rejected_edges`` (r,) int64 indices into its edges (file order), ``weights`` (m,) the final GNC weights (1 or 0 for an edge the re-admission re-classified),
    ``settings``, ``iterations``, ``known_inliers`` (m,) bool, ``history``."""

    input_graph: object = None
    rejected_edges: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    settings: object = None
    iterations: int = 0
    known_inliers: np.ndarray | None = None
    history: list = field(default_factory=list)

    def _describe(self) -> tuple[str, list[str]]:
        head, lines = super()._describe()
        return head, [self._robust_line(), *lines]

    def __post_init__(self):
        # ``graph``: the accepted edges of the input graph with their information as given (the graph ``chi2`` is
        # over, and the one ``pose_covariances`` and ``refine`` take), not GNC's last weighted graph
        if self.input_graph is not None:
            object.__setattr__(self, "graph", self.input_graph.subgraph_edges(self.accepted_edges))

