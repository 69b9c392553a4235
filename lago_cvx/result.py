"""What every LAGO route returns: ``LagoResult``, the poses with every intermediate quantity."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .graph import SpanningTree
from .metrics import chi2
from .phases import Phase1, Phase2, Phase3
from .posegraph import PoseGraph
from .positions import Polish
from .regularization import RegularizationReport
from .reports import Summary, fmt_timings, short_repr
from .uncertainty import EdgeUncertainty

__all__ = ["LagoResult"]


@dataclass(eq=False)
class LagoResult:
    """Everything LAGO computed.

    Covariances (``pose_covariances``) are phase 3's, eq. (15), also after the polish: its positions
    differ from phase 3's by second-order terms, so to first order they share phase 3's covariance. (The
    polish's own information, ``polish.positions.info``, holds the orientations fixed and would understate
    the position uncertainty.)"""

    #: The pose graph solved.
    graph: PoseGraph
    #: The final estimate (n, 3) (x, y, θ) in the frame given by ``anchor_pose`` (θ unwrapped along the
    #: tree; wrap for display).
    poses: np.ndarray
    #: The id of the pose held fixed.
    anchor: int
    #: Its index.
    anchor_index: int
    #: (3,) the anchor's pose (x, y, θ) in the output frame.
    anchor_pose: np.ndarray
    #: "closed_form" or "cvxpy".
    method: str
    #: The spanning tree.
    tree: SpanningTree
    #: The 2kπ report (its ``regularization`` field says "tree", "chordal" or "integer").
    regularization: RegularizationReport
    #: The per-edge uncertainties (marginal P_Δ, P_δ).
    uncertainty: EdgeUncertainty
    #: Phase 1 (see ``lago_cvx.phases``; plain LAGO computes the phases in the anchor's own frame, anchor at
    #: the origin).
    phase1: Phase1
    #: Phase 2.
    phase2: Phase2
    #: Phase 3.
    phase3: Phase3
    #: Seconds per step (keys ``tree``, ``regularization``, ``phase1``, ``phase2``, ``phase3``, ``positions``,
    #: ``total``).
    timings: dict
    #: The cvxpy problems (method "cvxpy" only: "phase1", "phase3", "positions", and "chordal" / "integer"
    #: with those regularizations).
    problems: dict = field(default_factory=dict)
    #: The name of the route (``lago_cvx.pipeline.ROUTES``) or "custom".
    route: str = "custom"
    #: "full" or "marginal": how phases 2–3 used each edge's 3×3 information.
    information: str = "marginal"
    #: "phase3" (the poses are phase 3's) or "resolve" (positions re-solved exactly for the orientations).
    positions: str = "phase3"
    #: With ``positions="resolve"``, the polish: a ``lago_cvx.positions.Polish``.
    polish: Polish | None = None

    def _frame(self) -> np.ndarray:
        """T (3, 3): the rotation from the phases' frame to the output frame."""
        T = np.eye(3)
        c, s = np.cos(self.anchor_pose[2]), np.sin(self.anchor_pose[2])
        T[:2, :2] = [[c, -s], [s, c]]
        return T

    @property
    def orientations(self) -> np.ndarray:
        """Phase-1 orientations θ̂ (n,), in the output frame."""
        return self.phase1.theta + self.anchor_pose[2]

    @property
    def chi2(self) -> float:
        """χ² at ``poses`` in the graph's cost (``lago_cvx.metrics.chi2``; no ½)."""
        return chi2(self.graph, self.poses)

    def pose_covariances(self, *, progress=None) -> np.ndarray:
        """Marginal covariance (n, 3, 3) of each pose, order (x, y, θ), zeros at the anchor, rotated into
        the output frame: the 3×3 diagonal blocks of phase 3's inverse information (eq. (15)), by selected
        inversion of its sparse factor (no dense inverse). It is the first-order covariance of LAGO's
        estimate whatever ``positions`` was: the re-solved positions (``positions="resolve"``) differ from
        phase 3's only at second order in the noise, so the same covariance describes them to first
        order. ``progress`` — an optional ``ProgressCallback(stage, fraction)``."""
        T = self._frame()
        return T @ self.phase3.pose_covariances(progress=progress) @ T.T

    def _describe(self) -> tuple[str, list[str]]:
        """The head and lines of ``repr``: counts, χ², route, timings (never an array)."""
        g, reg = self.graph, self.regularization
        try:
            chi = f"χ² = {self.chi2:.6g} (g2o, Σ eᵀΩe)"
        except Exception:  # repr must not fail on a result built by hand
            chi = "χ² not available"
        head = f"{g.n_poses} poses, {g.n_edges} edges ({g.n_loop_closures} loop closures): {chi}"
        a = self.anchor_pose
        return head, [
            f"route {self.route}: {self.tree.kind} spanning tree, {reg.regularization} regularization "
            f"({reg.n_regularized} of {reg.chords.size} chords corrected by 2kπ), {self.information} information, "
            f"positions {self.positions}; method {self.method}",
            f"anchor pose {self.anchor} at ({a[0]:.6g}, {a[1]:.6g}, {a[2]:.6g})",
            "time " + fmt_timings(self.timings),
        ]

    def __repr__(self) -> str:
        """A few lines whatever the size (poses, χ², route, timings); ``summary()`` for a table."""
        return short_repr(type(self).__name__, *self._describe())

    def _summary_rows(self) -> list:
        """(key, label, value) rows of ``summary()``."""
        g, reg = self.graph, self.regularization
        r = reg.summary()
        return [("n_poses", "poses", g.n_poses), ("n_edges", "edges", g.n_edges),
                ("chi2", "χ² (g2o, Σ eᵀΩe)", self.chi2), ("route", "route", self.route),
                ("method", "method", self.method), ("spanning_tree", "spanning tree", self.tree.kind),
                ("regularization", "regularization", r["regularization"]), ("n_chords", "chords", r["n_chords"]),
                ("n_regularized", "chords corrected", r["n_regularized"]),
                ("n_ambiguous", "ambiguous chords", r["n_ambiguous"]),
                ("max_abs_residual", "max |cycle residual|", r["max_abs_residual"]),
                ("information", "information", self.information), ("positions", "positions", self.positions),
                ("anchor", "anchor pose", int(self.anchor))]

    def summary(self) -> Summary:
        """The numbers of the result as a dict (JSON-ready values: ``n_poses``, ``n_edges``, ``method``,
        ``route``, ``spanning_tree``, the regularization report's summary, ``information``, ``positions``,
        ``chi2``, ``anchor``, ``timings``) that prints as a small table (``print(result.summary())``)."""
        return Summary(f"{type(self).__name__}: LAGO on {self.graph.name or 'a pose graph'}"[:78],
                       self._summary_rows(), timings=self.timings)


class AcceptedEdges:
    """What a GNC result of either dimension derives from its ``input_graph`` and ``rejected_edges``."""

    @property
    def accepted_edges(self) -> np.ndarray:
        """Indices (m − r,) of the accepted edges in the input graph."""
        keep = np.ones(self.input_graph.n_edges, bool)
        keep[self.rejected_edges] = False
        return np.flatnonzero(keep)

    def _robust_line(self) -> str:
        """The line of ``repr`` that says what GNC rejected."""
        s = self.settings
        c2 = s.c2_for(self.input_graph.dim)
        return (f"robust GNC-{s.loss.upper()} (c̄² = {c2:.4g}): {self.rejected_edges.size} "
                f"of {self.input_graph.n_edges} edges rejected after {self.iterations} iterations; χ² over the "
                "accepted edges")
